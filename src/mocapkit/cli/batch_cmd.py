"""``mocapkit batch``: a single-file command over many recordings (see mocapkit.batch)."""

from __future__ import annotations

import argparse
import shlex
import sys
from typing import Any

from mocapkit.cli.common import EXIT_ERROR, EXIT_OK, print_json

_EXAMPLES = """\
examples:
  mocapkit batch markers ../shared/data/c3d -o out/markers --workers 2 --json
  mocapkit batch imu 'recordings/*.csv' -o out/imu --args '--filter polaris'
  mocapkit batch body @sessions.txt -o out/body --engine ray --ray-address auto
  mocapkit batch retarget ../shared/data/c3d -o out/g1 --workers 2 --args '--robot g1'

Options in --args (or after a '--' among the inputs) go to the single-file command
(markers reconstruct, imu run, body angles, retarget) for every input. Outputs are
<input name>.mot/.sto/.csv in OUTDIR with a
manifest.jsonl (one line per file: input, output, ok, seconds, figures, error); a rerun
skips inputs whose output is newer (--force redoes them); a failing file is reported and
the batch goes on (exit 1 at the end if any failed).
"""


def register(sub: Any) -> None:
    p = sub.add_parser(
        "batch",
        help="a single-file command over many recordings (local processes or Ray)",
        epilog=_EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "kind", choices=["markers", "imu", "body", "retarget"], help="which command to run"
    )
    p.add_argument(
        "inputs",
        nargs="+",
        help="files, directories, globs ('*.c3d'), @list.txt files, or fsspec URLs "
        "('s3://bucket/trials/*.c3d'; the corpus extra and the file system's package)",
    )
    p.add_argument(
        "-o", "--output", required=True, help="output directory (a local path or an fsspec URL)"
    )
    p.add_argument("--workers", type=int, default=1, help="worker processes (default 1)")
    p.add_argument(
        "--engine",
        choices=["local", "ray"],
        default="local",
        help="local: worker processes here (default); ray: a Ray cluster",
    )
    p.add_argument("--ray-address", default=None, help="a Ray cluster (default: a local one)")
    p.add_argument("--force", action="store_true", help="redo inputs whose output exists")
    p.add_argument(
        "--args",
        default="",
        metavar="'OPTIONS'",
        help="options for the single-file command, quoted as one word (e.g. "
        "--args '--robot g1'); options after a '--' among the inputs work too",
    )
    p.add_argument("--json", action="store_true", help="print one JSON summary")
    p.set_defaults(func=_batch)


def _batch(args: argparse.Namespace) -> int:
    from mocapkit.batch import run_batch
    from mocapkit.cli.common import StepProgress

    inputs = list(args.inputs)
    extra: list[str] = []
    if "--" in inputs:  # argparse keeps a '--' inside nargs='+'
        cut = inputs.index("--")
        inputs, extra = inputs[:cut], inputs[cut + 1 :]
    extra += shlex.split(args.args) if args.args else []
    with StepProgress() as bars:

        def report(row: dict[str, Any], n_done: int, n_total: int) -> None:
            bars(f"batch {args.kind}", n_done, n_total)
            if not row["ok"] and not args.json:
                print(f"mocapkit batch: {row['input']}: {row['error']}", file=sys.stderr)

        result = run_batch(
            args.kind,
            inputs,
            args.output,
            extra,
            workers=args.workers,
            engine=args.engine,
            ray_address=args.ray_address,
            force=args.force,
            on_result=report,
        )
    if args.json:
        print_json(result.as_json())
    else:
        print(
            f"batch {args.kind}: {result.ok} ok, {result.failed} failed, {result.skipped} "
            f"skipped of {result.files} in {result.seconds:.1f} s -> {args.output}",
            file=sys.stderr,
        )
    return EXIT_OK if result.failed == 0 else EXIT_ERROR
