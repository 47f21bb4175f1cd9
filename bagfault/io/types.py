"""Message types of a run: definitions stored in the bag first, the distro's standard types second.

Bags written by Humble's sqlite3 plugin carry no definitions; their types
come from the rosbags typestore of the recording distro. Only the types a
run actually decodes are parsed and compiled, so a bag with hundreds of
topics costs nothing for the topics no fault touches.
"""

from __future__ import annotations

from functools import cached_property
from typing import TYPE_CHECKING, Any

from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore
from rosbags.typesys.base import TypesysError

from bagfault.errors import one_line

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

    from bagfault.io.channel import Channel
    from bagfault.io.definitions import Definitions

DISTROS = {
    'dashing': Stores.ROS2_DASHING,
    'eloquent': Stores.ROS2_ELOQUENT,
    'foxy': Stores.ROS2_FOXY,
    'galactic': Stores.ROS2_GALACTIC,
    'humble': Stores.ROS2_HUMBLE,
    'iron': Stores.ROS2_IRON,
    'jazzy': Stores.ROS2_JAZZY,
    'kilted': Stores.ROS2_KILTED,
}
DEFAULT_DISTRO = 'humble'


class Codec:
    """CDR decode/encode of one message type."""

    def __init__(self, msgtype: str, store: Typestore) -> None:
        self.msgtype = msgtype
        self.store = store

    def decode(self, data: bytes | memoryview) -> Any:
        """Bytes to message object."""
        return self.store.deserialize_cdr(data, self.msgtype)

    def encode(self, message: Any) -> bytes:
        """Message object to little-endian CDR bytes."""
        return bytes(self.store.serialize_cdr(message, self.msgtype))


def _parse(msgtype: str, encoding: str, text: str) -> dict[str, Any]:
    if encoding == 'ros2idl':
        sep = '=' * 80 + '\n'
        types: dict[str, Any] = {}
        parts = text.split(sep)[1:] if text.startswith(sep) else [text]
        for part in parts:
            body = part.split('\n', 1)[1] if part.startswith('IDL: ') else part
            types.update(get_types_from_idl(body))
        return types
    return dict(get_types_from_msg(text, msgtype))


class TypeCatalog:
    """Resolves message types to codecs and to output schema text."""

    def __init__(self, channels: list[Channel], distro: str | None, definitions: Definitions | None = None) -> None:
        self.distro = (distro or DEFAULT_DISTRO).lower()
        self._stored: dict[str, tuple[str, str]] = {}
        for channel in channels:
            if channel.schema_text and channel.msgtype and channel.schema_encoding in {'ros2msg', 'ros2idl'}:
                self._stored.setdefault(channel.msgtype, (channel.schema_encoding, channel.schema_text))
        self._user = {k: v for k, v in (definitions or {}).items() if k not in self._stored}
        self._extra: dict[str, tuple[str, str]] = {}
        self._store: Typestore | None = None
        self._store_types: frozenset[str] = frozenset()
        self._codecs: dict[str, Codec | None] = {}
        self._errors: dict[str, str] = {}

    @cached_property
    def standard(self) -> Typestore:
        """The distro's standard types (built when a type is not in the bag: building costs 0.2 s)."""
        return get_typestore(DISTROS.get(self.distro, DISTROS[DEFAULT_DISTRO]))

    def defines(self, msgtype: str) -> bool:
        """Whether the bag, the user or bagfault gives a definition of this type (the standard store aside)."""
        return msgtype in self._stored or msgtype in self._user or msgtype in self._extra

    def add_definition(self, msgtype: str, text: str, encoding: str = 'ros2msg') -> None:
        """Make a type known that no bag carries (bagfault's own event types)."""
        self._extra[msgtype] = (encoding, text)
        self._store = None
        self._codecs.clear()

    def _build(self, wanted: set[str]) -> Typestore:
        types: dict[str, Any] = {}
        for msgtype, (encoding, text) in (*self._stored.items(), *self._user.items(), *self._extra.items()):
            if msgtype in wanted or msgtype in self._extra or msgtype in self._user:
                try:
                    for name, definition in _parse(msgtype, encoding, text).items():
                        types.setdefault(name, definition)
                except (TypesysError, ValueError, IndexError) as exc:
                    where = 'given' if msgtype in self._user else 'stored'
                    self._errors[msgtype] = f'{where} definition does not parse: {one_line(exc)}'
        store = get_typestore(Stores.EMPTY)  # builtin_interfaces only: the standard store is built when needed
        missing = [x for x in wanted if x not in types and x not in store.fielddefs]
        while missing:
            name = missing.pop()
            if name in types or name in store.fielddefs or name not in self.standard.fielddefs:
                continue
            types[name] = self.standard.fielddefs[name]
            for _, desc in types[name][1]:
                missing.extend(_references(desc))
        for _, fields in list(types.values()):
            for _, desc in fields:
                for ref in _references(desc):
                    if ref not in types and ref not in store.fielddefs and ref in self.standard.fielddefs:
                        types[ref] = self.standard.fielddefs[ref]
        store.register({k: v for k, v in types.items() if k not in store.fielddefs})
        self._store_types = frozenset(wanted)
        return store

    def codec(self, msgtype: str) -> Codec | None:
        """Codec for a type, or None when no definition can be found or compiled."""
        if msgtype in self._codecs:
            return self._codecs[msgtype]
        if self._store is not None and msgtype in self._store.fielddefs:  # built with another type: no rebuild
            self._store_types |= {msgtype}
            self._codecs[msgtype] = Codec(msgtype, self._store)
            return self._codecs[msgtype]
        wanted = {*self._store_types, msgtype, *self._extra}
        try:
            self._store = self._build(wanted)
            _check_resolved(self._store, msgtype)
            codec: Codec | None = Codec(msgtype, self._store)
        except (TypesysError, KeyError, ValueError) as exc:
            self._errors.setdefault(msgtype, f'no usable definition ({one_line(exc)})')
            codec = None
        # Rebuilding the store invalidates earlier codecs' store; re-point them.
        for known in self._codecs.values():
            if known is not None:
                known.store = self._store  # type: ignore[assignment]
        self._codecs[msgtype] = codec
        return codec

    def why_not(self, msgtype: str) -> str:
        """Reason a type has no codec."""
        return self._errors.get(msgtype, 'type not found in the bag or the standard types of ' + self.distro)

    def schema(self, msgtype: str) -> tuple[str, str]:
        """(encoding, text) to write as output schema: the bag's, the user's (--msg-path), the distro's; ('', '')
        when nothing is known, as rosbag2 writes a type without definition."""
        if msgtype in self._stored:
            return self._stored[msgtype]
        if msgtype in self._extra:
            return self._extra[msgtype]
        if msgtype in self._user:
            codec = self.codec(msgtype)
            if codec is not None:
                return 'ros2msg', codec.store.generate_msgdef(msgtype, ros_version=2)[0]
        if msgtype in self.standard.fielddefs:
            text, _ = self.standard.generate_msgdef(msgtype, ros_version=2)
            return 'ros2msg', text
        return '', ''


def _check_resolved(store: Typestore, msgtype: str) -> None:
    """KeyError naming the first type `msgtype` refers to (itself included) that `store` does not define. What
    compiling its codec would find, without compiling: rosbags compiles a type's (de)serializers on its first
    use (14 ms a type, and numpy's import, 0.1 s, for the first), which a run whose faults never act skips."""
    seen, todo = set(), [msgtype]
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        seen.add(name)
        if name not in store.fielddefs:
            raise KeyError(name)
        for _, desc in store.fielddefs[name][1]:
            todo.extend(_references(desc))


def _references(desc: Any) -> list[str]:
    """Type names a field descriptor refers to."""
    kind, args = desc
    if int(kind) == 2:  # NAME
        return [args]
    if int(kind) in (3, 4):  # ARRAY, SEQUENCE
        sub, _ = args
        return _references(sub)
    return []
