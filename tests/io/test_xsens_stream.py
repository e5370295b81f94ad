"""Xsens MT Manager exports read block by block (mocapkit.io.xsens.XsensStream) and
streamed through ``imu run`` and ``body angles`` (mocapkit.imu.sensor_streams): the whole
reader's arrays, checks and warnings, whatever the block size."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

from mocapkit.errors import FileFormatError
from mocapkit.geometry import quat_from_axis_angle, quat_to_matrix
from mocapkit.io.opensim_table import read_table
from mocapkit.io.xsens import (
    DataGapWarning,
    XsensStream,
    common_packets,
    read_xsens_directory,
    read_xsens_export,
    trimmed_blocks,
    xsens_streams,
)

MATRIX = [f"Mat[{i}][{j}]" for i in (1, 2, 3) for j in (1, 2, 3)]
LABELS = ["PacketCounter", "Acc_X", "Acc_Y", "Acc_Z", "Gyr_X", "Gyr_Y", "Gyr_Z",
          "Mag_X", "Mag_Y", "Mag_Z", *MATRIX]  # fmt: skip


def _export(
    d: Path, sensor: str, first: int, n: int, seed: int, drop: tuple[int, ...] = ()
) -> Path:
    """One sensor turning about a slowly moving axis at 100 Hz; the 16-bit counter from
    ``first`` (it wraps), the rows ``drop`` missing."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 100.0
    angle = 0.8 * np.sin(1.3 * t + seed)
    q = quat_from_axis_angle(
        np.column_stack([np.sin(0.2 * t), np.cos(0.2 * t), 0.3 + 0 * t]), angle
    )
    R = quat_to_matrix(q)
    gyr = np.column_stack([np.gradient(angle, t)] * 3) * [0.5, 0.8, 0.2] + 0.01 * rng.normal(
        size=(n, 3)
    )
    acc = np.einsum("nji,j->ni", R, [0.0, 0.0, 9.81]) + 0.05 * rng.normal(size=(n, 3))
    mag = np.einsum("nji,j->ni", R, [0.0, 0.4, -0.8])
    packet = (first + np.arange(n)) % 65536
    keep = np.setdiff1d(np.arange(n), drop)
    rows = [
        "\t".join([str(packet[k]), *(f"{v:.6f}" for v in (*acc[k], *gyr[k], *mag[k])),
                   *(f"{v:.7f}" for v in R[k].reshape(-1))])
        for k in keep
    ]  # fmt: skip
    path = d / f"MT_012_000_{sensor}.txt"
    path.write_text("// Start Time: 0\n// Update Rate: 100.0Hz\n" + "\t".join(LABELS) + "\n"
                    + "\n".join(rows) + "\n")  # fmt: skip
    return path


def _suit(tmp_path: Path) -> Path:
    d = tmp_path / "xsens"
    d.mkdir()
    _export(d, "00B4AAAA", 65400, 900, 1, drop=(300, 301, 302))  # wraps at row 136
    _export(d, "00B4BBBB", 65410, 880, 2)
    _export(d, "00B4CCCC", 65405, 905, 3)
    return d


@pytest.mark.parametrize("rows", [1, 7, 136, 5000])
def test_blocks_are_the_whole_reader(tmp_path: Path, rows: int) -> None:
    d = _suit(tmp_path)
    path = next(d.glob("*AAAA.txt"))
    with pytest.warns(DataGapWarning, match="3 packets missing .* after data row 299") as w:
        whole = read_xsens_export(path)
    with warnings.catch_warnings(record=True) as again:
        warnings.simplefilter("always")
        parts = list(XsensStream(path).blocks(rows))
    assert [str(x.message) for x in again] == [str(x.message) for x in w]
    np.testing.assert_array_equal(np.concatenate([p.packet for p in parts]), whole.packet)
    assert whole.packet[-1] - whole.packet[0] == 899  # unwrapped across the wrap
    for field in ("time", "acc", "gyr", "mag"):
        np.testing.assert_array_equal(np.concatenate([getattr(p, field) for p in parts]),
                                      getattr(whole, field))  # fmt: skip
    np.testing.assert_array_equal(np.concatenate([p.orientation.quat for p in parts]),
                                  whole.orientation.quat)  # fmt: skip


def test_trimmed_pieces_are_the_directory_reader(tmp_path: Path) -> None:
    d = _suit(tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataGapWarning)
        whole = read_xsens_directory(d)
        streams = xsens_streams(d)
        first, last = common_packets(streams, 50)
    assert (first, last) == (65410, 65400 + 880 + 9)
    for name, s in streams.items():
        parts = list(trimmed_blocks(s, first, last, 50))
        for field in ("packet", "time", "gyr"):
            np.testing.assert_array_equal(np.concatenate([getattr(p, field) for p in parts]),
                                          getattr(whole[name], field))  # fmt: skip


def test_errors_in_a_later_block_name_the_row(tmp_path: Path) -> None:
    d = tmp_path / "x"
    d.mkdir()
    path = _export(d, "A", 10, 300, 4)
    lines = path.read_text().splitlines()
    lines[3 + 250] = lines[3 + 249]  # row 250 repeats row 249's packet
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(FileFormatError, match="packet counter repeats at data row 250"):
        list(XsensStream(path).blocks(100))
    with pytest.raises(FileFormatError, match="packet counter repeats at data row 250"):
        read_xsens_export(path)
    path = _export(d, "B", 10, 300, 4)
    lines = path.read_text().splitlines()
    cells = lines[3 + 210].split("\t")
    cells[-1] = "5"  # not a rotation
    lines[3 + 210] = "\t".join(cells)
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(FileFormatError, match=r"data row 210 is not a rotation matrix .* 1 such"):
        list(XsensStream(path).blocks(64))


@pytest.mark.filterwarnings("ignore::mocapkit.io.xsens.DataGapWarning")
def test_imu_run_and_body_angles_stream_an_xsens_directory(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from mocapkit.cli.main import main
    from mocapkit.imu.filters import make_filter
    from mocapkit.imu.resample import common_time_base, resample_orientation
    from mocapkit.io.imu_files import read_device_orientations, read_imu_recordings

    d = _suit(tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataGapWarning)
        recs = read_imu_recordings(d)
        oris = read_device_orientations(d)
    for flt in ("polaris", "device"):
        rc = main(["imu", "run", str(d), "--filter", flt, "-o", str(tmp_path / f"{flt}.sto"),
                   "--json"])  # fmt: skip
        assert rc == 0
        assert json.loads(capsys.readouterr().out)["streamed"] is True
        if flt == "device":
            series = list(oris.values())
        else:
            series = [make_filter("polaris", 100.0).run_recording(r) for r in recs.values()]
        t = common_time_base(series)
        want = np.stack([resample_orientation(s, t) for s in series], axis=1)
        got = read_table(tmp_path / f"{flt}.sto")
        np.testing.assert_allclose(got.time, t - t[0], atol=1e-9)
        # the filter's rate from the first piece's steps (100 Hz in the last digits)
        np.testing.assert_allclose(got.data, want, rtol=0, atol=1e-6 if flt == "polaris" else 1e-9)


OPENSENSE_MAP = {"torso": "00B42268", "pelvis": "00B42279", "tibia_r": "00B4227D",
                 "femur_r": "00B4227C", "tibia_l": "00B421ED", "femur_l": "00B421EE",
                 "calcn_r": "00B421EF", "calcn_l": "00B421E6"}  # fmt: skip


@pytest.mark.shared_data
def test_body_angles_stream_the_opensense_xsens_exports(
    shared_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """OpenSense's Xsens walk (8 exports, no gyroscope: the devices' matrices), through
    the body model in pieces: the whole path's angles (myIMUMappings.xml's sensors)."""
    from mocapkit.body.pipeline import run_body
    from mocapkit.body.sensor_tree import SensorTree
    from mocapkit.cli.main import main
    from mocapkit.io.imu_files import read_device_orientations
    from mocapkit.io.joint_angles_mot import read_joint_angles_mot

    d = shared_data / "opensense" / "xsens" / "IMUData"
    maps = [a for k, v in OPENSENSE_MAP.items() for a in ("--map", f"{k}={v}")]
    argv = ["body", "angles", str(d), "--preset", "opensense", "-o", str(tmp_path / "st.mot"),
            "--json", *maps]  # fmt: skip
    assert main(argv) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["streamed"] is True
    assert out["n_frames"] == 2432
    tree = SensorTree.preset("opensense").with_sensor_names(OPENSENSE_MAP)
    whole = run_body(tree, read_device_orientations(d))
    got = read_joint_angles_mot(tmp_path / "st.mot")
    assert got.names == whole.body.angles.names
    np.testing.assert_allclose(got.values, whole.body.angles.values, atol=1e-8)
