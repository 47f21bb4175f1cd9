"""What rosbag2's own C++ readers demand of an MCAP, written from their code, never from bagfault's.

Sources (ros2/rosbag2): `rosbag2_storage/include/rosbag2_storage/yaml.hpp` (BagMetadata, TopicMetadata,
FileInformation decode), `rosbag2_storage/src/rosbag2_storage/qos.cpp` (jazzy: the QoS decode that detects
numbers or names), `rosbag2_transport/src/rosbag2_transport/qos.cpp` (humble and iron: numbers read with
`as<int>()` outside any try), `rosbag2_storage_mcap/src/mcap_storage.cpp` (jazzy: the `rosbag2` record's
`serialized_metadata` decoded without a try; humble/iron read only channel metadata). yaml-cpp throws on a
missing key (`invalid node`) and on a scalar that does not convert (`bad conversion`); here both are
`Rosbag2Error`.
"""

from __future__ import annotations

from typing import Any

import yaml

DISTROS = ('humble', 'iron', 'jazzy')
# rmw_qos_*_policy_from_str: names the jazzy reader accepts (others become UNKNOWN)
HISTORY_NAMES = {'system_default', 'keep_last', 'keep_all', 'unknown'}


class Rosbag2Error(Exception):
    """What yaml-cpp would have thrown inside rosbag2."""


def _node(mapping: Any, key: str) -> Any:
    if not isinstance(mapping, dict) or key not in mapping:
        raise Rosbag2Error(f'invalid node; first invalid key: "{key}"')
    return mapping[key]


def _as_int(value: Any, what: str) -> int:
    """yaml-cpp `as<int>()`: a plain integer scalar (a bool or a name is a bad conversion)."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise Rosbag2Error(f'bad conversion: {what} = {value!r} is not an integer')
    return value


def _as_str(value: Any, what: str) -> str:
    if isinstance(value, (dict, list)) or value is None:
        raise Rosbag2Error(f'bad conversion: {what} = {value!r} is not a scalar')
    return str(value)


def _as_bool(value: Any, what: str) -> bool:
    if not isinstance(value, bool):
        raise Rosbag2Error(f'bad conversion: {what} = {value!r} is not a boolean')
    return value


def _time(node: Any, what: str) -> tuple[int, int]:
    return _as_int(_node(node, 'sec'), f'{what}.sec'), _as_int(_node(node, 'nsec'), f'{what}.nsec')


def decode_qos(text: str, distro: str) -> list[dict[str, Any]]:
    """A channel's `offered_qos_profiles` as the distro's player reads it; raises where the player throws."""
    if not text:
        return []
    profiles = yaml.safe_load(text)
    if not isinstance(profiles, list):
        raise Rosbag2Error('offered_qos_profiles is not a sequence')
    out = []
    for profile in profiles:
        if distro in ('humble', 'iron'):
            numeric = True
        else:  # jazzy: history as an int in [SYSTEM_DEFAULT, UNKNOWN] means the number form
            history = _node(profile, 'history')
            numeric = isinstance(history, int) and not isinstance(history, bool) and 0 <= history <= 3
        decoded: dict[str, Any] = {}
        for key in ('history', 'reliability', 'durability', 'liveliness'):
            value = _node(profile, key)
            decoded[key] = _as_int(value, key) if numeric else _as_str(value, key)
        if not numeric and str(decoded['history']) not in HISTORY_NAMES:
            decoded['history'] = 'unknown'
        if distro in ('humble', 'iron') or decoded['history'] in (1, 'keep_last'):
            decoded['depth'] = _as_int(_node(profile, 'depth'), 'depth')
        for key in ('deadline', 'lifespan', 'liveliness_lease_duration'):
            decoded[key] = _time(_node(profile, key), key)
        decoded['avoid_ros_namespace_conventions'] = _as_bool(
            _node(profile, 'avoid_ros_namespace_conventions'), 'avoid_ros_namespace_conventions')
        out.append(decoded)
    return out


def _topic(node: Any, version: int, distro: str) -> dict[str, Any]:
    topic = {key: _as_str(_node(node, key), key) for key in ('name', 'type', 'serialization_format')}
    if version >= 9:
        qos = _node(node, 'offered_qos_profiles')
        if not isinstance(qos, list):
            raise Rosbag2Error('version 9 offered_qos_profiles is not a sequence')
        topic['offered_qos_profiles'] = decode_qos(yaml.safe_dump(qos), distro)
    elif version >= 4:
        topic['offered_qos_profiles'] = decode_qos(_as_str(_node(node, 'offered_qos_profiles'), 'qos'), distro)
    if version >= 7:
        topic['type_description_hash'] = _as_str(_node(node, 'type_description_hash'), 'type_description_hash')
    return topic


def decode_bag_metadata(text: str, distro: str = 'jazzy') -> dict[str, Any]:
    """BagMetadata from a `serialized_metadata` (keys at the top level), as jazzy's MCAP reader decodes it."""
    node = yaml.safe_load(text)
    version = _as_int(_node(node, 'version'), 'version')
    info: dict[str, Any] = {'version': version,
                            'storage_identifier': _as_str(_node(node, 'storage_identifier'), 'storage_identifier'),
                            'duration': _as_int(_node(_node(node, 'duration'), 'nanoseconds'), 'duration'),
                            'starting_time': _as_int(_node(_node(node, 'starting_time'), 'nanoseconds_since_epoch'),
                                                     'starting_time'),
                            'message_count': _as_int(_node(node, 'message_count'), 'message_count')}
    topics = _node(node, 'topics_with_message_count')
    if not isinstance(topics, list):
        raise Rosbag2Error('topics_with_message_count is not a sequence')
    info['topics'] = [(_topic(_node(t, 'topic_metadata'), version, distro),
                       _as_int(_node(t, 'message_count'), 'message_count')) for t in topics]
    paths = _node(node, 'relative_file_paths')
    if not isinstance(paths, list):
        raise Rosbag2Error('relative_file_paths is not a sequence')
    info['relative_file_paths'] = [_as_str(p, 'relative_file_path') for p in paths]
    if version >= 3:
        info['compression_format'] = _as_str(_node(node, 'compression_format'), 'compression_format')
        info['compression_mode'] = _as_str(_node(node, 'compression_mode'), 'compression_mode')
    if version >= 5:
        files = _node(node, 'files')
        if not isinstance(files, list):
            raise Rosbag2Error('files is not a sequence')
        info['files'] = [(_as_str(_node(f, 'path'), 'path'),
                          _as_int(_node(_node(f, 'starting_time'), 'nanoseconds_since_epoch'), 'starting_time'),
                          _as_int(_node(_node(f, 'duration'), 'nanoseconds'), 'duration'),
                          _as_int(_node(f, 'message_count'), 'message_count')) for f in files]
    if version >= 6:
        custom = _node(node, 'custom_data')
        if custom is not None and not isinstance(custom, dict):
            raise Rosbag2Error('custom_data is not a map')
        info['custom_data'] = dict(custom or {})
    if version >= 8:
        info['ros_distro'] = _as_str(_node(node, 'ros_distro'), 'ros_distro')
    return info


def check_mcap(path: Any, distros: tuple[str, ...] = DISTROS) -> dict[str, Any]:
    """Open an MCAP as `ros2 bag info` of each distro would: every channel's QoS for humble, iron and jazzy,
    the last `rosbag2` record for jazzy. Returns jazzy's BagMetadata; raises Rosbag2Error where one throws."""
    from mcap.reader import make_reader

    with open(path, 'rb') as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        assert summary is not None
        records = [m for m in reader.iter_metadata() if m.name == 'rosbag2']
    for channel in summary.channels.values():
        for distro in distros:
            decode_qos(channel.metadata.get('offered_qos_profiles', ''), distro)
    if not records:
        raise Rosbag2Error('no rosbag2 metadata record')
    info: dict[str, Any] = {}
    for record in records:  # jazzy decodes each in turn; the last one stands
        if 'serialized_metadata' not in record.metadata:
            raise Rosbag2Error('rosbag2 record without serialized_metadata')
        info = decode_bag_metadata(record.metadata['serialized_metadata'])
    return info


def distros_reading(path: Any) -> tuple[str, ...]:
    """The distros whose players read every channel's QoS of an MCAP (a Jazzy recording's names: jazzy only)."""
    from mcap.reader import make_reader

    with open(path, 'rb') as stream:
        summary = make_reader(stream).get_summary()
    found = []
    for distro in DISTROS:
        try:
            for channel in summary.channels.values():
                decode_qos(channel.metadata.get('offered_qos_profiles', ''), distro)
        except Rosbag2Error:
            continue
        found.append(distro)
    return tuple(found)
