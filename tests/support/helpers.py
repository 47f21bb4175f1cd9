"""Independent readers of output files: the mcap library and rosbags, never bagfault."""

from __future__ import annotations

import hashlib
import os
import random
from collections import Counter, defaultdict
from pathlib import Path
from typing import Any

from mcap.reader import make_reader
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

NS = 1_000_000_000
ROOT = Path(__file__).resolve().parents[2]
FIXTURES = ROOT / 'tests' / 'fixtures'
SHARED = Path(os.environ.get('BAGFAULT_SHARED', ROOT.parent / 'shared'))
EXTERNAL = SHARED / 'external_bags'
ANCHORS = SHARED / 'anchor_scenarios'
CARET = SHARED / 'caret_samples'


def need(path: Path) -> Path:
    """Skip the test cleanly when third-party data is absent, saying so."""
    if not path.exists():
        import pytest

        pytest.skip(f'needs third-party data: {path} not present (set BAGFAULT_SHARED)')
    return path


def rpy(q: Any) -> tuple[float, float, float]:
    """Roll, pitch, yaw (ZYX) of a geometry_msgs Quaternion, by the textbook formulas."""
    import math

    x, y, z, w = q.x, q.y, q.z, q.w
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return roll, pitch, yaw


def image_pixels(message: Any) -> Any:
    """height x width x channels numpy array of a sensor_msgs/Image (rows of `step` bytes, REP 118 encodings)."""
    import numpy as np

    kind, channels = {'mono8': ('u1', 1), 'rgb8': ('u1', 3), 'bgr8': ('u1', 3), 'mono16': ('u2', 1),
                      '32FC1': ('f4', 1)}[message.encoding]
    dtype = np.dtype(('>' if message.is_bigendian else '<') + kind)
    rows = np.asarray(message.data, dtype=np.uint8).reshape(message.height, message.step)
    used = rows[:, :message.width * channels * dtype.itemsize].copy()
    return used.view(dtype).reshape(message.height, message.width, channels)


def third_party(cases: list[Any], *, arity: int = 1) -> list[Any]:
    """Parameter cases made of third-party files: the cases when they are here, else one case that skips."""
    if EXTERNAL.exists() and ANCHORS.exists():
        return list(cases)
    import pytest

    reason = f'needs third-party data: {SHARED} not present (set BAGFAULT_SHARED)'
    return [pytest.param(*([None] * arity), marks=pytest.mark.skip(reason=reason), id='third-party-data-absent')]


def counts(path: Path) -> Counter[str]:
    """Messages per topic, read with the mcap library."""
    with path.open('rb') as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        return Counter({summary.channels[cid].topic: n for cid, n in summary.statistics.channel_message_counts.items()})


def chunk_indexes(path: Path) -> list[Any]:
    """The chunk indexes of an MCAP file in file order (mcap library)."""
    with path.open('rb') as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None
    return sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)


def raw_messages(path: Path) -> dict[str, list[tuple[int, int, bytes]]]:
    """topic -> [(log_time, publish_time, data)] in log-time order, with the mcap library."""
    out: dict[str, list[tuple[int, int, bytes]]] = defaultdict(list)
    with path.open('rb') as stream:
        for _, channel, message in make_reader(stream).iter_messages(log_time_order=True):
            out[channel.topic].append((message.log_time, message.publish_time, message.data))
    return dict(out)


def decoded(path: Path, topics: list[str] | None = None) -> dict[str, list[tuple[int, Any]]]:
    """topic -> [(log_time, message)] decoded by rosbags from the definitions in the file.

    Channels whose schema is empty (a type nobody could decode) give raw bytes.
    """
    out: dict[str, list[tuple[int, Any]]] = defaultdict(list)
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
        connections = [c for c in reader.connections if topics is None or c.topic in topics]
        for connection, time, raw in reader.messages(connections=connections):
            opaque = path.suffix == '.mcap' and not connection.msgdef.data
            out[connection.topic].append((time, bytes(raw) if opaque else reader.deserialize(raw, connection.msgtype)))
    return dict(out)


def rosbags_counts(path: Path) -> Counter[str]:
    """Messages per topic as rosbags' AnyReader sees them (no decoding)."""
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
        return Counter(connection.topic for connection, _, _ in reader.messages())


def sha256(path: Path) -> str:
    """Digest of a file."""
    return hashlib.sha256(path.read_bytes()).hexdigest()


def tree_digest(path: Path) -> str:
    """Digest of a file or of every file below a folder (to prove inputs are untouched)."""
    digest = hashlib.sha256()
    files = sorted(p for p in path.rglob('*') if p.is_file()) if path.is_dir() else [path]
    for file in files:
        digest.update(file.name.encode())
        digest.update(file.read_bytes())
        digest.update(str(file.stat().st_mtime_ns).encode())
    return digest.hexdigest()


def make_bag(path: Path, streams: list[tuple[str, str, float]], duration: float) -> Path:
    """A synthetic MCAP with (topic, type, rate) streams, values from bagfault.demo.synthetic."""
    from bagfault.demo import synthetic

    specs = [synthetic.Stream(topic, msgtype, rate) for topic, msgtype, rate in streams]
    synthetic.write_mcap(path, synthetic.messages(specs, duration))
    return path


def run_inline(tmp: Path, scenario_text: str, bag: Path, **kw: Any) -> tuple[Path, Any]:
    """Run a scenario given as YAML text; return (output path, result)."""
    import textwrap

    from bagfault import api
    from bagfault.scenario import parse_scenario

    out = tmp / 'out.mcap'
    result = api.run(parse_scenario(textwrap.dedent(scenario_text)), [bag], out, **kw)
    return out, result


def claim_port_base(rng: random.Random | None = None) -> int:
    """A base for a test's own domain-claim ports (`BAGFAULT_DOMAIN_PORT_BASE`): below the kernel's ephemeral
    range, where no outgoing connection of another process takes a port (the range's ports are what a busy
    machine hands out: a claim there failed when some client had just been given it), above Ray's worker ports;
    `rng` picks one of several (a second suite beside this one runs the same test)."""
    try:
        low = int(Path('/proc/sys/net/ipv4/ip_local_port_range').read_text().split()[0])
    except (OSError, ValueError, IndexError):
        low = 32768
    top = low - 300  # room for every domain id (0-232) above the base
    return rng.randrange(20000, top, 300) if rng is not None else top
