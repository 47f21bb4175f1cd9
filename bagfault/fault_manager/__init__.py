"""Fault manager oracle: ros2_medkit's debounce, correlation and snapshots on bag time."""
