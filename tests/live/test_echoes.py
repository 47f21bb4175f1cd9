"""OwnEchoes: the listener of `bagfault test` tells bagfault's own messages on a played topic from the system's."""

from __future__ import annotations

import time

from bagfault.live.echoes import OwnEchoes


def test_own_messages_are_dropped_once_each_and_the_rest_is_the_systems() -> None:
    echoes = OwnEchoes()
    echoes.listen('/odom')
    for data in (b'a', b'b', b'a'):
        echoes.sent('/odom', data)
    # what came back: bagfault's three, interleaved with the system's b'a' after they were used up
    heard = [b'a', b'b', b'a', b'a', b'c']
    assert [echoes.take('/odom', data) for data in heard] == [True, True, True, False, False]


def test_identical_messages_each_need_their_own_note() -> None:
    echoes = OwnEchoes()
    echoes.listen('/enable')
    for _ in range(100):  # a constant message, as std_msgs/Bool true at 10 Hz
        echoes.sent('/enable', b'\x01')
    assert sum(echoes.take('/enable', b'\x01') for _ in range(101)) == 100


def test_topics_not_listened_to_are_not_noted() -> None:
    echoes = OwnEchoes()
    assert not echoes
    echoes.listen('/odom')
    assert echoes and '/odom' in echoes and '/imu' not in echoes
    echoes.sent('/imu', b'x')
    assert not echoes.take('/imu', b'x')
    assert not echoes.take('/odom', b'x')


def test_notes_never_heard_back_are_forgotten_after_keep() -> None:
    echoes = OwnEchoes(keep=0.05)
    echoes.listen('/odom')
    echoes.sent('/odom', b'lost')  # published before the listener matched: never comes back
    echoes.sent('/odom', b'a')
    assert echoes.take('/odom', b'a')
    time.sleep(0.1)
    echoes.sent('/odom', b'b')
    assert not echoes.take('/odom', b'lost')  # the same bytes from the system, later: the system's
    assert echoes.take('/odom', b'b')


def test_expiry_keeps_the_newer_note_of_the_same_bytes() -> None:
    echoes = OwnEchoes(keep=0.05)
    echoes.listen('/enable')
    echoes.sent('/enable', b'\x01')
    assert echoes.take('/enable', b'\x01')  # the first came back
    time.sleep(0.1)
    echoes.sent('/enable', b'\x01')  # the first note expires now; this one stays
    assert echoes.take('/enable', b'\x01')
    assert not echoes.take('/enable', b'\x01')


def test_a_latched_topic_notes_the_history_a_late_subscriber_receives() -> None:
    echoes = OwnEchoes()
    echoes.listen('/tf_static', (b'base->laser', b'base->imu'))
    assert echoes.take('/tf_static', b'base->imu')
    assert echoes.take('/tf_static', b'base->laser')
    assert not echoes.take('/tf_static', b'map->odom')
