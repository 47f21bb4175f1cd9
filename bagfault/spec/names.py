"""ROS names as scenarios and command lines give them: a topic without a leading '/' is in the root namespace."""

from __future__ import annotations


def absolute_topic(topic: str) -> str:
    """`topic` as ROS resolves a relative name in the root namespace: '/scan' for 'scan' and for '/scan'."""
    return topic if topic.startswith('/') else f'/{topic}'
