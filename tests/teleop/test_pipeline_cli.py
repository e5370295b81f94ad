"""Per-packet pipeline faults (dropout, NaN), recording/playback, and the CLI in-process."""

from __future__ import annotations

import json
import time

import numpy as np
import pytest

from mocapkit.cli.main import main
from mocapkit.errors import DataError
from mocapkit.robot import robonaut2_arm
from mocapkit.robot.segment_retarget import (
    SegmentRetargeter,
    robonaut2_groups,
    robonaut2_init_posture,
)
from mocapkit.teleop.pipeline import ArmTeleop, OrientationSample
from mocapkit.teleop.recording import (
    TeleopRecorder,
    Trajectory,
    loop_trajectory,
    playback_pose,
    read_commands,
)
from mocapkit.teleop.session import State, TeleopSession

ID = np.array([1.0, 0.0, 0.0, 0.0])


def _pipe():
    arm = robonaut2_arm("right")
    rt = SegmentRetargeter(arm, robonaut2_groups("right")[:2], robonaut2_init_posture("right"))
    s = TeleopSession()
    p = ArmTeleop(arm, rt, {1: "humerus_r", 2: "radius_r"}, s, None, stale_after_s=0.1)
    p.calibrate({1: ID, 2: ID})
    return p, s


def test_dropout_and_nan_are_reported_and_recover():
    p, _ = _pipe()
    now = 100.0
    f = p.process([OrientationSample(1, time.perf_counter_ns(), ID),
                   OrientationSample(2, time.perf_counter_ns(), ID)], now)  # fmt: skip
    assert f.T_model is not None
    np.testing.assert_allclose(f.q, robonaut2_init_posture("right"), atol=1e-9)
    # sensor 2 drops out: after 0.1 s its data is stale
    f = p.process([OrientationSample(1, 0, ID)], now + 0.2)
    assert f.T_model is None
    assert p.watchdog.fault(now + 0.2) == "sensor 2: stale for 0.20 s (dropout?)"
    f = p.process([OrientationSample(2, 0, np.array([np.nan] * 4))], now + 0.21)
    assert "sensor 2: invalid orientation" in str(p.watchdog.fault(now + 0.21))
    f = p.process([OrientationSample(1, 0, ID), OrientationSample(2, 0, ID)], now + 0.3)
    assert f.T_model is not None


def test_pipeline_needs_every_segment():
    arm = robonaut2_arm("right")
    rt = SegmentRetargeter(arm, robonaut2_groups("right")[:2], robonaut2_init_posture("right"))
    with pytest.raises(DataError, match="no sensor for segment"):
        ArmTeleop(arm, rt, {1: "humerus_r"}, TeleopSession())
    p, s = _pipe()
    with pytest.raises(DataError, match="no orientation for sensor 2"):
        p.calibrate({1: ID})
    assert s.state == State.DISABLED


def test_recording_round_trip_and_loop_blend(tmp_path):
    t = np.linspace(0, 2, 201)
    pos = np.stack([0.5 + 0.1 * np.sin(np.pi * t), -0.3 + 0 * t, 0.01 * t], axis=1)  # 2 cm seam
    path = tmp_path / "m.mcap"
    with TeleopRecorder(path) as rec:
        for k in range(len(t)):
            rec.command(t[k], pos[k], ID)
        rec.transition(0.0, "aligning", "engaged", "aligned")
    traj = read_commands(path)
    np.testing.assert_allclose(traj.pos, pos)
    looped, check = loop_trajectory(traj)
    assert check.loops
    assert check.seam_pos_m == pytest.approx(0.02)
    np.testing.assert_allclose(looped.pos[-1], pos[0], atol=1e-12)  # seam closed
    p, _ = playback_pose(looped, looped.t[-1] + 0.01 + 0.3, loop=True)  # wraps around
    np.testing.assert_allclose(p, playback_pose(looped, 0.3, loop=True)[0], atol=1e-3)
    far = Trajectory(t, pos + np.outer(t, [0.1, 0, 0]), np.tile(ID, (len(t), 1)))
    assert not loop_trajectory(far)[1].loops  # 20 cm seam: plays once
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"nonsense")
    from mocapkit.errors import FileFormatError

    with pytest.raises(FileFormatError, match="bad.mcap"):
        read_commands(bad)


def test_cli_help_lists_examples(capsys):
    assert main(["teleop", "--help"]) == 0
    out = capsys.readouterr().out
    assert "mocapkit teleop evaluate --shape circle --json" in out


@pytest.mark.slow
def test_cli_evaluate_json_end_to_end(capsys, tmp_path):
    """A short real-time run: operator -> pipeline -> UDP -> robot-server process."""
    plot = tmp_path / "fig9.png"
    code = main(["teleop", "evaluate", "--shape", "vertical", "--shape-seconds", "1.5",
                 "--json", "--plot", str(plot), "--record", str(tmp_path / "r.mcap")])  # fmt: skip
    assert code == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out) == {"shape", "ee_rmse_mm", "lag_ms", "pipeline_ms_p50", "pipeline_ms_p99",
                        "joint_rmse_deg"}  # fmt: skip
    assert out["shape"] == "vertical"
    # loose sanity bounds (not timing): the chain tracks the shape to centimetres
    assert out["ee_rmse_mm"] < 50
    assert out["joint_rmse_deg"] < 5
    assert plot.stat().st_size > 0
    assert len(read_commands(tmp_path / "r.mcap").t) > 10
