"""Injector base class: one message and the active faults in, 0..n messages out.

An injector never does I/O and never reads a clock. The engine gives it the
serialized message with its bag time and the faults active at that time;
offline, play and proxy modes all call the same code.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, ClassVar, Protocol

from bagfault.errors import InjectorConfigError, InjectorError, MalformedMessageError
from bagfault.faults.active import ActiveFault
from bagfault.faults.combine import strongest
from bagfault.faults.drop import drop_mask, should_drop
from bagfault.injectors.system import SystemInjector
from bagfault.schema import DELAY_MS, DROP_PROBABILITY, LIVE_OPTIONS, Key

if TYPE_CHECKING:
    from collections.abc import Sequence

    from bagfault.spec.model import FaultSpec, InjectorSpec


@dataclass(slots=True)
class RawMessage:
    """A serialized message with its times (ns): what flows between stages.

    `order` is the position of the input message it came from; it keeps
    outputs with equal times in input order and survives every fault.
    """

    log_time: int
    publish_time: int
    data: bytes | memoryview
    order: int = 0


class Codec(Protocol):
    """Turns CDR bytes of one message type into objects and back."""

    msgtype: str
    store: Any

    def decode(self, data: bytes | memoryview) -> Any:
        """Deserialize."""
        ...

    def encode(self, message: Any) -> bytes:
        """Serialize."""
        ...


class Injector:
    """Base of all topic injectors.

    Subclasses set the class attributes and implement `mutate`. The default
    flow follows the anchor: drop (drop_probability, strongest active fault
    wins), mutate the decoded message, delay (delay_ms, longest wins).
    """

    type_name: ClassVar[str] = ''
    description: ClassVar[str] = ''
    message_types: ClassVar[tuple[str, ...]] = ()
    fields: ClassVar[tuple[Key, ...]] = (DROP_PROBABILITY, DELAY_MS)
    options: ClassVar[tuple[Key, ...]] = LIVE_OPTIONS
    live_only: ClassVar[bool] = False
    stream_keys: ClassVar[frozenset[str]] = frozenset({'drop_probability', 'delay_ms'})

    def __init__(self, spec: InjectorSpec, codec: Codec | None = None, faults: Sequence[FaultSpec] = ()) -> None:
        self.spec = spec
        self.codec = codec
        self.faults = list(faults)
        self.tracks_history = False
        self._released = 0  # when the last delayed message goes out: delayed messages leave in order

    @property
    def busy(self) -> bool:
        """True while the injector holds messages back (the engine keeps feeding it)."""
        return False

    def watch(self, messages: list[RawMessage]) -> None:
        """See messages that pass untouched (only called when `tracks_history` is set)."""

    def flush(self, time: int) -> list[RawMessage]:
        """End of input: messages still held back."""
        return []

    @classmethod
    def check_type(cls, msgtype: str, store: Any, faults: Sequence[FaultSpec]) -> list[str]:
        """Problems of the faults with the actual message type of the bag (run start)."""
        return []

    @classmethod
    def check_options(cls, options: dict[str, Any]) -> None:
        """Cross-field checks of injector options; raise InjectorConfigError."""
        expected = options.get('message_type')
        if expected and cls.message_types and expected not in cls.message_types:
            raise InjectorConfigError(f'message_type {expected} does not fit injector type {cls.type_name!r}, '
                                      f'which takes {" or ".join(cls.message_types)}')

    @classmethod
    def check_fault(cls, config: dict[str, Any], options: dict[str, Any]) -> None:
        """Cross-field checks of one fault config; raise InjectorConfigError."""

    @classmethod
    def config_warnings(cls, config: dict[str, Any]) -> list[str]:
        """What a fault config asks for that has no effect (as in ros2_fault_injection): warnings, not errors."""
        return []

    @classmethod
    def field(cls, key: str) -> Key | None:
        """Schema entry for a fault config key."""
        return next((x for x in cls.fields if x.name == key), None)

    @classmethod
    def plot_fields(cls, key: str, config: dict[str, Any]) -> list[str]:
        """Field paths a config key changes, for before/after plots in reports."""
        return [path for prefix, path in cls.plotted if key.startswith(prefix)]

    plotted: ClassVar[tuple[tuple[str, str], ...]] = ()
    # (field path, config key, 'bias' | 'noise') in the order `mutate` applies them; when every active
    # key is one of these (or drop/delay), batches are patched in the CDR bytes instead of decoded.
    linear_ops: ClassVar[tuple[tuple[str, str, str], ...]] = ()

    @property
    def _linear_keys(self) -> frozenset[str]:
        return frozenset(key for _, key, _ in self.linear_ops) | self.stream_keys

    @classmethod
    def decodes(cls, faults: Sequence[FaultSpec]) -> bool:
        """True when any of these faults changes message content (a codec is needed)."""
        return any(key not in cls.stream_keys for fault in faults for key in fault.config)

    def needs_decoding(self, active: Sequence[ActiveFault]) -> bool:
        """True when an active fault changes message content."""
        return any(key not in self.stream_keys for fault in active for key in fault.config)

    def process(self, message: RawMessage, active: Sequence[ActiveFault]) -> list[RawMessage]:
        """Reference path: apply the active faults to one message."""
        if not active:
            return [message]
        if should_drop(active):
            return []
        out = message
        if self.needs_decoding(active):
            assert self.codec is not None
            decoded = self.codec.decode(message.data)
            self.mutate(decoded, message.log_time, active)
            out = replace(message, data=self.codec.encode(decoded))
        return self.retime([out], active)

    def process_batch(
        self,
        messages: list[RawMessage],
        active: Sequence[ActiveFault],
    ) -> list[RawMessage]:
        """Apply the active faults to consecutive messages; same bytes as `process`.

        Subclasses with a vectorised path override `mutate_batch`.
        """
        if not active:
            return messages
        keep = drop_mask(active, len(messages))
        kept = [m for m, k in zip(messages, keep, strict=True) if k] if keep is not None else messages
        if kept and self.needs_decoding(active):
            kept = self.mutate_batch(kept, active)
        return self.retime(kept, active)

    def mutate(self, message: Any, time: int, active: Sequence[ActiveFault]) -> None:
        """Change a decoded message in place."""
        raise NotImplementedError

    def mutate_batch(
        self,
        messages: list[RawMessage],
        active: Sequence[ActiveFault],
    ) -> list[RawMessage]:
        """Mutate many messages: patched in the CDR bytes when only `linear_ops` keys are active,
        decoded one by one otherwise. Both give the same bytes."""
        if self.linear_ops and all(k in self._linear_keys for f in active for k in f.config):
            patched = patch_linear(self, messages, active)
            if patched is not None:
                return patched
        return self.decode_batch(messages, active)

    def decode_batch(self, messages: list[RawMessage], active: Sequence[ActiveFault]) -> list[RawMessage]:
        """Decode, mutate and encode each message."""
        assert self.codec is not None
        out = []
        for message in messages:
            decoded = self.codec.decode(message.data)
            self.mutate(decoded, message.log_time, active)
            out.append(replace(message, data=self.codec.encode(decoded)))
        return out

    def retime(
        self,
        messages: list[RawMessage],
        active: Sequence[ActiveFault],
    ) -> list[RawMessage]:
        """Shift log and publish time by the longest active delay (see `delayed`)."""
        delay_ms, _ = strongest(active, 'delay_ms')
        if delay_ms <= 0:
            return messages
        shift = int(delay_ms) * 1_000_000
        return [self.delayed(m, shift) for m in messages]

    def delayed(self, message: RawMessage, shift: int) -> RawMessage:
        """The message `shift` ns later, but never before the previous delayed one: the anchor's delay queue
        is first in, first out, so a delay that shrinks while messages wait never reorders them."""
        due = max(message.log_time + shift, self._released)
        self._released = due
        return RawMessage(due, message.publish_time + (due - message.log_time), message.data, message.order)


class ServiceInjector:
    """Base of service injectors: schema only offline, behaviour in live mode."""

    type_name: ClassVar[str] = ''
    description: ClassVar[str] = ''
    service_type: ClassVar[str] = ''
    fields: ClassVar[tuple[Key, ...]] = ()
    options: ClassVar[tuple[Key, ...]] = ()
    live_only: ClassVar[bool] = True
    message_types: ClassVar[tuple[str, ...]] = ()

    @classmethod
    def check_options(cls, options: dict[str, Any]) -> None:
        """Cross-field checks of injector options."""

    @classmethod
    def check_fault(cls, config: dict[str, Any], options: dict[str, Any]) -> None:
        """Cross-field checks of one fault config."""

    @classmethod
    def field(cls, key: str) -> Key | None:
        """Schema entry for a fault config key."""
        return next((x for x in cls.fields if x.name == key), None)


InjectorType = type[Injector] | type[ServiceInjector] | type[SystemInjector]


def patch_linear(injector: Injector, messages: list[RawMessage],
                 active: Sequence[ActiveFault]) -> list[RawMessage] | None:
    """Biases and noise on scalar fields of same-layout messages as numpy columns; None if layouts differ."""
    import numpy as np  # noqa: PLC0415

    from bagfault.faults.cdr import FieldLayout, LayoutError  # noqa: PLC0415
    from bagfault.faults.combine import total  # noqa: PLC0415
    from bagfault.faults.noise import gaussian  # noqa: PLC0415

    assert injector.codec is not None
    length = len(messages[0].data)
    if any(len(m.data) != length for m in messages):
        return None
    paths = list(dict.fromkeys(path for path, _, _ in injector.linear_ops))
    try:
        layout = FieldLayout.of(messages[0].data, injector.codec.msgtype, injector.codec.store, paths)
    except LayoutError:
        return None
    rows = np.frombuffer(bytearray(b''.join(m.data for m in messages)), dtype=np.uint8).reshape(len(messages), length)
    if not layout.rows_matching(rows).all():
        return None
    columns = {path: layout.column(rows, path) for path in paths}
    for path, key, kind in injector.linear_ops:
        if kind == 'bias':
            value = total(active, key)
            if value != 0.0:
                columns[path] = columns[path] + value
        else:
            noise = gaussian(active, key, len(messages))
            if noise is not None:
                columns[path] = np.where(noise != 0.0, columns[path] + noise, columns[path])
    for path in paths:
        layout.store(rows, path, columns[path])
    blob = memoryview(rows.reshape(-1).data)
    return [RawMessage(m.log_time, m.publish_time, blob[i * length:(i + 1) * length], m.order)
            for i, m in enumerate(messages)]


# Plugins subclass Injector and raise these; they are bagfault.errors classes, re-exported for convenience.
__all__ = ['ActiveFault', 'Codec', 'Injector', 'InjectorConfigError', 'InjectorError', 'InjectorType',
           'MalformedMessageError', 'RawMessage', 'ServiceInjector', 'SystemInjector', 'patch_linear']
