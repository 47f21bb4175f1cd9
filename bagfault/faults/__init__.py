"""Reusable fault primitives: combining active faults, drop, noise, rotations."""

__all__ = [  # its public modules (imported when used, not here)
    'active',
    'cdr',
    'combine',
    'drop',
    'fieldpath',
    'header',
    'noise',
    'rng',
    'rotation',
]
