"""Stream faults on any topic of any type (`topic`): nothing is decoded.

Several active faults combine as elsewhere: the strongest probability,
delay, jitter, window or bit count wins, `throttle_hz` takes the lowest
rate, `blackout` and `freeze` apply if any fault sets them, stamp offsets
add up, and every fault counts its own bursts. Per message the steps run
in this order: blackout, burst, drop, throttle, freeze, stamp offset,
corrupt, duplicate, reorder, delay (+ jitter).
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from bagfault.errors import InjectorConfigError
from bagfault.faults.combine import strongest, total
from bagfault.faults.drop import should_drop
from bagfault.faults.header import has_header, shift_stamp
from bagfault.injectors.base import Injector, RawMessage
from bagfault.schema import DELAY_MS, DROP_PROBABILITY, MAX_DELAY_MS, Key, boolean, integer, probability
from bagfault.units import MS, NS

if TYPE_CHECKING:
    from collections.abc import Sequence

    from bagfault.faults.active import ActiveFault

MAX_STAMP_OFFSET_MS = 86_400_000 * 366  # a year either way
MIN_THROTTLE_HZ = 0.001
SIMPLE = frozenset({'drop_probability', 'delay_ms'})


class TopicInjector(Injector):
    """Drop, burst loss, blackout, delay/jitter, duplicates, reordering, throttling, freeze,
    stamp offset and bit corruption of serialized messages."""

    type_name = 'topic'
    description = 'Any message type: stream faults on the serialized messages (no decoding).'
    message_types: ClassVar[tuple[str, ...]] = ()
    fields: ClassVar[tuple[Key, ...]] = (
        DROP_PROBABILITY,
        integer('burst_drop', 'Drop this many consecutive messages ...', 0, minimum=0),
        integer('burst_period', '... out of every this many messages (counted from the fault start).', 0, minimum=0),
        boolean('blackout', 'Drop every message.'),
        DELAY_MS,
        integer('jitter_ms', 'Extra delay drawn uniformly from [0, jitter_ms] per message, in milliseconds.', 0,
                minimum=0, maximum=MAX_DELAY_MS),
        probability('duplicate_probability', 'Probability that a message is delivered twice (0..1).'),
        integer('reorder_window', 'Release messages in groups of this many, shuffled (deterministic).', 0, minimum=0),
        Key('throttle_hz', 'number', 'Keep at most this many messages per second, in Hz (0: off, else at '
                    'least 0.001).', default=0.0, minimum=0.0),
        boolean('freeze', 'Repeat the last message received before the fault, at the original times.'),
        integer('stamp_offset_ms', 'Shift header.stamp by this many milliseconds (header only is touched).', 0,
                minimum=-MAX_STAMP_OFFSET_MS, maximum=MAX_STAMP_OFFSET_MS),
        probability('corrupt_probability', 'Probability that a message gets bits flipped after the CDR header.'),
        integer('corrupt_bits', 'How many bits to flip in a corrupted message.', 1, minimum=1),
    )
    stream_keys = frozenset(f.name for f in fields)

    @classmethod
    def check_fault(cls, config: dict[str, Any], options: dict[str, Any]) -> None:
        """burst_drop needs a longer burst_period; reorder windows hold 2+ messages."""
        if ('burst_drop' in config) != ('burst_period' in config):
            raise InjectorConfigError('burst_drop and burst_period go together (drop N of every M messages)')
        if 'burst_drop' in config and not 0 < config['burst_drop'] < config['burst_period']:
            raise InjectorConfigError('burst_drop must be at least 1 and smaller than burst_period')
        if config.get('reorder_window', 2) == 1:
            raise InjectorConfigError('reorder_window of 1 reorders nothing; use 2 or more')
        if 'corrupt_bits' in config and 'corrupt_probability' not in config:
            raise InjectorConfigError('corrupt_bits needs corrupt_probability')
        if 0 < config.get('throttle_hz', 0) < MIN_THROTTLE_HZ:
            raise InjectorConfigError(f'throttle_hz {config["throttle_hz"]:g} is below {MIN_THROTTLE_HZ:g} Hz '
                                      '(one message in over 16 minutes); use blackout to drop everything')

    @classmethod
    def decodes(cls, faults: Sequence[Any]) -> bool:
        """Only stamp_offset_ms needs the type's definition (to find the header)."""
        return any('stamp_offset_ms' in f.config for f in faults)

    @classmethod
    def check_type(cls, msgtype: str, store: Any, faults: Sequence[Any]) -> list[str]:
        """stamp_offset_ms needs a type that starts with a std_msgs/Header."""
        if any('stamp_offset_ms' in f.config for f in faults) and not has_header(msgtype, store):
            return [f'stamp_offset_ms needs a message with a header, and {msgtype} has none']
        return []

    def __init__(self, spec: Any, codec: Any = None, faults: Sequence[Any] = ()) -> None:
        super().__init__(spec, codec, faults)
        self.tracks_history = any(f.config.get('freeze') for f in faults)
        self.last_good: RawMessage | None = None
        self._bursts: dict[tuple[str, int], int] = {}
        self._next_due: int | None = None
        self._throttle_since: tuple[str, int] | None = None
        self._window: list[RawMessage] = []

    def needs_decoding(self, active: Sequence[ActiveFault]) -> bool:
        """Never: every topic fault works on bytes."""
        return False

    @property
    def busy(self) -> bool:
        """True while a reorder window holds messages."""
        return bool(self._window)

    def watch(self, messages: list[RawMessage]) -> None:
        """Untouched messages still update the last good message (for freeze)."""
        if messages:
            self.last_good = messages[-1]

    def process_batch(self, messages: list[RawMessage], active: Sequence[ActiveFault]) -> list[RawMessage]:
        """Drop and delay alone are vectorised; anything else goes message by message."""
        if not self._window and all(set(f.config) <= SIMPLE for f in active):
            out = super().process_batch(messages, active)
            if self.tracks_history and messages:
                self.last_good = messages[-1]
            return out
        return [out for message in messages for out in self.process(message, active)]

    def process(self, message: RawMessage, active: Sequence[ActiveFault]) -> list[RawMessage]:
        """All stream faults on one message."""
        out: list[RawMessage] = []
        window, _ = strongest(active, 'reorder_window')
        if self._window and window < 2:
            out += self._release(message.log_time, message.order)
        if not active:
            self.last_good = message
            return [*out, message]
        if not self._passes(message, active):
            return out
        if any(f.config.get('freeze') for f in active):
            if self.last_good is None:
                self.last_good = message
            message = replace(message, data=self.last_good.data)
        else:
            self.last_good = message
        offset = int(total(active, 'stamp_offset_ms'))
        if offset:
            message = replace(message, data=shift_stamp(message.data, offset * MS))
        message = self._corrupt(message, active)
        copies = [message]
        chance, owner = strongest(active, 'duplicate_probability')
        if owner is not None and chance > 0 and owner.random.stream('duplicate_probability').random() < chance:
            copies.append(message)
        if window >= 2:
            released = []
            for copy in copies:
                self._window.append(copy)
                if len(self._window) >= window:
                    _, window_owner = strongest(active, 'reorder_window')
                    released += self._release(copy.log_time, copy.order, window_owner)
            copies = released
        return out + self._delay(copies, active)

    def _passes(self, message: RawMessage, active: Sequence[ActiveFault]) -> bool:
        """Blackout, bursts, random drop, throttle: True when the message survives."""
        if any(f.config.get('blackout') for f in active):
            return False
        burst = False
        for fault in active:
            if 'burst_drop' in fault.config:
                key = (fault.id, fault.since)
                count = self._bursts.get(key, 0)
                self._bursts[key] = count + 1
                burst = burst or count % fault.config['burst_period'] < fault.config['burst_drop']
        if burst or should_drop(active):
            return False
        rates = [f.config['throttle_hz'] for f in active if f.config.get('throttle_hz', 0) > 0]
        if rates:
            period = round(NS / min(rates))
            throttling = (f for f in active if f.config.get('throttle_hz', 0) > 0)
            owner = min(throttling, key=lambda f: f.config['throttle_hz'])
            if self._throttle_since != (owner.id, owner.since) or self._next_due is None:
                self._throttle_since, self._next_due = (owner.id, owner.since), message.log_time
            if message.log_time < self._next_due:
                return False
            late = message.log_time - self._next_due
            self._next_due = self._next_due + period if late < period else message.log_time + period
        return True

    def _corrupt(self, message: RawMessage, active: Sequence[ActiveFault]) -> RawMessage:
        chance, owner = strongest(active, 'corrupt_probability')
        if owner is None or chance <= 0 or owner.random.stream('corrupt_probability').random() >= chance:
            return message
        data = bytearray(message.data)
        bits = (len(data) - 4) * 8
        if bits <= 0:
            return message
        count = min(int(owner.config.get('corrupt_bits', 1)), bits)
        positions = owner.random.stream('corrupt_bits').choice(bits, size=count, replace=False)
        body = np.frombuffer(memoryview(data)[4:], dtype=np.uint8).copy()
        np.bitwise_xor.at(body, positions // 8, (1 << (positions % 8)).astype(np.uint8))
        data[4:] = body.tobytes()
        return replace(message, data=bytes(data))

    def _delay(self, messages: list[RawMessage], active: Sequence[ActiveFault]) -> list[RawMessage]:
        delay_ms, _ = strongest(active, 'delay_ms')
        jitter_ms, owner = strongest(active, 'jitter_ms')
        base = int(delay_ms) * MS
        out = []
        for message in messages:
            shift = base
            if owner is not None and jitter_ms > 0:
                shift += round(owner.random.stream('jitter_ms').random() * jitter_ms * MS)
            out.append(message if shift == 0 else self.delayed(message, shift))
        return out

    def _release(self, time: int, order: int, owner: ActiveFault | None = None) -> list[RawMessage]:
        """Emit the reorder window: shuffled when full, in order when cut short."""
        window, self._window = self._window, []
        if owner is not None:
            window = [window[i] for i in owner.random.stream('reorder_window').permutation(len(window))]
        return [RawMessage(time, m.publish_time, m.data, order) for m in window]

    def flush(self, time: int) -> list[RawMessage]:
        """End of input: release what the reorder window still holds."""
        return self._release(time, self._window[-1].order) if self._window else []


class CompressedImageInjector(TopicInjector):
    """The stream faults of `topic`, for sensor_msgs/msg/CompressedImage only."""

    type_name = 'compressed_image'
    description = 'sensor_msgs/msg/CompressedImage: stream faults (drop, delay, freeze, corrupt, ...).'
    message_types = ('sensor_msgs/msg/CompressedImage',)
