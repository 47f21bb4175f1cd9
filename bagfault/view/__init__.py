"""Views of a run while it happens: a Foxglove WebSocket server (`--foxglove`)."""

__all__ = [  # its public modules (imported when used, not here)
    'foxglove',
    'relay',
]
