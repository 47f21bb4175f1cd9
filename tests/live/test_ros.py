"""QoS from rosbag2's recorded offered_qos_profiles (numbers in older releases, names in newer)."""

from __future__ import annotations

import pytest
import yaml

rclpy = pytest.importorskip('rclpy')

from rclpy.qos import DurabilityPolicy, ReliabilityPolicy  # noqa: E402

from bagfault.live.ros import offered_yaml, qos, recorded_qos  # noqa: E402

pytestmark = pytest.mark.live  # needs rclpy

HUMBLE_TF_STATIC = ('- history: 3\n  depth: 0\n  reliability: 1\n  durability: 1\n  deadline:\n    sec: 9223372036\n'
                    '    nsec: 854775807\n  liveliness: 1\n  avoid_ros_namespace_conventions: false')
HUMBLE_CLOCK = '- history: 3\n  depth: 0\n  reliability: 2\n  durability: 2\n'
NAMED = '- history: keep_last\n  depth: 5\n  reliability: best_effort\n  durability: transient_local\n'


def test_numbers_and_names_of_rosbag2_profiles() -> None:
    latched = recorded_qos(HUMBLE_TF_STATIC)
    assert (latched.reliability, latched.durability, latched.depth) == (
        ReliabilityPolicy.RELIABLE, DurabilityPolicy.TRANSIENT_LOCAL, 10)  # depth 0 recorded: default depth
    clock = recorded_qos(HUMBLE_CLOCK)
    assert (clock.reliability, clock.durability) == (ReliabilityPolicy.BEST_EFFORT, DurabilityPolicy.VOLATILE)
    named = recorded_qos(NAMED)
    assert (named.reliability, named.durability, named.depth) == (
        ReliabilityPolicy.BEST_EFFORT, DurabilityPolicy.TRANSIENT_LOCAL, 5)


def test_unknown_profiles_give_none_and_written_profiles_read_back() -> None:
    assert recorded_qos('') is None and recorded_qos(': not yaml [') is None and recorded_qos('{}') is None
    profile = qos(7, 'best_effort', 'transient_local')
    again = recorded_qos(offered_yaml([profile, qos(3)]))  # the first publisher's profile is the one replayed
    assert (again.reliability, again.durability, again.depth) == (
        ReliabilityPolicy.BEST_EFFORT, DurabilityPolicy.TRANSIENT_LOCAL, 7)
    # rmw's numbers and nine keys (rmw/types.h: KEEP_LAST 1, RELIABLE 1, VOLATILE 2; a profile made in rclpy
    # leaves deadline, lifespan and liveliness at their defaults, 0 = system default)
    zero = {'sec': 0, 'nsec': 0}
    assert yaml.safe_load(offered_yaml([profile, qos(3)]))[1] == {
        'history': 1, 'depth': 3, 'reliability': 1, 'durability': 2, 'deadline': zero, 'lifespan': zero,
        'liveliness': 0, 'liveliness_lease_duration': zero, 'avoid_ros_namespace_conventions': False}


def test_adapted_qos_follows_rosbag2s_adapt_request_to_offers() -> None:
    """rosbag2_storage/src/rosbag2_storage/qos.cpp, Rosbag2QoS::adapt_request_to_offers: reliable only when
    every publisher offers it, transient local only when every one does; the default when there is none."""
    from types import SimpleNamespace

    from bagfault.live.ros import adapted_qos

    def offers(*profiles):
        return [SimpleNamespace(qos_profile=p) for p in profiles]

    latched = qos(1, 'reliable', 'transient_local')
    mixed = adapted_qos(10, offers(qos(5), qos(5, 'best_effort')))
    assert (mixed.reliability, mixed.durability, mixed.depth) == (
        ReliabilityPolicy.BEST_EFFORT, DurabilityPolicy.VOLATILE, 10)
    both_latched = adapted_qos(10, offers(latched, latched))
    assert (both_latched.reliability, both_latched.durability) == (
        ReliabilityPolicy.RELIABLE, DurabilityPolicy.TRANSIENT_LOCAL)
    one_latched = adapted_qos(10, offers(latched, qos(5)))
    assert one_latched.durability == DurabilityPolicy.VOLATILE
    none = adapted_qos(10, [])
    assert (none.reliability, none.durability) == (ReliabilityPolicy.RELIABLE, DurabilityPolicy.VOLATILE)


class _Matched:
    def __init__(self, publishers: int) -> None:
        self.publishers = publishers

    def get_publisher_count(self) -> int:
        return self.publishers


def test_lost_messages_are_sequence_gaps_of_one_publisher_only() -> None:
    """Gaps in one publisher's sequence numbers are losses (by hand: 1, 2, 5, 9 lost 2 + 3); a restarted
    publisher counts from its new start (1, 2, 4: one more); with two publishers matched a jump is the other's, not a loss, and
    that topic is no longer counted (1, 7, 2, 8 from two publishers would have made 5 + 5 false losses)."""
    from bagfault.live.recorder import Recorder

    recorder = Recorder(None, ['/a', '/b'], False, on_topic=lambda *_: None, on_message=lambda *_: None,
                        count_lost=True)
    recorder.subscriptions = {'/a': _Matched(1), '/b': _Matched(2)}
    recorder.counts = {'/a': 0, '/b': 0}
    for sequence in (1, 2, 5, 9, 1, 2, 4):  # then the publisher restarted; its message 3 lost
        recorder._received_with_info('/a', b'', {'publication_sequence_number': sequence})
    for sequence in (1, 7, 2, 8, 3, 9):
        recorder._received_with_info('/b', b'', {'publication_sequence_number': sequence})
    assert recorder.lost() == {'/a': 2 + 3 + 1}
    assert recorder.counts == {'/a': 7, '/b': 6}
