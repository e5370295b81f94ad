"""Orientation filters on simulated suits: every filter against the exact truth.

    python -m benchmarks.imu_synthetic                 # the whole suite, writes docs
    python -m benchmarks.imu_synthetic --quick --no-write   # 100 Hz, consumer-grade only

BROAD (:mod:`benchmarks.polaris_vs_vqf`) is real data but one sensor on a rigid body moved
by hand. This suite asks whether the ranking holds where the project uses its filters: on
body segments, with the linear accelerations of limbs, at other rates and sensor grades.
Motions (``MOTIONS``, each sampled at 400 Hz and decimated, so every rate sees the same
motion and the truth is exact at every sample):

- ``arm_shapes``: the teleoperation operator (:mod:`mocapkit.teleop.operator_cycle`, the
  body model) tracing infinity, circle and box (upper arm, forearm, and the torso sensor,
  which stays still);
- ``walk``: limbs of the suit's walking motion (:mod:`mocapkit.suit.motions`: pelvis,
  forearm, thigh, shank, foot), moving from the first sample;
- ``wave``: the suit's waving arm (upper arm, forearm, hand), moving from the first sample;
- ``fast_rotation``: a hand-held sensor in bursts of rotation up to ~600 deg/s about
  changing axes with 0.15 m translations, 3 s of rest between bursts;
- ``long_rest``: a tilted sensor at rest for 40 s, a slow 6 s turn, 20 s of rest.

Rates 50, 100, 200, 400 Hz; error models (:class:`mocapkit.imu.simulate.ImuErrorModel`):
``ideal``, ``consumer`` (``consumer_grade``), ``tactical`` (``tactical_grade``) and
``disturbed`` (consumer-grade with two magnetic disturbances of 25 and 40 uT, 15 % and
5 % of the run). Filters: every registered one (online), ``polaris`` offline, and the peers
vqf (online, offline; the ``bench`` extra). Errors (BROAD's definitions,
:mod:`mocapkit.imu.metrics`) after the first second: 9D total RMSE and 6D inclination RMSE.
The inputs are the sensors' readings as they are (no bias removed beforehand), so
a filter that does not estimate the gyroscope bias carries it.
"""

from __future__ import annotations

import argparse
import math
import time
import zlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mocapkit.geometry import quat_exp, quat_from_axis_angle, quat_mul, quat_normalize
from mocapkit.imu.filters import Polaris, available_filters, make_filter
from mocapkit.imu.metrics import orientation_rmse
from mocapkit.imu.simulate import ImuErrorModel, MagDisturbance, simulate_imu
from mocapkit.series import ImuRecording, PoseSeries
from mocapkit.suit.motions import FULL_BODY_SEGMENTS, suit_poses
from mocapkit.teleop.operator_cycle import arm_sensor_poses

REPO = Path(__file__).resolve().parents[1]
BASE_RATE = 400.0
RATES = (50.0, 100.0, 200.0, 400.0)
ERROR_MODELS = ("ideal", "consumer", "tactical", "disturbed")
SETTLE_S = 1.0  # errors are taken after this time (initialisation)
HEADING = "## Orientation filters on simulated suits"


# -- motions ---------------------------------------------------------------------------------
def _arm_shapes() -> dict[str, PoseSeries]:
    poses = arm_sensor_poses(("infinity", "circle", "box"), BASE_RATE, 6.0, seed=0)
    names = {"upper_arm_r": "upper_arm", "forearm_r": "forearm", "torso": "chest"}
    return {names[name]: p for name, p in poses.items()}


def _suit(motion: str, segments: tuple[str, ...], duration_s: float) -> dict[str, PoseSeries]:
    poses = suit_poses(motion, len(FULL_BODY_SEGMENTS), duration_s, BASE_RATE)
    out = {}
    for sid, p in poses.items():
        seg = FULL_BODY_SEGMENTS[sid - 1]
        if seg in segments:
            out[seg] = p
    return out


def _integrate(w: np.ndarray, q0: np.ndarray) -> np.ndarray:
    """``q[k] = q[k-1] exp(w[k] dt / 2)`` at BASE_RATE (the simulator recovers ``w``)."""
    steps = quat_exp(w / (2.0 * BASE_RATE))
    q = np.empty((len(w), 4))
    cur = quat_normalize(q0)
    for k in range(len(w)):
        cur = quat_normalize(quat_mul(cur, steps[k]))
        q[k] = cur
    return q


def _smoothstep(u: np.ndarray) -> np.ndarray:
    u = np.clip(u, 0.0, 1.0)
    return u**3 * (10 - 15 * u + 6 * u**2)


def _fast_rotation() -> dict[str, PoseSeries]:
    n = round(32.0 * BASE_RATE)
    t = np.arange(n) / BASE_RATE
    env = np.zeros(n)
    for start in (3.0, 10.0, 17.0, 24.0):  # 4 s bursts, 3 s rests
        u = (t - start) / 4.0
        env += np.where((u > 0) & (u < 1), np.sin(np.pi * np.clip(u, 0, 1)) ** 2, 0.0)
    freqs = np.array([0.9, 1.3, 1.7])
    w = np.radians(350.0) * env[:, None] * np.sin(2 * np.pi * freqs * t[:, None] + [0, 1, 2])
    q = _integrate(w, quat_from_axis_angle(np.array([1.0, 1.0, 0.0]), 0.4))
    pos = 0.15 * env[:, None] * np.sin(2 * np.pi * np.array([0.7, 1.1, 0.9]) * t[:, None])
    return {"hand_held": PoseSeries(t, q, pos + np.array([0.0, 0.0, 1.2]), name="hand_held")}


def _long_rest() -> dict[str, PoseSeries]:
    n = round(66.0 * BASE_RATE)
    t = np.arange(n) / BASE_RATE
    # a slow turn of 90 deg between 40 and 46 s: the rate is the smoothstep's derivative
    u = (t - 40.0) / 6.0
    rate = np.where((u > 0) & (u < 1), 30 * u**2 * (1 - u) ** 2, 0.0) * (np.pi / 2) / 6.0
    axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    q = _integrate(rate[:, None] * axis, quat_from_axis_angle(np.array([1.0, 0.2, 0.0]), 0.5))
    pos = 0.3 * _smoothstep(u)[:, None] * np.array([1.0, 0.5, 0.2])
    return {"resting": PoseSeries(t, q, pos + np.array([0.0, 0.0, 1.0]), name="resting")}


MOTIONS: dict[str, Callable[[], dict[str, PoseSeries]]] = {
    "arm_shapes": _arm_shapes,
    "walk": lambda: _suit("walk", ("pelvis", "forearm_r", "thigh_r", "shank_r", "foot_r"), 30.0),
    "wave": lambda: _suit("wave", ("upper_arm_r", "forearm_r", "hand_r"), 30.0),
    "fast_rotation": _fast_rotation,
    "long_rest": _long_rest,
}


def decimate(pose: PoseSeries, rate_hz: float) -> PoseSeries:
    step = round(BASE_RATE / rate_hz)
    return PoseSeries(pose.time[::step], pose.quat[::step], pose.pos[::step], name=pose.name)


def error_model(name: str, duration_s: float) -> tuple[ImuErrorModel | None, list[MagDisturbance]]:
    if name == "ideal":
        return None, []
    if name == "tactical":
        return ImuErrorModel.tactical_grade(), []
    dist: list[MagDisturbance] = []
    if name == "disturbed":
        d = duration_s
        dist = [
            MagDisturbance(0.30 * d, 0.45 * d, (15.0, -10.0, 17.0)),
            MagDisturbance(0.60 * d, 0.65 * d, (-30.0, 20.0, 15.0)),
        ]
    return ImuErrorModel.consumer_grade(), dist


# -- filters ---------------------------------------------------------------------------------
Runner = Callable[[ImuRecording], tuple[np.ndarray, np.ndarray]]  # -> (q9, q6)


def _registered(name: str) -> Runner:
    def run(rec: ImuRecording) -> tuple[np.ndarray, np.ndarray]:
        if name == "polaris":
            return Polaris(rate_hz=rec.rate_hz).run_both(rec.gyr, rec.acc, rec.mag)
        q9 = make_filter(name, rec.rate_hz).run(rec.gyr, rec.acc, rec.mag)
        q6 = make_filter(name, rec.rate_hz).run(rec.gyr, rec.acc)
        return q9, q6

    return run


def _polaris_offline(rec: ImuRecording) -> tuple[np.ndarray, np.ndarray]:
    r = Polaris(rate_hz=rec.rate_hz).smooth(rec.gyr, rec.acc, rec.mag)
    assert r.q9 is not None
    return r.q9, r.q6


def _vqf(offline: bool) -> Runner:
    import vqf

    def run(rec: ImuRecording) -> tuple[np.ndarray, np.ndarray]:
        g, a, m = (np.ascontiguousarray(x) for x in (rec.gyr, rec.acc, rec.mag))
        dt = 1.0 / rec.rate_hz
        out = vqf.offlineVQF(g, a, m, dt) if offline else vqf.VQF(dt).updateBatch(g, a, m)
        return out["quat9D"], out["quat6D"]

    return run


def filters(include_peers: bool = True) -> dict[str, Runner]:
    out = {name: _registered(name) for name in available_filters()}
    out["polaris offline"] = _polaris_offline
    if include_peers:
        try:
            out["vqf"] = _vqf(False)
            out["vqf offline"] = _vqf(True)
        except ImportError:
            print("vqf not installed (pip install 'mocapkit[bench]'): peers skipped")
    return out


# -- the suite -------------------------------------------------------------------------------
@dataclass(frozen=True)
class Row:
    motion: str
    sensor: str
    rate_hz: float
    errors: str
    filter: str
    total9_deg: float
    incl6_deg: float


def _seed(*parts: object) -> int:
    return zlib.crc32("/".join(str(p) for p in parts).encode())


def run_suite(
    motions: list[str], rates: list[float], errors: list[str], runners: dict[str, Runner]
) -> list[Row]:
    rows = []
    for motion in motions:
        poses = MOTIONS[motion]()
        for sensor, pose400 in poses.items():
            for rate in rates:
                pose = decimate(pose400, rate)
                duration = float(pose.time[-1])
                sel = pose.time >= SETTLE_S
                for err_name in errors:
                    model, dist = error_model(err_name, duration)
                    rng = np.random.default_rng(_seed(motion, sensor, rate, err_name))
                    rec = simulate_imu(pose, model, None, dist, rng if model else None)
                    for fname, run in runners.items():
                        q9, q6 = run(rec)
                        e9 = orientation_rmse(q9, pose.quat, sel)
                        e6 = orientation_rmse(q6, pose.quat, sel, align_heading=True)
                        rows.append(
                            Row(
                                motion,
                                sensor,
                                rate,
                                err_name,
                                fname,
                                math.degrees(e9.total),
                                math.degrees(e6.inclination),
                            )
                        )
        print(f"  {motion}: done", flush=True)
    return rows


# -- tables ----------------------------------------------------------------------------------
def _mean(rows: list[Row], attr: str) -> float:
    return float(np.mean([getattr(r, attr) for r in rows])) if rows else float("nan")


def _table(
    rows: list[Row], names: list[str], cols: list[tuple[str, Callable[[Row], bool]]], attr: str
) -> list[str]:
    """Rows = filters, columns = groups; the best of each column in bold."""
    values = {
        n: [_mean([r for r in rows if r.filter == n and keep(r)], attr) for _, keep in cols]
        for n in names
    }
    best = [min(values[n][j] for n in names) for j in range(len(cols))]
    out = ["| filter | " + " | ".join(c for c, _ in cols) + " |"]
    out.append("|---|" + "---:|" * len(cols))
    for n in names:
        cells = [
            f"**{v:.2f}**" if math.isclose(v, best[j], rel_tol=0.005) else f"{v:.2f}"
            for j, v in enumerate(values[n])
        ]
        out.append(f"| {n} | " + " | ".join(cells) + " |")
    return out


def _wins(rows: list[Row], names: list[str], attr: str, online: list[str]) -> str:
    """How often each online filter is best (within 2 %) over every case."""
    cases: dict[tuple[str, str, float, str], dict[str, float]] = {}
    for r in rows:
        cases.setdefault((r.motion, r.sensor, r.rate_hz, r.errors), {})[r.filter] = getattr(r, attr)
    count = dict.fromkeys(online, 0)
    for vals in cases.values():
        best = min(vals[n] for n in online if n in vals)
        for n in online:
            if n in vals and vals[n] <= 1.02 * best + 1e-3:
                count[n] += 1
    return ", ".join(f"{n} {count[n]}" for n in online) + f" (of {len(cases)} cases)"


def report(rows: list[Row], seconds: float, command: str) -> str:
    names = list(dict.fromkeys(r.filter for r in rows))
    online = [n for n in names if "offline" not in n]
    errs = list(dict.fromkeys(r.errors for r in rows))
    rates = sorted({r.rate_hz for r in rows})
    motions = list(dict.fromkeys(r.motion for r in rows))
    lines = [
        f"`{command}` (module docstring: motions, rates, error models). Mean RMSE [deg] "
        f"over every sensor of every motion after the first {SETTLE_S:g} s; "
        f"{len(rows) // max(1, len(names))} cases per filter; {seconds:.0f} s "
        "(measured under load). Best in bold; offline filters see the whole recording.",
        "",
    ]
    for attr, title in (("total9_deg", "9D total"), ("incl6_deg", "6D inclination")):
        lines += [f"**{title}**, by error model (all motions and rates):", ""]
        lines += _table(rows, names, [(e, lambda r, e=e: r.errors == e) for e in errs], attr)
        lines += ["", f"{title}, consumer-grade, by rate (all motions):", ""]
        cons = [r for r in rows if r.errors == "consumer"] or rows
        lines += _table(
            cons, names, [(f"{x:g} Hz", lambda r, x=x: r.rate_hz == x) for x in rates], attr
        )
        lines += ["", f"{title}, consumer-grade, by motion (all rates):", ""]
        lines += _table(cons, names, [(m, lambda r, m=m: r.motion == m) for m in motions], attr)
        lines += [
            "",
            f"Cases where each online filter is best (within 2 %): "
            f"{_wins(rows, names, attr, online)}.",
            "",
        ]
    return "\n".join(lines)


def write_section(text: str) -> Path:
    path = REPO / "docs" / "benchmarks.md"
    content = path.read_text()
    section = f"{HEADING}\n\n{text}\n"
    if HEADING in content:
        start = content.index(HEADING)
        nxt = content.find("\n## ", start + len(HEADING))
        content = content[:start] + section + (content[nxt + 1 :] if nxt >= 0 else "")
    else:
        content = content.rstrip("\n") + "\n\n" + section
    path.write_text(content)
    return path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="100 Hz, consumer-grade only")
    parser.add_argument("--motions", default=",".join(MOTIONS))
    parser.add_argument("--rates", default=",".join(f"{r:g}" for r in RATES))
    parser.add_argument("--errors", default=",".join(ERROR_MODELS))
    parser.add_argument("--no-peers", action="store_true")
    parser.add_argument("--no-write", action="store_true", help="print only")
    args = parser.parse_args()
    rates = [100.0] if args.quick else [float(x) for x in args.rates.split(",")]
    errs = ["consumer"] if args.quick else args.errors.split(",")
    motions = args.motions.split(",")
    runners = filters(not args.no_peers)
    t0 = time.perf_counter()
    rows = run_suite(motions, rates, errs, runners)
    seconds = time.perf_counter() - t0
    text = report(rows, seconds, "python -m benchmarks.imu_synthetic")
    print(text)
    full = not args.quick and len(rates) == len(RATES) and len(errs) == len(ERROR_MODELS)
    if not args.no_write and full and len(motions) == len(MOTIONS):
        print(f"written to {write_section(text)}")


if __name__ == "__main__":
    main()
