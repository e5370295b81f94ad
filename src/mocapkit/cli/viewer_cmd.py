"""``mocapkit viewer``: the live web viewer on a teleoperation session."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from mocapkit.cli.boundary import port
from mocapkit.cli.common import EXIT_OK, print_json

_EXAMPLES = """\
examples:
  mocapkit viewer                       # simulated operator, open http://127.0.0.1:8080/
  mocapkit viewer --port 9000 --shapes circle,infinity --seconds 120
  mocapkit viewer --host 0.0.0.0        # reachable from other machines on the network
  mocapkit viewer --seconds 30 --json   # stop after 30 s, print the session's figures
  mocapkit viewer --robot g1            # the operator drives Unitree G1 (whole body)

The page shows the operator's skeleton, the sensor frames and the Robonaut 2 arm, with
buttons Calibrate / Engage / Disengage / Reindex and gauges for latency, packet loss and
the safety state. Needs the viz extra: pip install 'mocapkit[viz]'.
"""


def register(sub: Any) -> None:
    p = sub.add_parser(
        "viewer",
        help="live web viewer (viser) of a teleoperation session, with its controls",
        description="Starts a live teleoperation session (mocapkit.teleop.live) fed by a "
        "simulated suit (the operator traces the paper's shapes in a loop; a sender process, "
        "real UDP, receiver, host-side filters, body model, retargeting and robot-server "
        "process) and serves the live 3-D viewer on HOST:PORT.",
        epilog=_EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--host", default="127.0.0.1", help="address to serve on")
    p.add_argument("--port", type=port, default=8080, help="port (the next free one if busy)")
    p.add_argument("--seconds", type=float, default=None, help="stop after this long")
    p.add_argument(
        "--shapes",
        default="vertical,horizontal,diagonal,circle,box,infinity",
        help="comma-separated shapes the simulated operator traces in a loop",
    )
    p.add_argument("--filter", default=None, help="orientation filter (default: the best)")
    p.add_argument(
        "--robot",
        default="robonaut2-right",
        help="robot: an arm, or a humanoid name or robot YAML (mocapkit robot list), drawn "
        "from its meshes",
    )
    p.add_argument("--ideal-sensors", action="store_true", help="no IMU noise or bias")
    p.add_argument("--seed", type=int, default=0, help="noise and mounting seed")
    p.add_argument("--json", action="store_true", help="print the session's figures at the end")
    p.set_defaults(func=_viewer)


def _check_address(host: str) -> None:
    """Bind a TCP socket to ``host`` (any port) and close it: an address that is not on
    this machine raises OSError here, at once, instead of a server that never starts."""
    import socket

    try:
        infos = socket.getaddrinfo(host, 0, type=socket.SOCK_STREAM)
    except socket.gaierror as exc:
        raise OSError(exc.errno, f"cannot resolve host {host!r}", host) from exc
    family, kind, proto, _, address = infos[0]
    with socket.socket(family, kind, proto) as s:
        try:
            s.bind(address)
        except OSError as exc:
            raise OSError(exc.errno, exc.strerror, f"--host {host}") from exc


def _viewer(args: argparse.Namespace) -> int:
    from mocapkit.teleop.simulated import SimulatedConfig, SimulatedSession
    from mocapkit.viz.live_api import LiveSnapshot
    from mocapkit.viz.viewer import TeleopViewer, import_viser

    import_viser()  # fail early, with the install hint, before starting anything
    _check_address(args.host)  # ... and on an address this machine does not have
    shapes = tuple(s.strip() for s in args.shapes.split(",") if s.strip())
    cfg = SimulatedConfig(
        shapes=shapes,
        duration_s=None if args.seconds is None else args.seconds + 5.0,
        filter_name=args.filter,
        sensor_noise=not args.ideal_sensors,
        seed=args.seed,
        robot=args.robot,
    )
    sim = SimulatedSession(cfg)
    with sim, TeleopViewer(sim, host=args.host, port=args.port) as viewer:
        print(f"mocapkit viewer: open {viewer.url} (Ctrl-C to stop)", file=sys.stderr)
        try:
            viewer.serve(args.seconds)
        finally:
            snap = LiveSnapshot.from_mapping(sim.snapshot())
    summary = {
        "url": viewer.url,
        "seconds": round(snap.t_s, 3),
        "filter": sim.filter_name,
        "state": snap.state,
        "safety": snap.safety,
        "packets": snap.packets,
        "packet_loss": snap.packet_loss,
        "latency_ms_p50": snap.latency_ms_p50,
        "latency_ms_p99": snap.latency_ms_p99,
        "commands": [c for c, _ in viewer.commands],
        "transitions": list(snap.transitions),
    }
    if args.json:
        print_json(summary)
    return EXIT_OK
