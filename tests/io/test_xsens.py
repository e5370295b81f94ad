"""Xsens MT Manager text exports: the OpenSense recording and malformed tiny files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mocapkit.errors import DataError, FileFormatError
from mocapkit.geometry import quat_rotate
from mocapkit.io.xsens import read_xsens_directory, read_xsens_export, trim_to_common_packets

HEADER = "// Update Rate: 100.0Hz\n"
LABELS = "PacketCounter\tAcc_X\tAcc_Y\tAcc_Z\t" + "\t".join(
    f"Mat[{i}][{j}]" for i in (1, 2, 3) for j in (1, 2, 3)
)
IDENTITY = "\t".join(["1", "0", "0", "0", "1", "0", "0", "0", "1"])


def _rows(packets: list[int], extra: str = "") -> str:
    return "".join(f"{p}\t0\t0\t9.8\t{IDENTITY}{extra}\n" for p in packets)


@pytest.mark.shared_data
def test_opensense_exports_trimmed_to_common_packets(shared_data: Path) -> None:
    exports = read_xsens_directory(shared_data / "opensense" / "xsens" / "IMUData")
    assert len(exports) == 8
    lengths = {e.n_samples for e in exports.values()}
    assert lengths == {2432}  # packets 472..2903, the shortest file's range
    e = exports["00B421E6"]
    assert e.packet[0] == 472
    assert e.time[0] == 0.0
    assert e.time[-1] == pytest.approx(24.31)
    assert e.gyr is None
    # the matrix is R_world_sensor: the accelerometer turned into the world is +g up
    acc_world = quat_rotate(e.orientation.quat, e.acc).mean(axis=0)
    np.testing.assert_allclose(acc_world, [0.0, 0.0, 9.8], atol=0.1)
    with pytest.raises(DataError, match="has no gyroscope columns"):
        e.to_recording()
    untrimmed = read_xsens_directory(shared_data / "opensense" / "xsens" / "IMUData", trim=False)
    assert max(u.n_samples for u in untrimmed.values()) == 2505


def test_packet_counter_wraps_and_gyroscope_columns(tmp_path: Path) -> None:
    p = tmp_path / "MT_0_0_AAA.txt"
    labels = LABELS + "\tGyr_X\tGyr_Y\tGyr_Z"
    p.write_text(HEADER + labels + "\n" + _rows([65534, 65535, 0, 1], "\t0.1\t0\t0"))
    e = read_xsens_export(p)
    np.testing.assert_array_equal(e.packet, [65534, 65535, 65536, 65537])
    rec = e.to_recording()
    assert rec.rate_hz == pytest.approx(100.0)
    np.testing.assert_allclose(rec.gyr[:, 0], 0.1)


def test_trim_to_common_packets(tmp_path: Path) -> None:
    a = tmp_path / "MT_0_0_A.txt"
    b = tmp_path / "MT_0_0_B.txt"
    a.write_text(HEADER + LABELS + "\n" + _rows([10, 11, 12, 13]))
    b.write_text(HEADER + LABELS + "\n" + _rows([11, 12, 13, 14, 15]))
    out = trim_to_common_packets({"A": read_xsens_export(a), "B": read_xsens_export(b)})
    for e in out.values():
        np.testing.assert_array_equal(e.packet, [11, 12, 13])
        np.testing.assert_allclose(e.time, [0.0, 0.01, 0.02])
    c = tmp_path / "MT_0_0_C.txt"
    c.write_text(HEADER + LABELS + "\n" + _rows([20, 21]))
    with pytest.raises(DataError, match="the exports share no packet"):
        trim_to_common_packets({"A": read_xsens_export(a), "C": read_xsens_export(c)})


def test_malformed_exports(tmp_path: Path) -> None:
    p = tmp_path / "MT_x.txt"
    p.write_text(LABELS + "\n" + _rows([1]))
    with pytest.raises(FileFormatError, match="no '// Update Rate: <Hz>' header line"):
        read_xsens_export(p)
    p.write_text(HEADER + "PacketCounter\tAcc_X\tAcc_Y\n1\t0\t0\n")
    with pytest.raises(FileFormatError, match=r"missing column\(s\) Acc_Z, Mat\[1\]\[1\]"):
        read_xsens_export(p)
    p.write_text(HEADER + LABELS + "\n" + _rows([1]) + "2\t0\t0\t\t" + IDENTITY + "\n")
    with pytest.raises(
        FileFormatError, match="column 'Acc_Z' is empty or non-finite at data row 1"
    ):
        read_xsens_export(p)
    p.write_text(HEADER + LABELS + "\n" + _rows([1, 1]))
    with pytest.raises(FileFormatError, match="packet counter repeats at data row 1"):
        read_xsens_export(p)
    p.write_text(HEADER)
    with pytest.raises(FileFormatError, match="no column labels"):
        read_xsens_export(p)
    with pytest.raises(FileFormatError, match="not a directory of Xsens MT Manager exports"):
        read_xsens_directory(tmp_path / "none")
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(FileFormatError, match=r"no MT_\*.txt Xsens MT Manager exports"):
        read_xsens_directory(empty)


def test_a_counter_jump_that_cuts_the_trial_is_warned_about(tmp_path: Path) -> None:
    from mocapkit.io.xsens import DataGapWarning

    a = tmp_path / "MT_0_0_A.txt"
    b = tmp_path / "MT_0_0_B.txt"
    a.write_text(HEADER + LABELS + "\n" + _rows(list(range(10, 400))))
    # B's counter jumps: its last 40 rows look 1000 packets later (a glitch)
    b.write_text(HEADER + LABELS + "\n" + _rows(list(range(300, 340)) + list(range(1340, 1380))))
    with pytest.warns(DataGapWarning, match=r"1000 packets missing"):
        eb = read_xsens_export(b)
    with pytest.warns(DataGapWarning, match=r"sensor A: only 100 of its 390 rows"):
        trim_to_common_packets({"A": read_xsens_export(a), "B": eb})


def test_orientations_that_are_not_rotations_are_refused(tmp_path: Path) -> None:
    p = tmp_path / "MT_0_0_A.txt"
    ones = "\t".join(["1"] * 9)
    p.write_text(HEADER + LABELS + "\n" + _rows([1]) + "2\t0\t0\t9.81\t" + ones + "\n")
    with pytest.raises(FileFormatError, match=r"data row 1 is not a rotation matrix"):
        read_xsens_export(p)
