"""Copy the bundled marker trial out of the OpenSim gait2392 tutorial (run once; the
results are committed under src/mocapkit/data/gait2392/).

    .venv/bin/python tools/make_gait_crop.py ../shared/data/opensim/gait2392

The walking trial ``subject01_walk1.trc`` (2.5 s, 151 frames at 60 Hz) is copied
whole; the static trial ``subject01_static.trc`` (5 s) is cut to its first
``static_frames`` frames, the header's frame counts updated and every data row kept
byte for byte.
"""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

OUT = Path(__file__).resolve().parents[1] / "src" / "mocapkit" / "data" / "gait2392"


def crop_trc(src: Path, dst: Path, frames: int) -> None:
    lines = src.read_text().splitlines(keepends=True)
    keys = lines[1].rstrip("\r\n").split("\t")
    values = lines[2].rstrip("\r\n").split("\t")
    for key in ("NumFrames", "OrigNumFrames"):
        values[keys.index(key)] = str(frames)
    head = [lines[0], lines[1], "\t".join(values) + "\n", lines[3], lines[4]]
    rows = [ln for ln in lines[5:] if ln.strip()]
    if lines[5].strip() == "":  # the blank line OpenSim writes after the header
        head.append(lines[5])
    dst.write_text("".join(head + rows[:frames]))


def main(folder: str, static_frames: int = 60) -> None:
    src = Path(folder)
    OUT.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(src / "subject01_walk1.trc", OUT / "subject01_walk1.trc")
    crop_trc(src / "subject01_static.trc", OUT / "subject01_static_crop.trc", static_frames)


if __name__ == "__main__":
    main(*sys.argv[1:])
