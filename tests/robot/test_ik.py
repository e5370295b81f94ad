"""Damped-least-squares IK: reachable targets, limits, unreachable targets."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.errors import ConfigError
from mocapkit.robot import IkParams, ik_step, robonaut2_arm, solve_ik


def test_reaches_nearby_targets_within_limits():
    arm = robonaut2_arm("right")
    rng = np.random.default_rng(3)
    for _ in range(20):
        q_true = np.clip(arm.q_ref + rng.normal(0, 0.25, arm.n), arm.lower, arm.upper)
        res = solve_ik(arm, arm.fk(q_true), arm.q_ref)
        assert res.reached, res
        assert arm.within_limits(res.q).all()
        # the solver's own tolerances (1e-5 m, 1e-4 rad) times its reporting margin of 10
        assert res.pos_err_m < 1e-4
        assert res.rot_err_rad < 1e-3


def test_unreachable_target_returns_closest_pose():
    arm = robonaut2_arm("right")
    T = arm.fk(arm.q_ref)
    T[:3, 3] += [1.5, 0.0, 0.0]  # 1.5 m further forward: beyond the 0.8 m arm
    res = solve_ik(arm, T, arm.q_ref)
    assert not res.reached
    assert 0.5 < res.pos_err_m < 1.5
    assert arm.within_limits(res.q).all()


def test_step_respects_the_joint_speed_cap():
    arm = robonaut2_arm("right")
    T = arm.fk(arm.q_ref)
    T[:3, 3] += [0.0, 0.0, 0.2]
    cap = arm.velocity_limit * 0.01
    q_new, err, _ = ik_step(arm, arm.q_ref, T, max_dq=cap)
    assert np.all(np.abs(q_new - arm.q_ref) <= cap + 1e-12)
    assert np.linalg.norm(err[:3]) == pytest.approx(0.2)


def test_joint_at_limit_is_frozen_not_pushed_through():
    arm = robonaut2_arm("right")
    q = arm.q_ref.copy()
    q[3] = 0.0  # elbow straight: at its upper limit
    T = arm.fk(q)
    T[:3, 3] += [0.3, 0.0, 0.0]  # further than the straight arm reaches
    q_new, _, _frozen = ik_step(arm, q, T)
    assert arm.within_limits(q_new).all()
    assert q_new[3] <= 0.0


def test_params_are_validated():
    with pytest.raises(ConfigError, match=r"IkParams.rot_weight_m: expected a positive number"):
        IkParams(rot_weight_m=0.0)
    with pytest.raises(ConfigError, match=r"IkParams.max_iters: expected >= 1"):
        IkParams(max_iters=0)
