"""The command line's error boundary: one clear line and exit 1, never a traceback, for
OS errors, decode errors and outputs that would overwrite an input; bugs say so."""

from __future__ import annotations

import errno
import socket
from pathlib import Path

import numpy as np
import pytest

from mocapkit.cli import imu_cmd
from mocapkit.cli.boundary import describe_os_error
from mocapkit.cli.main import main
from mocapkit.io.imu_csv import write_imu_csv
from mocapkit.series import ImuRecording


@pytest.fixture
def recording(tmp_path: Path) -> Path:
    n = 200
    t = np.arange(n) / 100.0
    rec = ImuRecording(t, np.zeros((n, 3)), np.tile([0.0, 0.0, 9.81], (n, 1)), name="s")
    return write_imu_csv(tmp_path / "rec.csv", rec)


def _err(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return err


def test_output_equal_to_the_input_is_refused_and_the_input_kept(
    recording: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    before = recording.read_bytes()
    code = main(["imu", "run", str(recording), "--filter", "miller", "-o", str(recording)])
    assert code == 1
    assert "is also the input" in _err(capsys)
    assert recording.read_bytes() == before


def test_a_directory_where_a_file_is_expected(
    recording: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = tmp_path / "out.sto"  # a directory with a file's name
    folder.mkdir()
    assert main(["imu", "run", str(recording), "--filter", "miller", "-o", str(folder)]) == 1
    assert f"{folder}: this is a directory, a file is expected here" in _err(capsys)


def test_the_parent_of_the_output_is_a_file(
    recording: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = recording / "x.sto"
    assert main(["imu", "run", str(recording), "--filter", "miller", "-o", str(out)]) == 1
    assert "a part of this path is a file, not a directory" in _err(capsys)


def test_undecodable_yaml(
    recording: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "tree.yaml"
    bad.write_text("a: [1, 2\n")
    out = tmp_path / "x.mot"
    assert main(["body", "angles", str(recording), "--tree", str(bad), "-o", str(out)]) == 1
    assert "not valid YAML" in _err(capsys)


def test_a_udp_port_in_use(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as busy:
        busy.bind(("127.0.0.1", 0))
        port = busy.getsockname()[1]
        argv = ["suit", "record", "--host", "127.0.0.1", "--port", str(port)]
        assert main([*argv, "--out", str(tmp_path / "r.mcap"), "--seconds", "0.2"]) == 1
    assert "Address already in use" in _err(capsys)


@pytest.mark.parametrize("value", ["70000", "-1", "http"])
def test_a_port_out_of_range_is_a_usage_error(
    value: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["suit", "simulate", "--port", value]) == 2
    assert "expected a port number 0..65535" in _err(capsys)


def test_the_viewer_fails_fast_on_an_address_not_on_this_machine(
    capsys: pytest.CaptureFixture[str],
) -> None:
    pytest.importorskip("viser")
    assert main(["viewer", "--host", "192.0.2.1", "--seconds", "1"]) == 1  # TEST-NET-1
    assert "--host 192.0.2.1" in _err(capsys)


@pytest.mark.parametrize(
    ("code", "words"),
    [
        (errno.ENOSPC, "the disk is full"),
        (errno.EACCES, "permission denied"),
        (errno.EROFS, "read-only"),
    ],
)
def test_os_errors_name_the_file_and_the_fix(code: int, words: str) -> None:
    exc = OSError(code, "strerror", "/data/out.mcap")
    line = describe_os_error(exc)
    assert line.startswith("/data/out.mcap: ")
    assert words in line


def test_disk_full_inside_a_command(
    recording: Path,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    def full(args: object) -> int:
        raise OSError(errno.ENOSPC, "No space left on device", str(tmp_path / "o.sto"))

    monkeypatch.setattr(imu_cmd, "_run", full)
    out = tmp_path / "o.sto"
    assert main(["imu", "run", str(recording), "--filter", "miller", "-o", str(out)]) == 1
    assert f"{out}: the disk is full" in _err(capsys)


def test_a_bug_says_so_and_where_to_report_it(
    recording: Path,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    def boom(args: object) -> int:
        raise ZeroDivisionError("division by zero")

    monkeypatch.setattr(imu_cmd, "_run", boom)
    out = tmp_path / "o.sto"
    assert main(["imu", "run", str(recording), "--filter", "miller", "-o", str(out)]) == 1
    err = _err(capsys)
    assert "internal error (ZeroDivisionError: division by zero)" in err
    assert "please report it" in err
