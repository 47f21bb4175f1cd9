"""Fault manager oracle: ros2_medkit's debounce, correlation and snapshots on bag time."""

__all__ = [  # its public modules (imported when used, not here)
    'config',
    'correlation',
    'manager',
    'model',
    'observer',
    'reporters',
    'snapshots',
]
