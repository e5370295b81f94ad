"""Fuzzing every file reader (issue 12): valid files with random bytes changed, lines cut
and the end truncated, and random bytes. Whatever comes in, only mocapkit's own errors
(``MocapkitError``, with a message) may come out: never a raw ``ValueError``,
``IndexError``, ``UnicodeDecodeError``, a zstd or MCAP exception, a hang or a NaN
silently accepted as data is checked separately by each reader's tests."""

from __future__ import annotations

import tempfile
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from mocapkit.errors import MocapkitError
from mocapkit.io.bvh import read_bvh
from mocapkit.io.c3d import read_c3d, write_c3d
from mocapkit.io.imu_csv import read_imu_csv, write_imu_csv
from mocapkit.io.joint_angles_mot import read_joint_angles_mot, write_joint_angles_mot
from mocapkit.io.opensense import read_orientations_sto, write_orientations_sto
from mocapkit.io.opensim_table import read_table
from mocapkit.io.trc import read_trc
from mocapkit.markers.trajectories import MarkerTrajectories
from mocapkit.series import ImuRecording, JointAngleSeries, OrientationSeries
from mocapkit.suit.mcap_fast import read_frame_buffer
from mocapkit.suit.recording import McapRecorder, read_frames
from mocapkit.teleop.recording import TeleopRecorder, read_messages

TRC_DIR = Path(__file__).resolve().parents[1] / "data" / "trc"


def _seed_files(tmp: Path) -> dict[str, bytes]:
    """One small valid file per format, written by our writers or shipped in tests/data."""
    out: dict[str, bytes] = {}
    n = 30
    t = np.arange(n) / 100.0
    rec = ImuRecording(
        t, np.full((n, 3), 0.1), np.tile([0.0, 0.0, 9.81], (n, 1)), np.tile([20.0, 0, -40], (n, 1))
    )
    out["csv"] = write_imu_csv(tmp / "a.csv", rec).read_bytes()
    ang = JointAngleSeries(t, ["knee_angle_r", "hip_flexion_r"], np.zeros((n, 2)))
    out["mot"] = write_joint_angles_mot(tmp / "a.mot", ang).read_bytes()
    q = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    out["sto"] = write_orientations_sto(
        tmp / "a.sto", {"pelvis_imu": OrientationSeries(t, q)}
    ).read_bytes()
    out["trc"] = (TRC_DIR / "exampleFormat.trc").read_bytes()
    out["bvh"] = (
        b"HIERARCHY\nROOT Hips\n{\n OFFSET 0 0 0\n CHANNELS 6 Xposition Yposition Zposition "
        b"Zrotation Xrotation Yrotation\n End Site\n {\n  OFFSET 0 1 0\n }\n}\nMOTION\n"
        b"Frames: 2\nFrame Time: 0.01\n0 0 0 0 0 0\n0 0 0 1 2 3\n"
    )
    with McapRecorder(tmp / "a.mcap") as r:
        for k in range(20):
            r.write_frame(bytes([k]) * 18, 1_000_000 * k)
    out["suit_mcap"] = (tmp / "a.mcap").read_bytes()
    traj = MarkerTrajectories(
        np.arange(20) / 100.0, np.random.default_rng(0).normal(size=(20, 3, 3)), ["A", "B", "C"]
    )
    out["c3d"] = write_c3d(tmp / "a.c3d", traj).read_bytes()
    with TeleopRecorder(tmp / "b.mcap") as tr:
        for k in range(20):
            tr.command(0.01 * k, [0.1, 0.2, 0.3], [1.0, 0.0, 0.0, 0.0])
    out["teleop_mcap"] = (tmp / "b.mcap").read_bytes()
    return out


with tempfile.TemporaryDirectory() as _d:
    SEEDS = _seed_files(Path(_d))

READERS: dict[str, tuple[str, Callable[[Path], Any]]] = {
    "csv": (".csv", read_imu_csv),
    "mot": (".mot", read_joint_angles_mot),
    "sto": (".sto", read_orientations_sto),
    "table": (".sto", read_table),
    "trc": (".trc", read_trc),
    "bvh": (".bvh", read_bvh),
    "c3d": (".c3d", read_c3d),  # ezc3d is native: a damaged file once crashed the process
    "suit_mcap": (".mcap", read_frames),
    "suit_mcap_fast": (".mcap", read_frame_buffer),
    "teleop_mcap": (".mcap", lambda p: read_messages(p, "/teleop/command")),
}
SEED_OF = {"table": "sto", "suit_mcap_fast": "suit_mcap"}


@st.composite
def mutated(draw: Any, seed: bytes) -> bytes:
    """A valid file with a few bytes changed, a span deleted and maybe the end cut."""
    data = bytearray(seed)
    for _ in range(draw(st.integers(0, 4))):
        if data:
            data[draw(st.integers(0, len(data) - 1))] = draw(st.integers(0, 255))
    if data and draw(st.booleans()):
        a = draw(st.integers(0, len(data) - 1))
        del data[a : a + draw(st.integers(1, 40))]
    if data and draw(st.booleans()):
        data = data[: draw(st.integers(0, len(data)))]
    return bytes(data)


def _read(kind: str, data: bytes) -> None:
    suffix, reader = READERS[kind]
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / f"fuzz{suffix}"
        path.write_bytes(data)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # recovered recordings, unit hints
            try:
                reader(path)
            except MocapkitError as exc:
                message = str(exc)
            else:
                message = "read"
    assert message  # an error always says what is wrong


@pytest.mark.parametrize("kind", list(READERS))
@given(data=st.data())
def test_a_damaged_file_gives_only_mocapkit_errors(kind: str, data: st.DataObject) -> None:
    _read(kind, data.draw(mutated(SEEDS[SEED_OF.get(kind, kind)])))


@pytest.mark.parametrize("kind", list(READERS))
@given(blob=st.binary(max_size=400))
def test_random_bytes_give_only_mocapkit_errors(kind: str, blob: bytes) -> None:
    _read(kind, blob)


@pytest.mark.parametrize("kind", list(READERS))
def test_the_seed_files_are_valid(kind: str) -> None:
    suffix, reader = READERS[kind]
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / f"seed{suffix}"
        path.write_bytes(SEEDS[SEED_OF.get(kind, kind)])
        reader(path)  # no error: the mutations start from a file the reader accepts
