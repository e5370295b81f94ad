"""OpenSim .mot/.sto tables: round trips and the real OpenSense quaternion file."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mocapkit.errors import FileFormatError
from mocapkit.io.opensim_table import read_table, write_table


def test_numeric_round_trip(tmp_path: Path) -> None:
    t = np.arange(5) / 100.0
    data = np.random.default_rng(0).normal(size=(5, 3))
    write_table(tmp_path / "a.mot", t, ["hip_flexion_r", "knee_angle_r", "ankle_angle_r"], data)
    table = read_table(tmp_path / "a.mot")
    assert table.in_degrees
    assert table.labels == ["hip_flexion_r", "knee_angle_r", "ankle_angle_r"]
    np.testing.assert_allclose(table.data, data, rtol=1e-9)
    np.testing.assert_allclose(table.column("knee_angle_r"), data[:, 1], rtol=1e-9)
    with pytest.raises(FileFormatError, match="column 'nope' not in table; available: hip"):
        table.column("nope")


def test_quaternion_round_trip(tmp_path: Path) -> None:
    t = np.arange(4) / 100.0
    q = np.random.default_rng(1).normal(size=(4, 2, 4))
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    write_table(tmp_path / "q.sto", t, ["pelvis_imu", "torso_imu"], q)
    table = read_table(tmp_path / "q.sto")
    assert table.is_quaternion
    np.testing.assert_allclose(table.data, q, rtol=1e-9)


def test_reads_opensense_orientations(shared_data: Path) -> None:
    table = read_table(shared_data / "opensense" / "walking_orientations.sto")
    assert table.is_quaternion
    assert "pelvis_imu" in table.labels
    np.testing.assert_allclose(np.linalg.norm(table.data, axis=-1), 1.0, atol=1e-6)


def test_malformed(tmp_path: Path) -> None:
    (tmp_path / "x.sto").write_text("name\nnope\n")
    with pytest.raises(FileFormatError, match="no 'endheader' line"):
        read_table(tmp_path / "x.sto")
    (tmp_path / "y.sto").write_text("endheader\ntime\ta\n0\t1\t2\n")
    with pytest.raises(FileFormatError, match="row 0 has 3 cells, expected 2"):
        read_table(tmp_path / "y.sto")


def test_vectorised_parse_falls_back_to_naming_the_bad_row(tmp_path: Path) -> None:
    """Well-formed files take the vectorised parser; a bad token goes to the row parser."""
    p = tmp_path / "q.sto"
    p.write_text("x\nDataType=Quaternion\nendheader\ntime\ta\n0\t1,0,0,0\n0.01\t1,0,zero,0\n")
    with pytest.raises(FileFormatError, match="row 1: could not convert string to float"):
        read_table(p)
    p.write_text("x\nendheader\ntime\ta\tb\n0\t1\t2\n0.01\t3\t4\n")
    table = read_table(p)
    np.testing.assert_array_equal(table.data, [[1, 2], [3, 4]])
    np.testing.assert_array_equal(table.time, [0.0, 0.01])
