"""``mocapkit view FILE...``: recordings and results in the browser, on a timeline."""

from __future__ import annotations

import argparse
import sys
import time
from typing import Any

from mocapkit.cli.boundary import port
from mocapkit.cli.common import EXIT_OK, print_json

_EXAMPLES = """\
examples:
  mocapkit view ../shared/data/c3d/walking2.c3d                 # the marker trial's body
  mocapkit retarget walk.mot --robot g1 -o walk_g1.npz
  mocapkit view walk.mot walk_g1.npz                            # human and robot side by side
  mocapkit view walk_g1.csv --robot g1 --port 9000 --play
  mocapkit view a.bvh b.bvh --seconds 60 --json

Files: marker trials (C3D, TRC: reconstructed on the way, the tracked markers in red),
joint angles (.mot/.sto on OpenSim's names), BVH, IMU recordings (through the body model),
and robot trajectories written by mocapkit retarget (.npz; .csv with --robot). The page:
Play / Pause, a time slider, the speed, loop. A file that cannot be read is named with
the reason; the others are shown. Needs the viz extra: pip install 'mocapkit[viz]'.
"""


def register(sub: Any) -> None:
    p = sub.add_parser(
        "view",
        help="recordings and results in the browser (viser), side by side on a timeline",
        description="Serves a 3-D page with every file as a body or a robot, side by side, "
        "and a timeline (play, pause, scrub, speed).",
        epilog=_EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("files", nargs="+", help="files to show (see the examples)")
    p.add_argument("--robot", default=None, help="robot name or YAML of a .csv trajectory")
    p.add_argument("--height", type=float, default=None, help="subject height [m] (marker trials)")
    p.add_argument("--host", default="127.0.0.1", help="address to serve on")
    p.add_argument("--port", type=port, default=8080, help="port (the next free one if busy)")
    p.add_argument("--play", action="store_true", help="start playing at once")
    p.add_argument("--seconds", type=float, default=None, help="stop after this long")
    p.add_argument("--json", action="store_true", help="print what was shown at the end")
    p.set_defaults(func=_view)


def _view(args: argparse.Namespace) -> int:
    from mocapkit.cli.viewer_cmd import _check_address
    from mocapkit.viz.file_viewer import FileViewer
    from mocapkit.viz.viewer import import_viser

    import_viser()
    _check_address(args.host)
    with FileViewer(host=args.host, port=args.port) as viewer:
        viewer.load(args.files, robot=args.robot, height_m=args.height)
        for path, why in viewer.failed:
            print(f"mocapkit view: {path} not shown: {why}", file=sys.stderr)
        viewer.start()
        if args.play:
            viewer.play()
        print(f"mocapkit view: open {viewer.url} (Ctrl-C to stop)", file=sys.stderr)
        end = None if args.seconds is None else time.monotonic() + args.seconds
        while end is None or time.monotonic() < end:
            time.sleep(0.1)
        summary = {
            "url": viewer.url,
            "shown": [
                {
                    "file": tr.name,
                    "kind": type(tr).__name__.replace("Track", "").lower(),
                    "frames": int(tr.time.size),
                    "notes": tr.notes,
                }
                for tr in viewer.tracks
            ],
            "failed": [{"file": f, "error": e} for f, e in viewer.failed],
            "seconds": [viewer.t0, viewer.t1],
        }
    if args.json:
        print_json(summary)
    return EXIT_OK
