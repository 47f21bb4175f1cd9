"""`--foxglove [HOST:PORT]`: a run shown in Foxglove while it happens, with its faults as controls.

A Foxglove WebSocket server (the `foxglove-sdk` package): every played,
faulty and recorded topic as a channel with its ros2msg schema (CDR, as
recorded), the event topics likewise and every event as JSON on
/bagfault/events; each fault's `active` switch and config keys as
parameters (`<fault>.active`, `<fault>.<key>`), edits checked by the same
schema as scenario files (a refused edit keeps the value and says why as a
status message); for `play`, the playback controls (play, pause, speed,
seek) and the time range of the bag; for `proxy`, a reload service.
"""

from __future__ import annotations

import json
import math
import threading
import time
from typing import TYPE_CHECKING, Any, Protocol

import foxglove
from foxglove.websocket import Capability, PlaybackCommand, PlaybackState, PlaybackStatus, ServerListener

from bagfault.errors import BagfaultError, FieldValueError, UsageError
from bagfault.events import EVENTS_JSON_TOPIC, FaultEvent, event_json
from bagfault.injectors.registry import get_injector_type
from bagfault.view.relay import Relay

if TYPE_CHECKING:
    from collections.abc import Callable

    from bagfault.engine.run import Run, Sink
    from bagfault.events import Event
    from bagfault.live.pacer import Pacer
    from bagfault.live.viewing import LiveView, OpenView
    from bagfault.spec.model import FaultSpec, Scenario

DEFAULT_PORT = 8765
TIME_PERIOD = 0.05  # seconds between time broadcasts
STATUS_ID = 'bagfault-parameters'


class Controls(Protocol):
    """Where parameter edits go: a play's FaultControl, a proxy's session."""

    def ask(self, fault_id: str, key: str | None, value: object) -> Any:
        """Check and apply (or queue) a change; FieldValueError with the reason when refused."""
        ...

    def fault(self, fault_id: str) -> FaultSpec | None:
        """The fault with its current config (the run's FaultState)."""
        ...


def parse_address(text: str) -> tuple[str, int]:
    """'HOST:PORT', ':PORT', 'HOST' or '' -> (host, port); UsageError otherwise."""
    host, _, port = text.rpartition(':') if ':' in text else (text, '', '')
    try:
        number = int(port) if port else DEFAULT_PORT
    except ValueError:
        raise UsageError(f'--foxglove {text}: the port must be a number (HOST:PORT)') from None
    if not 0 <= number <= 65535:
        raise UsageError(f'--foxglove {text}: the port must be 0 to 65535')
    return host or '127.0.0.1', number


HIDDEN_NOTE = '{topic} not shown in the Foxglove view: no definition of {msgtype} (give one with --msg-path)'


class FoxgloveView:
    """The WebSocket server of one command, shared by its passes."""

    def __init__(self, address: str, scenario: Scenario, *, controls: Controls | None = None,
                 playback: Pacer | None = None, time_range: tuple[int, int] | None = None,
                 reload: Any = None, editable: bool | None = None) -> None:
        host, port = parse_address(address)
        self.scenario = scenario
        self.controls = controls
        self.playback = playback
        self.context = foxglove.Context()
        self.active: set[str] = set()
        self.asked: dict[str, object] = {}  # values edited here, shown until the run's fault state has them
        self._channels: list[foxglove.Channel | None] = []
        self.hidden: dict[str, str] = {}  # topics not shown (no definition of their type) and their types
        self._run: Run | None = None
        self._last_time = 0.0
        self._lock = threading.Lock()
        capabilities = [Capability.Time]
        if editable or (editable is None and controls is not None):  # a proxy sets its controls later
            capabilities.append(Capability.Parameters)
        services = []
        if reload is not None:
            capabilities.append(Capability.Services)
            services.append(foxglove.Service(
                name='/bagfault/reload_scenario', schema=foxglove.ServiceSchema(name='std_srvs/srv/Trigger'),
                handler=lambda _request: json.dumps(dict(zip(('success', 'message'), reload(), strict=True))).encode()))
        if playback is not None:
            capabilities.append(Capability.PlaybackControl)
        try:  # on loopback, behind the relay that clients reach (view/relay.py: both subprotocol names)
            self.server = foxglove.start_server(
                name=f'bagfault: {scenario.name}', host='127.0.0.1', port=0, capabilities=capabilities,
                server_listener=_Listener(self), supported_encodings=['json'], services=services or None,
                context=self.context, playback_time_range=time_range)
        except Exception as exc:  # noqa: BLE001 - the SDK raises RuntimeError for a port in use, a bad host
            raise BagfaultError(f'--foxglove {address}: cannot start the server: {exc}') from None
        try:
            self.relay = Relay(host, port, self.server.port)
        except OSError as exc:
            self.server.stop()
            raise BagfaultError(f'--foxglove {address}: cannot start the server: {exc.strerror or exc}') from None
        self._events = foxglove.Channel(EVENTS_JSON_TOPIC, message_encoding='json', context=self.context)

    def notes(self) -> list[str]:
        """What the view could not show, for the run's summary."""
        return [HIDDEN_NOTE.format(topic=t, msgtype=m) for t, m in sorted(self.hidden.items())]

    @property
    def url(self) -> str:
        """ws:// address clients connect to."""
        return f'ws://{parse_address("")[0]}:{self.relay.port}'

    # -- records ---------------------------------------------------------------------------------
    def add_channel(self, topic: str, msgtype: str, schema_encoding: str, schema_text: str,
                    message_encoding: str = 'cdr') -> int:
        """A channel with the recorded schema."""
        if not schema_text:  # a type nobody defined: Foxglove could not decode it, so it is not shown
            self.hidden[topic] = msgtype
            self._channels.append(None)
            return len(self._channels) - 1
        schema = foxglove.Schema(name=msgtype, encoding=schema_encoding or 'ros2msg', data=schema_text.encode())
        self._channels.append(foxglove.Channel(topic, schema=schema, message_encoding=message_encoding,
                                               context=self.context))
        return len(self._channels) - 1

    def write(self, channel_id: int, log_time: int, data: bytes | memoryview) -> None:
        """One record, as recorded."""
        channel = self._channels[channel_id]
        if channel is not None:
            channel.log(data if isinstance(data, bytes) else bytes(data), log_time=log_time)

    def attach(self, run: Run) -> None:
        """A pass: its events go out as JSON and move the parameters."""
        self._run = run
        run.event_listeners.append(self.event)

    def event(self, event: Event, _data: bytes) -> None:
        """Every event on /bagfault/events; a fault switched moves its parameter."""
        origin = self._run.stats.origin if self._run is not None else None
        self._events.log(event_json(event, origin).encode(), log_time=event.time)
        if isinstance(event, FaultEvent) and event.state in ('active', 'inactive'):
            if event.state == 'active':
                self.active.add(event.fault_id)
            else:
                self.active.discard(event.fault_id)
            self.server.publish_parameter_values(self.parameters([f'{event.fault_id}.active']))
        elif isinstance(event, FaultEvent) and event.state == 'config_updated':
            self.server.publish_parameter_values(self.parameters(
                [p.name for p in self.parameters() if p.name.startswith(f'{event.fault_id}.')]))

    def played(self, bag_time: int) -> None:
        """The timeline's time, at most every TIME_PERIOD."""
        now = time.monotonic()
        if now - self._last_time >= TIME_PERIOD:
            self._last_time = now
            self.server.broadcast_time(bag_time)

    def ended(self, bag_time: int) -> None:
        """The end of the bag: clients see it; a seek starts again."""
        self.server.broadcast_playback_state(PlaybackState(
            status=PlaybackStatus.Ended, current_time=bag_time, playback_speed=self._rate(), did_seek=False,
            request_id=None))

    def sink(self, inner: Sink) -> Sink:
        """A sink that writes to `inner` and shows every record here (the proxy's run)."""
        return ViewSink(self, inner)

    def close(self) -> None:
        """Stop the server (and its relay)."""
        self.relay.close()
        self.server.stop()

    # -- parameters --------------------------------------------------------------------------------
    def parameters(self, names: list[str] | None = None) -> list[foxglove.Parameter]:
        """Current values: `<fault>.active` and every config key of the fault's injector type."""
        out = []
        for loaded in self.scenario.faults:
            fault = (self.controls.fault(loaded.id) if self.controls is not None else None) or loaded
            injector = self.scenario.injector(fault.injector_id)
            cls = get_injector_type(injector.type) if injector is not None else None
            values: list[tuple[str, object]] = [('active', fault.id in self.active)]
            if cls is not None:
                values += [(f.name, fault.config.get(f.name, f.default)) for f in cls.fields
                           if f.type in ('number', 'special_float', 'integer', 'boolean', 'string', 'non_empty_string')]
            for key, value in values:
                name = f'{fault.id}.{key}'
                if names and name not in names:
                    continue
                if name in self.asked and self.asked[name] == value:
                    del self.asked[name]  # the fault state has it now
                out.append(_parameter(name, self.asked.get(name, value)))
        return out

    def set_parameters(self, parameters: list[foxglove.Parameter]) -> list[foxglove.Parameter]:
        """Edits: each checked and applied (or queued for the pass); a refused one keeps its value."""
        refused = []
        for parameter in parameters:
            fault_id, _, key = parameter.name.partition('.')
            try:
                if self.controls is None:
                    raise FieldValueError('this view is read-only')
                value = self.controls.ask(fault_id, None if key == 'active' else key, parameter.get_value())
            except FieldValueError as exc:
                refused.append(f'{parameter.name}: {exc}')
                continue
            if key == 'active':
                self.active.add(fault_id) if value else self.active.discard(fault_id)
            else:
                self.asked[parameter.name] = value  # a play applies it between two messages
        if refused:
            self.server.publish_status('; '.join(refused), foxglove.StatusLevel.Error, STATUS_ID)
        return self.parameters([p.name for p in parameters])

    # -- playback ----------------------------------------------------------------------------------
    def _rate(self) -> float:
        return float(self.playback.rate) if self.playback is not None else 1.0

    def playback_request(self, request: Any) -> PlaybackState | None:
        """Play, pause, speed, seek."""
        pacer = self.playback
        if pacer is None:
            return None
        if request.playback_speed and math.isfinite(request.playback_speed) and request.playback_speed > 0 \
                and abs(request.playback_speed - pacer.rate) > 1e-6:
            pacer.set_rate(float(request.playback_speed))
        if request.playback_command == PlaybackCommand.Pause:
            pacer.pause()
        else:
            pacer.resume()
        did_seek = request.seek_time is not None
        if did_seek:
            pacer.seek(int(request.seek_time))
        current = int(request.seek_time) if did_seek else (pacer.bag_time_now() or pacer.clock_value)
        return PlaybackState(status=PlaybackStatus.Paused if pacer.paused else PlaybackStatus.Playing,
                             current_time=max(0, current), playback_speed=self._rate(), did_seek=did_seek,
                             request_id=request.request_id)


def _parameter(name: str, value: object) -> foxglove.Parameter:
    if isinstance(value, float):
        return foxglove.Parameter(name, value=value, type=foxglove.ParameterType.Float64)
    if value is None:
        return foxglove.Parameter(name, value='')
    return foxglove.Parameter(name, value=value)  # type: ignore[arg-type]


class _Listener(ServerListener):
    """The server's callbacks, handed to the view."""

    def __init__(self, view: FoxgloveView) -> None:
        self.view = view

    def on_get_parameters(self, client: Any, param_names: list[str], request_id: str | None = None) -> list[Any]:
        return self.view.parameters(param_names or None)

    def on_set_parameters(self, client: Any, parameters: list[Any], request_id: str | None = None) -> list[Any]:
        return self.view.set_parameters(parameters)

    def on_playback_control_request(self, playback_control_request: Any) -> PlaybackState | None:
        return self.view.playback_request(playback_control_request)


class ViewSink:
    """A sink that writes to another sink and shows every record in the view (the proxy's run)."""

    def __init__(self, view: FoxgloveView, inner: Any) -> None:
        self.view = view
        self.inner = inner
        self._shown: dict[int, int] = {}

    def add_channel(self, topic: str, msgtype: str, schema_encoding: str, schema_text: str,
                    message_encoding: str = 'cdr', metadata: dict[str, str] | None = None) -> int:
        """The inner sink's channel, shown too."""
        channel = self.inner.add_channel(topic, msgtype, schema_encoding, schema_text, message_encoding, metadata)
        self._shown[channel] = self.view.add_channel(topic, msgtype, schema_encoding, schema_text, message_encoding)
        return int(channel)

    def write(self, channel_id: int, log_time: int, publish_time: int, data: bytes | memoryview) -> None:
        """Written and shown."""
        self.inner.write(channel_id, log_time, publish_time, data)
        self.view.write(self._shown[channel_id], log_time, data)


def opener(address: str) -> OpenView:
    """The view's opener for `--foxglove ADDRESS`, which the API hands to the live commands and the closed loop."""

    def open_view(scenario: Scenario, *, controls: Any = None, playback: Any = None,
                  time_range: tuple[int, int] | None = None, reload: Callable[[], tuple[bool, str]] | None = None,
                  editable: bool | None = None) -> LiveView:
        return FoxgloveView(address, scenario, controls=controls, playback=playback, time_range=time_range,
                            reload=reload, editable=editable)

    return open_view
