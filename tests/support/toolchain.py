"""The toolchain's view of an output: rosbag2's rules (rosbag2_rules), rosbags' AnyReader, `rosbags-convert`,
Foxglove's MCAP library (support.foxglove)."""

from __future__ import annotations

import subprocess
import sys
import tempfile
from collections import Counter
from collections.abc import Collection
from pathlib import Path
from typing import Any

import yaml
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

from support.foxglove import foxglove_reads
from support.helpers import counts
from support.rosbag2_rules import DISTROS, check_mcap, decode_qos

PADDING = 0xA1  # bagfault's padding record before an aligned run of copied chunks (docs/modes/run.md)
NINE_KEYS = {'history', 'depth', 'reliability', 'durability', 'deadline', 'lifespan', 'liveliness',
             'liveliness_lease_duration', 'avoid_ros_namespace_conventions'}


def any_reader_decodes(path: Path, undecodable: Collection[str] = ()) -> Counter[str]:
    """Messages per topic that rosbags' AnyReader opens and deserializes (types with a definition)."""
    found: Counter[str] = Counter()
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
        for connection, _, raw in reader.messages():
            if connection.msgdef.data and connection.topic not in undecodable:
                reader.deserialize(raw, connection.msgtype)
            found[connection.topic] += 1
    return found


def undefined_types(path: Path) -> set[str]:
    """Types whose schema is empty (no definition anywhere): no tool can convert or decode them."""
    with path.open('rb') as stream:
        summary = make_reader(stream).get_summary()
    return {s.name for s in summary.schemas.values() if not s.data}


def converted(path: Path, tmp_path: Path, left_out: Collection[str] = ()) -> Counter[str]:
    """`rosbags-convert` of the file into a rosbag2 sqlite3 bag, read back with AnyReader (types without a
    definition left out: rosbags-convert refuses them, in the input as in the output)."""
    target = Path(tempfile.mkdtemp(prefix=f'{path.stem}_', dir=tmp_path)) / 'converted'
    tool = Path(sys.executable).with_name('rosbags-convert')
    undefined = sorted(undefined_types(path))
    exclude = ['--exclude-msgtype', *undefined] if undefined else []
    exclude += ['--exclude-topic', *left_out] if left_out else []
    done = subprocess.run([str(tool), '--src', str(path), '--dst', str(target), '--dst-storage', 'sqlite3',
                           *exclude], capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 0, done.stdout + done.stderr
    with AnyReader([target]) as reader:
        return Counter(connection.topic for connection, _, _ in reader.messages())


def assert_toolchain_opens(path: Path, tmp_path: Path, *, distro: str | None = None,
                           distros: tuple[str, ...] = DISTROS, undecodable: Collection[str] = ()) -> dict[str, Any]:
    """rosbag2's rules for the distros (all three unless the input's own QoS was readable by fewer), no anchors,
    AnyReader decoding every message (but on `undecodable` topics), `rosbags-convert`."""
    info = check_mcap(path, distros)
    assert info['version'] == 8 and info['storage_identifier'] == 'mcap'
    assert distro is None or info['ros_distro'] == distro
    found = counts(path)
    assert info['message_count'] == sum(found.values())
    listed = {topic['name']: n for topic, n in info['topics']}
    assert listed == {t: found.get(t, 0) for t in listed} and set(listed) >= {t for t, n in found.items() if n}
    with path.open('rb') as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        records = [*reader.iter_metadata()]
    for channel in summary.channels.values():
        text = channel.metadata.get('offered_qos_profiles', '')  # an input's channel kept as it is may have none
        assert '&' not in text and '*id' not in text, text  # rosbag2 never writes YAML anchors
        decode_qos(text, distros[0])
        assert all(set(profile) == NINE_KEYS for profile in yaml.safe_load(text) or [])
        type_hash = channel.metadata.get('topic_type_hash', '')  # optional for every reader
        assert type_hash == '' or type_hash.startswith('RIHS01_')
    assert all('&id' not in value for record in records for value in record.metadata.values())
    assert any_reader_decodes(path, undecodable) == Counter({t: n for t, n in found.items() if n})
    undefined = {c.topic for c in summary.channels.values() if not summary.schemas[c.schema_id].data}
    assert converted(path, tmp_path, undecodable) == Counter(
        {t: n for t, n in found.items() if n and t not in undefined and t not in undecodable})
    foxglove = foxglove_reads(path)
    assert foxglove['indexed'] == foxglove['stream']['counts'] == {t: n for t, n in found.items() if n}
    assert foxglove['stream']['done'] and set(foxglove['stream']['unknown']) <= {PADDING}
    return info
