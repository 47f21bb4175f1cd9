"""Path latency from bag data, with CARET architecture files."""

__all__ = [  # its public modules (imported when used, not here)
    'architecture',
    'collect',
    'compute',
    'measure',
]
