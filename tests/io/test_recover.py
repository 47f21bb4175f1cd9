"""`bagfault recover`: a recording cut at any byte keeps every message of its complete chunks."""

from __future__ import annotations

import struct
import subprocess
import sys
from pathlib import Path

import pytest
from support.helpers import raw_messages

from bagfault import api
from bagfault.errors import InputError
from bagfault.io.mcap_sink import McapSink
from bagfault.io.recover import requested_name

CHUNK = 0x06


def partial_recording(tmp_path: Path, messages: int) -> tuple[McapSink, Path]:
    """A live-style recording left unfinished: one chunk per message (flush_every=0), as a kill leaves it."""
    sink = McapSink(tmp_path / 'live.mcap', flush_every=0.0)
    sink.add_metadata('bagfault', {'mode': 'proxy'})
    channel = sink.add_channel('/imu', 'sensor_msgs/msg/Imu', 'ros2msg', 'float64 x')
    for n in range(messages):
        sink.write(channel, 1_000 + n, 1_000 + n, struct.pack('<Q', n))
    return sink, sink.partial


def chunk_ends(data: bytes) -> list[int]:
    """Byte offsets where each chunk record ends, from the record framing (opcode, u64 length) alone."""
    ends, offset = [], 8
    while offset + 9 <= len(data):
        opcode, length = struct.unpack_from('<BQ', data, offset)
        offset += 9 + length
        if opcode == CHUNK and offset <= len(data):
            ends.append(offset)
    return ends


@pytest.mark.parametrize('cut', [0.35, 0.5, 0.9, 0.999])
def test_a_cut_recording_keeps_the_messages_of_its_complete_chunks(tmp_path: Path, cut: float) -> None:
    sink, partial = partial_recording(tmp_path, 200)
    data = partial.read_bytes()
    sink.abort()
    size = int(len(data) * cut)
    killed = tmp_path / '.out.mcap.x1y2.partial'
    killed.write_bytes(data[:size])
    complete = sum(end <= size for end in chunk_ends(data))
    done = api.recover(tmp_path / 'out.mcap')  # the name that was asked for; the partial is found beside it
    assert done.source == killed and done.output == tmp_path / 'out.mcap'
    assert not done.complete and done.stopped
    assert done.messages == complete > 0
    got = raw_messages(done.output)['/imu']  # read back by the mcap library, summary and CRCs included
    assert [struct.unpack('<Q', d)[0] for _, _, d in got] == list(range(complete))
    assert killed.read_bytes() == data[:size]  # the input is untouched


def test_a_complete_recording_comes_back_whole(tmp_path: Path) -> None:
    sink = McapSink(tmp_path / 'whole.mcap')
    channel = sink.add_channel('/a', 'std_msgs/msg/String', 'ros2msg', 'string data')
    for n in range(50):
        sink.write(channel, n, n, bytes([n]) * 3)
    sink.finish()
    done = api.recover(tmp_path / 'whole.mcap', tmp_path / 'again.mcap')
    assert done.complete and done.messages == 50
    assert raw_messages(tmp_path / 'again.mcap') == raw_messages(tmp_path / 'whole.mcap')


def test_nothing_to_recover_is_one_clear_error(tmp_path: Path) -> None:
    with pytest.raises(InputError, match=r'no partial recording \(\.gone\.mcap\.\*\.partial\)'):
        api.recover(tmp_path / 'gone.mcap')
    (tmp_path / 'notes.txt').write_text('hello')
    with pytest.raises(InputError, match='not an MCAP recording'):
        api.recover(tmp_path / 'notes.txt', tmp_path / 'x.mcap')
    assert not (tmp_path / 'x.mcap').exists()
    cli = subprocess.run([sys.executable, '-m', 'bagfault.cli', 'recover', str(tmp_path / 'gone.mcap')],
                         capture_output=True, text=True, check=False)
    assert cli.returncode == 2 and len(cli.stderr.strip().splitlines()) == 1


def test_requested_names() -> None:
    assert requested_name(Path('/d/.out.mcap.k2j4x.partial')) == Path('/d/out.mcap')
    assert requested_name(Path('/d/copy.mcap')) == Path('/d/copy.recovered.mcap')


def test_a_recovered_recording_opens_in_the_ros_toolchain_with_the_recorders_distro(tmp_path: Path) -> None:
    from support.toolchain import assert_toolchain_opens

    sink = McapSink(tmp_path / 'live.mcap', ros_distro='jazzy', flush_every=0.0)
    channel = sink.add_channel('/n', 'std_msgs/msg/Int32', 'ros2msg', 'int32 data',
                               metadata={'offered_qos_profiles': '- history: keep_last\n  depth: 5\n'
                                                                 '  reliability: best_effort\n'})
    for n in range(40):
        sink.write(channel, 1_000 + n, 1_000 + n, b'\x00\x01\x00\x00' + struct.pack('<i', n))
    data = sink.partial.read_bytes()
    sink.abort()
    (tmp_path / '.out.mcap.k1.partial').write_bytes(data[:chunk_ends(data)[-1] + 3])  # cut inside the next record
    done = api.recover(tmp_path / 'out.mcap')
    assert done.messages == 40
    info = assert_toolchain_opens(done.output, tmp_path, distro='jazzy')  # from the recording's opening record
    [(topic, count)] = info['topics']
    assert count == 40 and topic['offered_qos_profiles'][0]['reliability'] == 2  # best effort, in rmw's number
