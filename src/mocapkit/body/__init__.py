"""Human body models: sensor-to-segment trees, calibration, segment orientations and joint
angles from inertial sensors; skeleton models, marker sets and scaling for optical capture."""
