"""Every count an input declares is checked against what was read: a difference is an error naming both counts
(no output), or with --salvage a warning saying how many are missing."""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import pytest
from support.helpers import FIXTURES, make_bag

from bagfault.cli import main

SCENARIO = 'injector: {id: i, type: imu, input_topic: /imu, output_topic: /imu_out}\nfaults: []\n'


def declare(path: Path, count: int) -> None:
    """Set the Statistics record's message_count of an MCAP and write the summary CRC again (a consistent summary
    that counts messages the file does not hold, as one whose chunk index left a chunk out)."""
    data = bytearray(path.read_bytes())
    footer = len(data) - 8 - 29
    _, _, summary_start, _, _ = struct.unpack('<BQQQI', data[footer:footer + 29])
    position = summary_start
    found = False
    while position < footer:
        opcode, length = data[position], struct.unpack_from('<Q', data, position + 1)[0]
        if opcode == 0x0B:  # Statistics: message_count is its first field
            struct.pack_into('<Q', data, position + 9, count)
            found = True
        position += 9 + length
    assert found
    struct.pack_into('<I', data, footer + 25, zlib.crc32(data[summary_start:footer + 25]))
    path.write_bytes(bytes(data))


@pytest.mark.parametrize('copy', [True, False], ids=['chunk-copy', 'reference'])
def test_an_mcap_that_declares_more_messages_than_it_holds(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                          copy: bool) -> None:
    bag = make_bag(tmp_path / 'imu.mcap', [('/imu', 'sensor_msgs/msg/Imu', 50.0)], 2.0)  # 100 messages
    declare(bag, 103)
    (tmp_path / 's.yaml').write_text(SCENARIO)
    options = [] if copy else ['--no-chunk-copy']
    code = main(['run', str(tmp_path / 's.yaml'), str(bag), '-o', str(tmp_path / 'out.mcap'), *options])
    err = capsys.readouterr().err
    assert code == 2 and err.count('\n') == 1
    assert f'{bag}: the input declares 103 messages and 100 were read: part of it was not read' in err
    assert not (tmp_path / 'out.mcap').exists()
    code = main(['run', str(tmp_path / 's.yaml'), str(bag), '-o', str(tmp_path / 'out.mcap'), '--salvage',
                 *options])
    err = capsys.readouterr().err
    assert code == 0 and 'declares 103 messages and 100 were read: 3 missing (--salvage)' in err
    assert (tmp_path / 'out.mcap').exists()


def test_a_rosbag2_folder_whose_metadata_claims_more_than_its_storage_holds(tmp_path: Path,
                                                                          capsys: pytest.CaptureFixture[str]) -> None:
    import shutil

    import yaml

    bag = tmp_path / 'bag'
    shutil.copytree(FIXTURES / 'rover_3s_sqlite3', bag)
    meta = yaml.safe_load((bag / 'metadata.yaml').read_text())
    held = meta['rosbag2_bagfile_information']['message_count']
    meta['rosbag2_bagfile_information']['message_count'] = held + 32
    (bag / 'metadata.yaml').write_text(yaml.safe_dump(meta))
    (tmp_path / 's.yaml').write_text(SCENARIO)
    code = main(['check', str(tmp_path / 's.yaml'), str(bag)])
    err = capsys.readouterr().err
    assert code == 2 and f'the input declares {held + 32} messages and {held} were read' in err


def test_a_rosbag2_folder_holding_a_storage_file_its_metadata_does_not_list(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A split metadata.yaml does not list (a stray copy, or rosbag2's own Dashing test bag, which holds a
    test.db3 beside cdr_test.db3): rosbag2 reads only the listed files, and so does bagfault, saying so."""
    import shutil

    folder = tmp_path / 'bag'
    shutil.copytree(FIXTURES / 'rover_3s_sqlite3', folder)
    shutil.copy(folder / 'rover_3s_sqlite3.db3', folder / 'rover_3s_sqlite3_1.db3')
    scenario = tmp_path / 'scenario.yaml'
    scenario.write_text(SCENARIO)
    out = tmp_path / 'out.mcap'
    assert main(['run', str(scenario), str(folder), '-o', str(out)]) == 0
    captured = capsys.readouterr()
    assert 'rover_3s_sqlite3_1.db3 in the folder but not listed in metadata.yaml: not read' in captured.err
    assert 'from 780 read' in captured.out  # the listed file's 780 messages, once
