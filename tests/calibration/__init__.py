"""Tests of the calibration package (issue 13)."""
