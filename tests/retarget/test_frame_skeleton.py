"""The live path's one-frame skeleton (numba) equals from_coordinates on that frame."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.body.sensor_tree import SensorTree
from mocapkit.errors import DataError
from mocapkit.retarget.human import TREE_TO_HUMAN, FrameSkeleton, from_coordinates

SEGMENTS = tuple(sorted(TREE_TO_HUMAN.values()))


@pytest.mark.parametrize("with_translation", [False, True])
def test_frame_skeleton_equals_from_coordinates(with_translation: bool) -> None:
    rng = np.random.default_rng(7)
    names = SensorTree.preset("full_body_15").coordinate_names
    fk = FrameSkeleton(SEGMENTS)
    for k in range(20):
        frame = {c: float(rng.uniform(-1.2, 1.2)) for c in names}
        if k % 3 == 0:  # a coordinate not reported: a zero coordinate, as from_coordinates
            frame.pop(names[5 + k % 7])
        if with_translation:
            frame.update(pelvis_tx=rng.uniform(-1, 1), pelvis_ty=0.9, pelvis_tz=rng.uniform(-1, 1))
        got = fk(0.01 * k, frame)
        want = from_coordinates(np.array([0.01 * k]), {c: np.array([v]) for c, v in frame.items()},
                                SEGMENTS)  # fmt: skip
        np.testing.assert_array_equal(got.time, want.time)
        for s in SEGMENTS:
            np.testing.assert_allclose(got.pos[s], want.pos[s], atol=1e-12)
            np.testing.assert_allclose(got.quat[s], want.quat[s], atol=1e-12)
            np.testing.assert_allclose(got.neutral_pos[s], want.neutral_pos[s], atol=1e-12)
            np.testing.assert_allclose(got.neutral_quat[s], want.neutral_quat[s], atol=1e-12)


def test_frame_skeleton_bad_input() -> None:
    with pytest.raises(DataError, match="'wing_r'"):
        FrameSkeleton(("pelvis", "wing_r"))
    fk = FrameSkeleton(SEGMENTS)
    with pytest.raises(DataError, match="pelvis_list"):
        fk(0.0, {"pelvis_tilt": 0.0, "pelvis_rotation": 0.0})
    # a NaN angle (a dropout upstream) counts as zero, as from_coordinates has it: no NaN pose
    frame = {"pelvis_tilt": 0.0, "pelvis_list": 0.0, "pelvis_rotation": 0.0,
             "knee_angle_r": float("nan")}  # fmt: skip
    m = fk(0.0, frame)
    assert all(np.isfinite(m.pos[s]).all() for s in SEGMENTS)
