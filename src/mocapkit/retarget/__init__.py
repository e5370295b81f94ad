"""Whole-body humanoid retargeting from either capture: human segment poses -> per-bone
scaled targets -> one QP per frame on the robot (Pinocchio + proxsuite). A robot is a
YAML file (``mocapkit/data/humanoids``)."""
