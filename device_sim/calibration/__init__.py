"""Metric camera support: calibration model, per-unit truth, rays, rectification, flash store."""
