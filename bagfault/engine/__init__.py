"""Engine: the run loop, bag-time scheduler, router, time-ordered merge, per-fault random streams."""

__all__ = [  # its public modules (imported when used, not here)
    'activation',
    'build',
    'chunk_copy',
    'control',
    'fault_state',
    'lead',
    'merge',
    'offline',
    'options',
    'oracles',
    'pipeline',
    'provenance',
    'result',
    'routing',
    'run',
    'scheduler',
    'stop',
]
