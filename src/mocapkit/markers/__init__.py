"""Optical marker data: cleaning, and reconstruction of joint angles by direct marker
control (prioritized operational-space control of marker subsets) or by weighted
least-squares inverse kinematics, with per-frame joint-error bounds."""
