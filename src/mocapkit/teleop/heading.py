"""The body's heading at calibration, refined from the first elbow flexion.

A pose calibration needs to know which way the body faced: with the arm hanging in the
N-pose no sensor shows it, so it comes from a sensor axis assumed to point forward
(:class:`~mocapkit.body.calibration.HeadingFromSensor`), and a sensor strapped on a few
degrees off turns the whole chest frame by that much. Teleoperation feels it directly: a
heading error ``d`` turns every hand displacement by ``d`` in the chest frame (a 10 cm
shape with 5 deg of heading error is 9 mm off).

The elbow is a hinge whose axis is known in the upper arm's frame (the tree's elbow axis,
Rajagopal's). When the forearm flexes relative to the upper arm, the relative rotation
``r(t) = q_world_humerus^-1 q_world_radius`` changes by a rotation about that axis, in the
upper arm's frame as the calibration computed it. A heading error ``d`` at calibration
conjugates every calibrated segment by ``Rz(d)`` at the pose, which for a hanging upper
arm is a turn about its own long axis: the measured elbow axis comes out turned by ``d``
about the upper arm's long axis. :class:`HingeHeading` measures that angle during the
first flexion of more than ``min_flex_deg`` after the calibration and gives the
corrected heading; the pipeline then recalibrates from the same pose window. No sensor
mounting is assumed: the axis comes from the two segments' relative motion.
"""

from __future__ import annotations

import math

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.body.sensor_tree import SensorTree
from mocapkit.teleop._kernels import relative_rotvec


class HingeHeading:
    """Watches ``child`` flexing about its joint's first axis relative to ``parent``.

    Args:
        tree: the sensor tree (the joint axis comes from ``child``'s joint).
        parent, child: segment names (``humerus_r``, ``radius_r``).
        min_flex_deg: the flexion used to measure the axis (the larger, the less the
            orientation noise matters).
    """

    def __init__(
        self, tree: SensorTree, parent: str, child: str, min_flex_deg: float = 60.0
    ) -> None:
        names = tree.segment_names
        self.i_parent = names.index(parent)
        self.i_child = names.index(child)
        axes = tree.segment(child).joint.axes
        self.axis_model = np.asarray(axes[0], dtype=np.float64) / np.linalg.norm(axes[0])
        self.long_axis = np.array([0.0, 1.0, 0.0])  # OpenSim segments: y along the bone
        self.min_flex = math.radians(min_flex_deg)
        self._r0: FloatArray | None = None
        self._r = np.empty(4)
        self._v = np.empty(3)
        self._sum = np.zeros(3)
        self.correction_rad: float | None = None
        """The heading correction [rad] once measured (add it to the heading)."""
        self.flex_rad = 0.0

    def update(self, q_world_segment: FloatArray) -> float | None:
        """One frame of calibrated segment orientations (S, 4); returns the heading
        correction [rad] on the frame it is measured, else None."""
        if self.correction_rad is not None:
            return None
        qp, qc = q_world_segment[self.i_parent], q_world_segment[self.i_child]
        if not (math.isfinite(qp[0] + qp[1] + qp[2] + qp[3] + qc[0] + qc[1] + qc[2] + qc[3])):
            return None
        if self._r0 is None:
            self._r0 = np.empty(4)
            relative_rotvec(qp, qc, np.array([1.0, 0.0, 0.0, 0.0]), self._r0, self._v)
            return None
        # the flexion since the calibration, in the parent's frame
        angle = relative_rotvec(qp, qc, self._r0, self._r, self._v)
        v = self._v
        self.flex_rad = angle
        if angle < 0.5 * self.min_flex:
            return None
        self._sum += v  # accumulate the axis over the second half of the flexion
        if angle < self.min_flex:
            return None
        axis = self._sum / np.linalg.norm(self._sum)
        if float(axis @ self.axis_model) < 0:  # an extension: same axis, other sense
            axis = -axis
        y = self.long_axis
        a = axis - (axis @ y) * y
        b = self.axis_model - (self.axis_model @ y) * y
        # the signed angle from the model's axis to the measured one about the long axis
        turn = math.atan2(float(y @ np.cross(b, a)), float(a @ b))
        self.correction_rad = turn
        return turn
