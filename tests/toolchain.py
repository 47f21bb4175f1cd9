"""The ROS toolchain's view of an output: rosbag2's rules (rosbag2_rules), rosbags' AnyReader, `rosbags-convert`."""

from __future__ import annotations

import subprocess
import sys
from collections import Counter
from pathlib import Path
from typing import Any

from helpers import counts
from mcap.reader import make_reader
from rosbag2_rules import check_mcap, decode_qos
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore


def any_reader_decodes(path: Path) -> Counter[str]:
    """Messages per topic that rosbags' AnyReader opens and deserializes (types it knows)."""
    found: Counter[str] = Counter()
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
        for connection, _, raw in reader.messages():
            if connection.msgdef.data:
                reader.deserialize(raw, connection.msgtype)
            found[connection.topic] += 1
    return found


def converted(path: Path, tmp_path: Path) -> Counter[str]:
    """`rosbags-convert` of the file into a rosbag2 sqlite3 bag, read back with AnyReader."""
    target = tmp_path / f'{path.stem}_converted'
    tool = Path(sys.executable).with_name('rosbags-convert')
    done = subprocess.run([str(tool), '--src', str(path), '--dst', str(target), '--dst-storage', 'sqlite3'],
                          capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 0, done.stderr
    with AnyReader([target]) as reader:
        return Counter(connection.topic for connection, _, _ in reader.messages())


def assert_toolchain_opens(path: Path, tmp_path: Path, *, distro: str | None = None) -> dict[str, Any]:
    """Every check of the issue: rosbag2's rules for three distros, no anchors, AnyReader, rosbags-convert."""
    info = check_mcap(path)
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
        text = channel.metadata['offered_qos_profiles']
        assert '&' not in text and '*id' not in text, text  # rosbag2 never writes YAML anchors
        for profile in decode_qos(text, 'humble'):
            assert len(profile) == 9  # the nine keys, numbers
        assert 'topic_type_hash' in channel.metadata
    assert all('&id' not in value for record in records for value in record.metadata.values())
    assert any_reader_decodes(path) == Counter({t: n for t, n in found.items() if n})
    assert converted(path, tmp_path) == Counter({t: n for t, n in found.items() if n})
    return info
