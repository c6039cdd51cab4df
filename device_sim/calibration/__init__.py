"""Metric camera support: per-unit truth, lens rays, the chessboard scene, rectification, flash store.

The calibration data model itself is shared with the host: protocol.calibration.
"""
