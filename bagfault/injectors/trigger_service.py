"""Trigger service injector (`trigger_service`, std_srvs/srv/Trigger): live mode only."""

from __future__ import annotations

from typing import ClassVar

from bagfault.injectors.base import ServiceInjector
from bagfault.schema import Key, boolean, string


class TriggerServiceInjector(ServiceInjector):
    """Forced failure and response delay of a Trigger service."""

    type_name = 'trigger_service'
    description = 'std_srvs/srv/Trigger: forced failure and response delay (live mode only).'
    service_type = 'std_srvs/srv/Trigger'
    fields: ClassVar[tuple[Key, ...]] = (
        Key('delay_ms', 'integer', 'Delay before the response is returned, in milliseconds.', default=0, minimum=0),
        boolean('force_failure', 'Answer success=false without calling the target service.'),
        string('failure_message', 'Response message used while force_failure is active.', 'Injected service failure'),
    )


