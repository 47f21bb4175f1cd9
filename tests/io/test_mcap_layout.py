"""The padding before a long run of copied chunks (bagfault/io/mcap_layout.py), by hand: ALIGN 64 KiB, runs of
1 MiB or more, a record at least 9 bytes long (opcode and length)."""

from __future__ import annotations

import struct

from bagfault.io.mcap_layout import padding_length, padding_record

MIB = 1 << 20


def test_the_padding_puts_a_long_run_a_multiple_of_64_kib_from_its_input_place() -> None:
    assert padding_length(100, 100, MIB) == 0  # already there
    assert padding_length(100, 109, MIB) == 9  # the smallest record
    assert padding_length(100, 105, MIB) == 5 + 65536  # 5 bytes hold no record: the next place
    assert padding_length(70_000, 43, MIB) == 61_115  # 70000 + 61115 - 43 = 131072 = 2 x 65536
    assert padding_length(100, 105, MIB - 1) == 0  # a short run stays where it falls


def test_a_padding_record_is_its_opcode_its_length_and_zeros() -> None:
    assert padding_record(9) == b'\xa1' + bytes(8)
    record = padding_record(20)
    assert len(record) == 20 and struct.unpack_from('<BQ', record) == (0xA1, 11) and record[9:] == bytes(11)
