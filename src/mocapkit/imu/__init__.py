"""Inertial orientation estimation: filters, initialisation, calibration, evaluation."""
