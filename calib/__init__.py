"""Calibration: rigid-body fit, tip pivot calibration, force tare and matrix, clock alignment."""
