"""`mocapkit suit` in-process through main(argv), with short durations on loopback."""

from __future__ import annotations

import json
import socket
import threading
import time
from pathlib import Path
from typing import Any

import pytest

from mocapkit.cli.main import main
from mocapkit.imu.filters import available_filters
from mocapkit.suit.radio import radio_rate_markdown
from mocapkit.suit.recording import read_frames

# runs live processes and sockets against the clock: run serially (see Makefile)
pytestmark = pytest.mark.realtime


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _objects(text: str) -> list[Any]:
    dec = json.JSONDecoder()
    out, i = [], 0
    text = text.strip()
    while i < len(text):
        obj, j = dec.raw_decode(text, i)
        out.append(obj)
        i = j
        while i < len(text) and text[i].isspace():
            i += 1
    return out


def test_help_lists_examples(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["suit", "--help"]) == 0
    out = capsys.readouterr().out
    assert "mocapkit suit bench --sensors 15 --rate-hz 1000 --seconds 10 --json" in out
    assert main(["suit", "receive", "--help"]) == 0


@pytest.mark.parametrize("sender", ["process", "thread"])
def test_bench_prints_exactly_the_five_figures(
    sender: str, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["suit", "bench", "--sensors", "3", "--rate-hz", "200", "--seconds", "0.3", "--json"]
    code = main([*argv, "--sender", sender])
    assert code == 0
    obj = json.loads(capsys.readouterr().out)
    assert list(obj) == ["sent", "received", "lost", "latency_ms_p50", "latency_ms_p99"]
    assert obj["sent"] == 3 * 61
    assert obj["lost"] == 0
    assert obj["received"] == obj["sent"]
    assert 0 < obj["latency_ms_p50"] <= obj["latency_ms_p99"]


def test_radio_table_matches_docs(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["suit", "radio-table"]) == 0
    assert capsys.readouterr().out == radio_rate_markdown()
    assert main(["suit", "radio-table", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert rows[-1]["n_sensors"] == 15
    assert rows[-1]["ratio"] > 2


def _run_receiver(argv: list[str], codes: list[int]) -> threading.Thread:
    th = threading.Thread(target=lambda: codes.append(main(argv)))
    th.start()
    time.sleep(0.5)  # let it bind
    return th


def test_simulate_record_replay_decode(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    port = _free_port()
    rec_a = tmp_path / "a.mcap"
    codes: list[int] = []
    th = _run_receiver(
        [
            "suit",
            "record",
            "--host",
            "127.0.0.1",
            "--port",
            str(port),
            "--seconds",
            "2.0",
            "--out",
            str(rec_a),
            "--json",
        ],
        codes,
    )
    sim = [
        "suit",
        "simulate",
        "--port",
        str(port),
        "--sensors",
        "3",
        "--rate-hz",
        "100",
        "--seconds",
        "0.5",
        "--speed",
        "0",
        "--motion",
        "wave",
        "--noise",
        "--json",
    ]
    assert main(sim) == 0
    th.join()
    assert codes == [0]
    sent, summary = _objects(capsys.readouterr().out)
    assert sent["frames"] == 3 * 51
    assert summary["datagrams"] == 153
    assert summary["dropped"] == {}
    assert set(summary["sensors"]) == {"1", "2", "3"}
    assert summary["sensors"]["1"]["delivered"] == 51
    assert summary["recording"]["frames"] == 153

    port2 = _free_port()
    rec_b = tmp_path / "b.mcap"
    th = _run_receiver(
        [
            "suit",
            "receive",
            "--host",
            "127.0.0.1",
            "--port",
            str(port2),
            "--seconds",
            "1.5",
            "--record",
            str(rec_b),
            "--json",
        ],
        codes,
    )
    assert main(["suit", "replay", str(rec_a), "--port", str(port2), "--speed", "0", "--json"]) == 0
    th.join()
    capsys.readouterr()
    assert [f.data for f in read_frames(rec_b)] == [f.data for f in read_frames(rec_a)]

    assert main(["suit", "decode", str(rec_a), "--json"]) == 0
    dec = json.loads(capsys.readouterr().out)
    assert dec["samples"] == 153
    assert dec["samples_per_sensor"] == {"1": 51, "2": 51, "3": 51}


def test_simulate_through_the_radio_model(capsys: pytest.CaptureFixture[str]) -> None:
    port = _free_port()
    argv = [
        "suit",
        "simulate",
        "--port",
        str(port),
        "--sensors",
        "2",
        "--rate-hz",
        "100",
        "--seconds",
        "0.2",
        "--speed",
        "0",
        "--radio",
        "--radio-bps",
        "1000000",
        "--loss",
        "0.5",
        "--json",
    ]
    assert main(argv) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["radio"]["sent"] == 42
    assert 5 < out["radio"]["lost"] < 37


def test_errors_exit_1_with_a_message(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["suit", "decode", str(tmp_path / "none.mcap")]) == 1
    assert "no such file" in capsys.readouterr().err
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
        assert (
            main(
                ["suit", "receive", "--host", "127.0.0.1", "--port", str(port), "--seconds", "0.1"]
            )
            == 1
        )
    assert f"cannot bind UDP 127.0.0.1:{port}" in capsys.readouterr().err
    assert main(["suit", "simulate", "--sensors", "16", "--seconds", "0.1"]) == 1
    assert "n_sensors: expected 1..15, got 16" in capsys.readouterr().err


@pytest.mark.parametrize("name", available_filters()[:1] or ["<none registered>"])
def test_simulate_on_node_fusion_over_the_paper_radio(
    name: str, capsys: pytest.CaptureFixture[str]
) -> None:
    if name == "<none registered>":
        pytest.skip("no orientation filter registered yet (the imu part lands them)")
    argv = ["suit", "simulate", "--port", str(_free_port()), "--mode", "orientation",
            "--filter", name, "--sensors", "15", "--rate-hz", "100", "--seconds", "0.5",
            "--radio", "--json"]  # fmt: skip
    assert main(argv) == 0
    out = json.loads(capsys.readouterr().out)
    # the hub polls at 95 % of the radio's rate for 15 sensors (28.7 Hz): nothing overflows
    assert out["radio"]["overflow"] == 0
    assert out["frames"] == out["radio"]["sent"] > 10
