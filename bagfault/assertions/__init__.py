"""Assertions: expected outcomes checked on the engine's clock."""

__all__ = [  # its public modules (imported when used, not here)
    'base',
    'fault_event',
    'fault_status',
    'field_delta',
    'field_range',
    'fields',
    'message_count',
    'path_latency',
    'registry',
    'runner',
    'sequence',
    'topic_gap',
    'topic_hz',
    'windows',
]
