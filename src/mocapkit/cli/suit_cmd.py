"""``mocapkit suit``: simulate, receive, record, replay, decode and benchmark the motion suit."""

from __future__ import annotations

import argparse
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from mocapkit.cli.boundary import port
from mocapkit.cli.common import EXIT_OK, print_json

_EPILOG = """\
examples:
  mocapkit suit simulate --port 9000 --sensors 15 --rate-hz 100 --seconds 30 --motion walk
  mocapkit suit simulate --port 9000 --mode orientation --filter miller --radio
  mocapkit suit receive --port 9000                       (live table; Ctrl-C to stop)
  mocapkit suit receive --port 9000 --seconds 5 --json    (summary as JSON)
  mocapkit suit record --port 9000 --out session.mcap --seconds 60
  mocapkit suit replay session.mcap --port 9000 --speed 2
  mocapkit suit decode session.mcap --json
  mocapkit suit bench --sensors 15 --rate-hz 1000 --seconds 10 --json
  mocapkit suit radio-table
"""


def register(sub: Any) -> None:
    p = sub.add_parser(
        "suit",
        help="the motion suit: simulate, receive, record, replay, benchmark",
        description="The motion suit: IMU nodes, hub, radio, host receiver (docs/protocol.md).",
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    ss = p.add_subparsers(dest="suit_command", metavar="SUBCOMMAND")
    fmt = argparse.RawDescriptionHelpFormatter

    s = ss.add_parser(
        "simulate", help="stream a simulated suit", epilog=_EPILOG, formatter_class=fmt
    )
    s.add_argument(
        "--host",
        default="127.0.0.1",
        help="address (receive: to listen on; simulate and replay: to send to)",
    )
    s.add_argument("--port", type=port, default=9000, help="UDP port of the receiver")
    s.add_argument("--serial-port", help="send over this serial device instead of UDP")
    s.add_argument("--baud", type=int, default=921_600, help="serial line speed [bit/s]")
    s.add_argument("--sensors", type=int, default=15, help="number of sensors, 1..15")
    s.add_argument("--rate-hz", type=float, default=100.0, help="IMU sampling rate [Hz]")
    s.add_argument("--seconds", type=float, default=10.0, help="length of the motion [s]")
    s.add_argument(
        "--motion",
        default="walk",
        choices=["walk", "wave", "static"],
        help="the simulated body motion",
    )
    s.add_argument(
        "--mode",
        default="raw",
        choices=["raw", "orientation"],
        help="raw samples (host-side fusion) or on-node orientation",
    )
    s.add_argument("--filter", default="miller", help="on-node filter (orientation mode)")
    s.add_argument("--noise", action="store_true", help="consumer-grade IMU errors")
    s.add_argument("--speed", type=float, default=1.0, help="1 real time, 0 as fast as possible")
    s.add_argument(
        "--round-hz",
        type=float,
        help="hub polling rounds per second (default: the sampling rate; with --radio in "
        "orientation mode, 95%% of the radio's highest rate)",
    )
    s.add_argument("--radio", action="store_true", help="send through the paper's radio model")
    s.add_argument(
        "--radio-bps",
        type=float,
        default=33_600.0,
        help="the radio link's bit rate [bit/s] (the paper's: 33,600)",
    )
    s.add_argument("--loss", type=float, default=0.0, help="radio packet loss probability")
    s.add_argument("--reorder", type=float, default=0.0, help="radio reordering probability")
    s.add_argument(
        "--seed", type=int, default=0, help="random seed of the simulated noise and losses"
    )
    s.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    s.set_defaults(func=_simulate)

    for name, helptext in (
        ("receive", "receive and show live statistics"),
        ("record", "receive and record to MCAP"),
    ):
        r = ss.add_parser(name, help=helptext, epilog=_EPILOG, formatter_class=fmt)
        r.add_argument(
            "--host",
            default="0.0.0.0",
            help="address (receive: to listen on; simulate and replay: to send to)",
        )
        r.add_argument("--port", type=port, default=9000, help="UDP port")
        r.add_argument("--serial-port", help="receive from this serial device instead of UDP")
        r.add_argument("--baud", type=int, default=921_600, help="serial line speed [bit/s]")
        r.add_argument("--seconds", type=float, help="stop after this long (default: Ctrl-C)")
        r.add_argument(
            "--protocols",
            default="auto",
            choices=["auto", "suit", "slimevr"],
            help="which wire protocols to accept: suit, slimevr or auto (by the first byte)",
        )
        r.add_argument("--json", action="store_true", help="print one JSON summary at the end")
        r.add_argument(
            "--samples",
            choices=["live", "at-close", "none"],
            help="decoded samples channel: live (the receiver's stream; SlimeVR; up to a few "
            "kHz), at-close (decoded when the recording closes; the default for our protocol), "
            "none",
        )
        if name == "record":
            r.add_argument(
                "-o", "--output", "--out", dest="out", required=True, help="MCAP file to write"
            )
        else:
            r.add_argument("--record", help="also record to this MCAP file")
        r.set_defaults(func=_receive)

    rp = ss.add_parser(
        "replay", help="send a recording again, byte for byte", epilog=_EPILOG, formatter_class=fmt
    )
    rp.add_argument("recording", help="an MCAP recording written by 'suit record'")
    rp.add_argument(
        "--host",
        default="127.0.0.1",
        help="address (receive: to listen on; simulate and replay: to send to)",
    )
    rp.add_argument("--port", type=port, default=9000, help="UDP port")
    rp.add_argument("--speed", type=float, default=1.0, help="1 real time, 0 as fast as possible")
    rp.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    rp.set_defaults(func=_replay)

    d = ss.add_parser(
        "decode", help="batch-decode a recording", epilog=_EPILOG, formatter_class=fmt
    )
    d.add_argument("recording", help="an MCAP recording written by 'suit record'")
    d.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    d.set_defaults(func=_decode)

    b = ss.add_parser(
        "bench", help="simulator -> loopback UDP -> receiver", epilog=_EPILOG, formatter_class=fmt
    )
    b.add_argument("--sensors", type=int, default=15, help="number of sensors")
    b.add_argument("--rate-hz", type=float, default=1000.0, help="sample rate per sensor [Hz]")
    b.add_argument("--seconds", type=float, default=10.0, help="how long [s]")
    b.add_argument(
        "--sender",
        default="process",
        choices=["process", "thread"],
        help="run the simulator in its own process (default) or in a thread of this one",
    )
    b.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    b.set_defaults(func=_bench)

    t = ss.add_parser(
        "radio-table",
        help="per-sensor update rate on the paper's radio",
        epilog=_EPILOG,
        formatter_class=fmt,
    )
    t.add_argument("--bps", type=float, default=33_600.0, help="radio bit rate [bit/s]")
    t.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    t.set_defaults(func=_radio_table)


def _simulate(args: argparse.Namespace) -> int:
    import numpy as np

    from mocapkit.imu.simulate import ImuErrorModel
    from mocapkit.suit.radio import RadioLink, RadioParams, ours_round_bytes, update_rate_hz
    from mocapkit.suit.simulator import SuitSimConfig, SuitSimulator
    from mocapkit.suit.transport import SerialTransport, Transport, UdpTransport

    round_hz = args.round_hz
    if round_hz is None and args.radio and args.mode == "orientation":
        round_hz = 0.95 * update_rate_hz(ours_round_bytes(args.sensors), args.radio_bps)
    cfg = SuitSimConfig(
        mode=args.mode,
        filter_name=args.filter,
        errors=ImuErrorModel.consumer_grade() if args.noise else None,
        round_hz=round_hz,
    )
    rng = np.random.default_rng(args.seed)
    sim = SuitSimulator.from_motion(args.motion, args.sensors, args.seconds, args.rate_hz, cfg, rng)
    transport: Transport = (
        SerialTransport(args.serial_port, args.baud)
        if args.serial_port
        else UdpTransport.connect(args.host, args.port)
    )
    link = None
    send: Callable[[bytes], None] = transport.send
    if args.radio:
        params = RadioParams(bps=args.radio_bps, loss=args.loss, reorder=args.reorder)
        link = RadioLink(transport.send, params, np.random.default_rng(args.seed + 1))
        send = link.send
    print(
        f"suit: streaming {args.sensors} sensors ({args.mode}) to {transport.name}",
        file=sys.stderr,
    )
    t0 = time.perf_counter()
    try:
        n = sim.stream(send, speed=args.speed)
    finally:
        if link is not None:
            link.close()
        transport.close()
    summary: dict[str, Any] = {
        "frames": n,
        "seconds": time.perf_counter() - t0,
        "hub": vars(sim.hub.stats),
    }
    if link is not None:
        summary["radio"] = dict(link.model.counts)
        if link.model.counts["overflow"]:
            print(
                f"suit: the radio dropped {link.model.counts['overflow']} of "
                f"{link.model.counts['sent']} frames (transmit buffer full): lower --round-hz "
                "or --rate-hz, or raise --radio-bps",
                file=sys.stderr,
            )
    if args.json:
        print_json(summary)
    else:
        print(f"sent {n} frames in {summary['seconds']:.2f} s", file=sys.stderr)
    return EXIT_OK


def _stats_json(rx: Any) -> dict[str, Any]:
    st = rx.stats()
    return {
        "datagrams": st.datagrams,
        "bytes": st.bytes,
        "dropped": st.dropped,
        "sensors": {
            str(sid): {
                "state": s.state,
                "delivered": s.delivered,
                "lost": s.lost,
                "duplicate": s.duplicate,
                "stale": s.stale,
                "reordered": s.reordered,
                "rate_hz": s.rate_hz,
                "latency_ms_p50": s.latency_ms_p50,
                "latency_ms_p99": s.latency_ms_p99,
                "battery_mv": s.battery_mv,
            }
            for sid, s in st.sensors.items()
        },
    }


def _table(rx: Any) -> Any:
    from rich.table import Table

    st = rx.stats()
    table = Table(
        title=f"suit receiver: {st.datagrams} datagrams, {st.dropped_total} dropped "
        + (str(st.dropped) if st.dropped else "")
    )
    for col in (
        "sensor",
        "state",
        "rate Hz",
        "delivered",
        "lost",
        "loss %",
        "dup",
        "stale",
        "latency p50 ms",
        "p99 ms",
    ):
        table.add_column(col, justify="right")
    for sid, s in st.sensors.items():
        table.add_row(
            str(sid),
            s.state,
            f"{s.rate_hz:.0f}",
            str(s.delivered),
            str(s.lost),
            f"{100 * s.loss_ratio:.2f}",
            str(s.duplicate),
            str(s.stale),
            f"{s.latency_ms_p50:.2f}",
            f"{s.latency_ms_p99:.2f}",
        )
    return table


def _receive(args: argparse.Namespace) -> int:
    from mocapkit.suit.receiver import Receiver, ReceiverConfig
    from mocapkit.suit.recording import McapRecorder
    from mocapkit.suit.transport import SerialTransport, Transport, UdpTransport

    transport: Transport = (
        SerialTransport(args.serial_port, args.baud)
        if args.serial_port
        else UdpTransport.bind(args.host, args.port)
    )
    out = getattr(args, "out", None) or getattr(args, "record", None)
    mode = args.samples or ("live" if args.protocols == "slimevr" else "at-close")
    samples_mode: Any = mode.replace("-", "_")
    recorder = McapRecorder(out, samples=samples_mode) if out else None
    rx = Receiver(transport, ReceiverConfig(protocols=args.protocols), recorder)
    stop = threading.Event()

    def drain() -> None:  # the pipeline's place: here we only keep the queues short
        while not stop.is_set():
            rx.get_batch(4096, 0.1)

    consumer = threading.Thread(target=drain, daemon=True)
    rx.start()
    consumer.start()
    deadline = None if args.seconds is None else time.monotonic() + args.seconds
    try:
        if args.json or not sys.stderr.isatty():
            while deadline is None or time.monotonic() < deadline:
                time.sleep(0.05)
        else:
            from rich.console import Console
            from rich.live import Live

            with Live(_table(rx), console=Console(stderr=True), refresh_per_second=4) as live:
                while deadline is None or time.monotonic() < deadline:
                    time.sleep(0.25)
                    live.update(_table(rx))
    finally:
        rx.stop()
        stop.set()
        consumer.join(timeout=2.0)
        transport.close()
        if recorder is not None:
            recorder.close()
    summary = _stats_json(rx)
    if recorder is not None:
        summary["recording"] = {
            "path": str(recorder.path),
            "frames": recorder.frames,
            "samples": recorder.samples,
        }
    if args.json:
        print_json(summary)
    else:
        from rich.console import Console

        Console(stderr=True).print(_table(rx))
    return EXIT_OK


def _replay(args: argparse.Namespace) -> int:
    from mocapkit.suit.recording import replay
    from mocapkit.suit.transport import UdpTransport

    tx = UdpTransport.connect(args.host, args.port)
    t0 = time.perf_counter()
    try:
        n = replay(Path(args.recording), tx.send, speed=args.speed)
    finally:
        tx.close()
    summary = {"frames": n, "seconds": time.perf_counter() - t0}
    if args.json:
        print_json(summary)
    else:
        print(f"replayed {n} frames in {summary['seconds']:.2f} s", file=sys.stderr)
    return EXIT_OK


def _decode(args: argparse.Namespace) -> int:
    import numpy as np

    from mocapkit.suit.batch import decode_stream
    from mocapkit.suit.recording import read_frames

    t0 = time.perf_counter()
    frames = read_frames(Path(args.recording))
    if not frames:
        from mocapkit.errors import FileFormatError

        raise FileFormatError(
            f"{args.recording}: no suit frames (/suit/packets) in this recording; a "
            "teleoperation recording (/teleop/...) is read by 'mocapkit teleop playback'"
        )
    buf = b"".join(f.data for f in frames)
    t1 = time.perf_counter()
    dec = decode_stream(buf)
    t2 = time.perf_counter()
    ids, counts = np.unique(dec.sensor_id, return_counts=True)
    decode_s = t2 - t1
    summary: dict[str, Any] = {
        "frames": len(frames),
        "valid_frames": dec.n_frames,
        "samples": len(dec),
        "skipped_bytes": dec.skipped_bytes,
        "read_s": t1 - t0,
        "decode_s": t2 - t1,
        "samples_per_sensor": {str(int(i)): int(c) for i, c in zip(ids, counts, strict=True)},
    }
    if args.json:
        print_json(summary)
    else:
        print(
            f"{dec.n_frames} valid frames of {len(frames)}, {len(dec)} samples, "
            f"decoded in {decode_s * 1e3:.1f} ms",
            file=sys.stderr,
        )
    return EXIT_OK


def _bench(args: argparse.Namespace) -> int:
    from mocapkit.suit.bench import run_loopback_bench

    r = run_loopback_bench(args.sensors, args.rate_hz, args.seconds, sender=args.sender)
    keys = ("sent", "received", "lost", "latency_ms_p50", "latency_ms_p99")
    if args.json:
        print_json({k: r[k] for k in keys})
    else:
        for k in (*keys, "drops", "send_late_ms_p99"):
            print(f"{k}: {r[k]}", file=sys.stderr)
    return EXIT_OK


def _radio_table(args: argparse.Namespace) -> int:
    from mocapkit.suit.radio import radio_rate_markdown, radio_rate_table

    if args.json:
        print_json(radio_rate_table(15, args.bps))
    else:
        sys.stdout.write(radio_rate_markdown(15, args.bps))
    return EXIT_OK
