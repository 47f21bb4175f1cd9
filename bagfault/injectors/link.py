"""Stream faults between two nodes of the system under test (`link`): schema here, carried out by the closed loop."""

from __future__ import annotations

from typing import Any, ClassVar

from bagfault.errors import InjectorConfigError
from bagfault.injectors.system import SystemInjector
from bagfault.injectors.topic import TopicInjector
from bagfault.schema import Key

LINK_PREFIX = '/bagfault/link'  # a link's subscriber is remapped to LINK_PREFIX + topic, where bagfault publishes


class LinkInjector(SystemInjector):
    """Stream faults between two nodes of the system: the subscriber's side remapped to bagfault's link."""

    type_name = 'link'
    description = ("A topic the system publishes to itself: its subscriber is started again with the topic remapped "
                   f"to {LINK_PREFIX}/TOPIC, where bagfault republishes it through the `topic` injector's faults "
                   '(`bagfault test` only; no root, no tc).')
    options: ClassVar[tuple[Key, ...]] = (
        Key('link_topic', 'non_empty_string', 'The topic between the nodes, as the system names it.',
                    required=True),
        Key('subscriber', 'target', 'The process whose subscription is remapped: {node: /NAME} or '
                    '{command: REGEX} (started again, with the remap added to its command line, before the bag '
                    'plays).', required=True),
    )
    fields = TopicInjector.fields

    @classmethod
    def check_options(cls, options: dict[str, Any]) -> None:
        """A topic name and a subscriber that is one process, not the whole system."""
        if options.get('subscriber') == 'system':
            raise InjectorConfigError("subscriber: name one process ({node: /NAME} or {command: REGEX}), not 'system'")

    @classmethod
    def check_fault(cls, config: dict[str, Any], options: dict[str, Any]) -> None:
        """As the `topic` injector checks its faults."""
        TopicInjector.check_fault(config, options)
