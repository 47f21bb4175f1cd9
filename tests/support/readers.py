"""An output through every check another tool makes."""

from __future__ import annotations

import struct
import zlib
from typing import TYPE_CHECKING

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

if TYPE_CHECKING:
    from pathlib import Path


def verify(path: Path) -> int:
    """Every check another tool makes: CRCs (mcap), decoding of every message (mcap-ros2-support), rosbags."""
    with path.open('rb') as stream:
        reader = make_reader(stream, validate_crcs=True, decoder_factories=[DecoderFactory()])
        decoded = sum(1 for _ in reader.iter_decoded_messages())
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
        for connection, _, raw in reader.messages():
            reader.deserialize(raw, connection.msgtype)
    data = path.read_bytes()
    footer = len(data) - 8 - 29
    _, _, summary_start, _, crc = struct.unpack('<BQQQI', data[footer:footer + 29])
    assert crc != 0 and crc == zlib.crc32(data[summary_start:footer + 25])  # the summary CRC is written
    return decoded
