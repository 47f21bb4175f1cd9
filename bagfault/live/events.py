"""Events on the live graph: every fault, assertion, scenario status and fault manager event as it happens.

Always as JSON on /bagfault/events (std_msgs/msg/String, reliable, transient
local with a history of 1000, so a recorder that joins late still gets the
timeline); and, where the anchor's interface packages are importable
(`ros2_fault_injection`, `ros2_medkit_msgs`), as those messages on the
anchor's own topics, so its RViz panel and scripts see bagfault's faults.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from bagfault.events import EVENTS_JSON_TOPIC, AssertionEvent, FaultEvent, ScenarioStatus, event_json
from bagfault.live.ros import has_interface, interface_class

if TYPE_CHECKING:
    from bagfault.engine.run import Run
    from bagfault.events import Event

HISTORY = 1000
LATCHED = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=HISTORY, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)


class LiveEvents:
    """Publishes a run's events as they are written (a listener of `Run.write_event`)."""

    def __init__(self, node: Any, *, anchor_topics: bool) -> None:
        self.node = node
        self.run: Run | None = None
        self.anchor_topics = anchor_topics  # False where the sink already publishes them (play, test)
        string = interface_class('std_msgs/msg/String')
        self._string = string
        self._json = node.create_publisher(string, EVENTS_JSON_TOPIC, LATCHED)
        self._anchor: dict[str, Any] = {}
        self.published = 0
        if anchor_topics:  # opened now, so a listener (volatile, as `ros2 topic echo`) is matched before the first
            for kind in (FaultEvent, AssertionEvent, ScenarioStatus):
                self._publisher(kind.topic, kind.msgtype)

    def attach(self, run: Run) -> None:
        """Publish this run's events (a play --loop attaches each pass)."""
        self.run = run
        run.event_listeners.append(self.publish)

    def publish(self, event: Event, data: bytes) -> None:
        """JSON always; the anchor's message where its type is installed."""
        origin = self.run.stats.origin if self.run is not None else None
        self._json.publish(self._string(data=event_json(event, origin)))
        self.published += 1
        if not self.anchor_topics or not has_interface(event.msgtype):
            return
        publisher = self._publisher(event.topic, event.msgtype)
        if publisher is not None:
            publisher.publish(data)

    def _publisher(self, topic: str, msgtype: str) -> Any:
        """The anchor-typed publisher of a topic, made on first use; None where the type is not installed."""
        publisher = self._anchor.get(topic)
        if publisher is None and has_interface(msgtype):
            publisher = self._anchor[topic] = self.node.create_publisher(interface_class(msgtype), topic, LATCHED)
        return publisher
