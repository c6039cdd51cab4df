"""Stereo calibration: board detection, solving, gating, outputs, writing to a unit, ROS export."""
