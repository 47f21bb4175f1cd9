"""`bagfault record`: live topics into an MCAP with their schemas and QoS, for `bagfault check`.

Topics are matched as they appear (given names, or every topic with --all);
each is subscribed raw, with a QoS that accepts what its publishers offer
(best effort if any publisher is best effort, transient local if all are),
and written with the receive time on the node's clock (sim time with
use_sim_time). Definitions come from the standard types of the distro.
"""

from __future__ import annotations

import contextlib
import json
import time
from dataclasses import dataclass, field
from functools import partial
from typing import TYPE_CHECKING, Any

from bagfault import __version__
from bagfault.io.types import TypeCatalog
from bagfault.live.losses import LossCount
from bagfault.live.recording import start_recording
from bagfault.live.ros import adapted_qos, has_interface, interface_class, make_node, offered_metadata
from bagfault.live.runtime import ros_context
from bagfault.spec.names import absolute_topic

if TYPE_CHECKING:
    from collections.abc import Callable, Collection
    from pathlib import Path

    from bagfault.engine.stop import StopFlag

DISCOVERY_PERIOD = 0.1  # seconds between looks at the graph for new topics
DEPTH = 1000  # messages a topic may queue while the executor is busy elsewhere (keep-last drops beyond)


@dataclass
class RecordResult:
    """What a recording holds."""

    output: Path
    counts: dict[str, int] = field(default_factory=dict)
    missing: list[str] = field(default_factory=list)
    skipped: dict[str, str] = field(default_factory=dict)
    reason: str = ''
    lost: dict[str, int] = field(default_factory=dict)  # topic -> messages known lost (see Recorder.lost)


class Recorder:
    """Subscribes raw to matching topics as they appear and hands on what arrives.

    `on_topic(topic, msgtype, metadata)` (offered_qos_profiles, topic_type_hash) is called once per subscribed
    topic, `on_message(topic, data)` for every message (in the executor's
    thread). Topics in `exclude` are never subscribed.
    """

    def __init__(self, node: Any, topics: Collection[str], every: bool, *,
                 on_topic: Callable[[str, str, dict[str, str]], None], on_message: Callable[[str, bytes], None],
                 exclude: Collection[str] = (), every_excludes: tuple[str, ...] = (),
                 count_lost: bool = False) -> None:
        self.node = node
        self.wanted = set(topics)
        self.every = every
        self.exclude = set(exclude)
        self.every_excludes = every_excludes  # prefixes `every` does not take (they can still be named)
        self.on_topic = on_topic
        self.on_message = on_message
        self.subscriptions: dict[str, Any] = {}
        self.skipped: dict[str, str] = {}
        self.counts: dict[str, int] = {}
        # with `count_lost` (an executor that hands message info over: not rclpy's events executor), messages
        # known lost per topic (see LossCount)
        self.count_lost = count_lost
        self.losses = LossCount()

    def discover(self) -> list[str]:
        """Subscribe to matching topics that appeared since the last look; the topics newly subscribed."""
        added = []
        for topic, types in self.node.get_topic_names_and_types():
            if topic in self.subscriptions or topic in self.skipped or topic in self.exclude:
                continue
            if not ((self.every and not topic.startswith(self.every_excludes)) or topic in self.wanted):
                continue
            publishers = self.node.get_publishers_info_by_topic(topic)
            if not publishers:
                continue  # only subscribers so far: nothing to record, and no QoS to match
            msgtype = types[0]
            if not has_interface(msgtype):
                self.skipped[topic] = msgtype
                self.node.get_logger().warning(f'{topic}: {msgtype} has no Python bindings here; not recorded')
                continue
            self.subscribe(topic, msgtype)
            added.append(topic)
        return added

    def subscribe(self, topic: str, msgtype: str) -> None:
        """Subscribe raw to one topic now (QoS from its current publishers, whose profiles are recorded)."""
        infos = self.node.get_publishers_info_by_topic(topic)
        profile = adapted_qos(DEPTH, infos)
        self.on_topic(topic, msgtype, offered_metadata(infos))
        self.counts.setdefault(topic, 0)
        if self.count_lost:
            from rclpy.event_handler import SubscriptionEventCallbacks  # noqa: PLC0415

            events = SubscriptionEventCallbacks(message_lost=partial(self._lost, topic))
            self.subscriptions[topic] = self.node.create_subscription(
                interface_class(msgtype), topic, partial(self._received_with_info, topic),
                profile, raw=True, event_callbacks=events)
        else:
            self.subscriptions[topic] = self.node.create_subscription(
                interface_class(msgtype), topic, partial(self._received, topic), profile, raw=True)
        self.node.get_logger().info(f'recording {topic} ({msgtype})')

    def unmatched(self) -> list[str]:
        """Topics whose subscription has not yet matched every publisher the graph shows (a message sent before
        the match completes is not received)."""
        return sorted(topic for topic, subscription in self.subscriptions.items()
                      if subscription.get_publisher_count() < self.node.count_publishers(topic))

    def _received(self, topic: str, data: bytes) -> None:
        self.counts[topic] += 1
        self.on_message(topic, data)

    def _received_with_info(self, topic: str, data: bytes, info: dict[str, int]) -> None:
        self.losses.heard(topic, info, self.subscriptions[topic].get_publisher_count)
        self._received(topic, data)

    def _lost(self, topic: str, status: Any) -> None:
        self.losses.report(topic, status.total_count)

    def lost(self) -> dict[str, int]:
        """Messages known lost per topic, between the first and the last one received (see LossCount)."""
        return self.losses.lost()


def run_record(
    topics: list[str],
    output: Path,
    *,
    every: bool = False,
    duration: float | None = None,
    use_sim_time: bool = False,
    stop: StopFlag,
    ros_args: list[str] | None = None,
) -> RecordResult:
    """Record until `duration` seconds (wall clock) have passed or a stop; the file is complete on return."""
    from rclpy.executors import SingleThreadedExecutor  # noqa: PLC0415
    from rclpy.parameter import Parameter  # noqa: PLC0415

    names = [absolute_topic(t) for t in topics]
    with ros_context(stop) as context:
        overrides = [Parameter('use_sim_time', Parameter.Type.BOOL, True)] if use_sim_time else []
        node = make_node('bagfault_recorder', context, ros_args, parameter_overrides=overrides)
        executor = SingleThreadedExecutor(context=context)  # hands each message's info over (sequence numbers)
        executor.add_node(node)
        metadata = {'tool': 'bagfault', 'version': __version__, 'mode': 'record',
                    'topics': ' '.join(names) if names else '--all'}
        with contextlib.ExitStack() as closing, start_recording(output, metadata) as recording:
            closing.callback(node.destroy_node)
            closing.callback(executor.shutdown)
            catalog = TypeCatalog([], 'jazzy')
            channels: dict[str, int] = {}

            def on_topic(topic: str, msgtype: str, metadata: dict[str, str]) -> None:
                channels[topic] = recording.add_channel(topic, msgtype, *catalog.schema(msgtype), 'cdr', metadata)

            def on_message(topic: str, data: bytes) -> None:
                now = node.get_clock().now().nanoseconds
                recording.write(channels[topic], now, now, data)

            recorder = Recorder(node, names, every, on_topic=on_topic, on_message=on_message, count_lost=True)
            node.get_logger().info('bagfault record ready')
            started = last_look = time.monotonic()
            recorder.discover()
            while not stop.is_set():
                now = time.monotonic()
                if duration is not None and now - started >= duration:
                    stop.set('duration')
                    break
                if now - last_look >= DISCOVERY_PERIOD:
                    recorder.discover()
                    last_look = now
                executor.spin_once(timeout_sec=0.05)
                recording.tick()
            lost = recorder.lost()
            recording.add_metadata('bagfault.recording', {'received': json.dumps(recorder.counts, sort_keys=True),
                                                          'lost': json.dumps(lost, sort_keys=True)})
            recording.finish()
    return RecordResult(output, dict(recorder.counts), sorted(set(names) - set(recorder.subscriptions)),
                        dict(recorder.skipped), stop.reason, lost)
