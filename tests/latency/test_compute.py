"""caret_analyze's own response-time unit tests, ported: class, test name, records and expected values from
tier4/caret_analyze src/test/record/records_service/test_response_time_all.py at commit 679f1ec9.

A caret record is one message flow (start, end), end None when the flow was
dropped. Here each distinct start is one first-topic message and each record
with an end one output matched to it, which is what bagfault's path tracing
produces; `response_cases` must then give caret's records exactly.
Times are caret's integers, read as nanoseconds; the expected response
times are converted to milliseconds.
"""

from __future__ import annotations

import numpy as np
import pytest
from support.helpers import FIXTURES

from bagfault.demo import synthetic
from bagfault.latency.compute import response_cases
from bagfault.latency.measure import measure

NS_PER_MS = 1_000_000

CASES = [
    ('TestResponseTimeAll', 'test_two_column_default_case', 'all', [(0, 2), (3, 4), (11, 12)], [(3, 1), (11, 1)]),
    ('TestResponseTimeAll', 'test_three_column_default_case', 'all', [(0, 2), (3, 6), (11, 16)], [(3, 3), (11, 5)]),
    ('TestResponseTimeAll', 'test_single_input_multi_output_case', 'all', [(0, 4), (1, 5), (1, 6), (1, 13)],
     [(1, 4)]),
    ('TestResponseTimeAll', 'test_multi_input_single_output_case', 'all', [(0, 12), (1, 13), (2, 13), (5, 13)],
     [(1, 12), (2, 11), (5, 8)]),
    ('TestResponseTimeAll', 'test_drop_case', 'all', [(0, 12), (1, 13), (2, None), (5, 13)],
     [(1, 12), (2, 11), (5, 8)]),
    ('TestResponseTimeAll', 'test_cross_flow_case', 'all', [(0, 10), (3, 4), (4, 10), (6, 6)],
     [(0, 10), (4, 6), (6, 0)]),
    ('TestResponseTimeAll', 'test_invalid_value_case', 'all', [(0, 2), (3, 2), (3, 4), (11, 12), (13, 12)],
     [(3, 1), (11, 1)]),
    ('TestResponseTimeBest', 'test_two_column_default_case', 'best', [(0, 2), (3, 4), (11, 12)], [(3, 1), (11, 1)]),
    ('TestResponseTimeBest', 'test_three_column_default_case', 'best', [(0, 2), (3, 6), (11, 16)],
     [(3, 3), (11, 5)]),
    ('TestResponseTimeBest', 'test_single_input_multi_output_case', 'best', [(0, 4), (1, 5), (1, 6), (1, 13)],
     [(1, 4)]),
    ('TestResponseTimeBest', 'test_multi_input_single_output_case', 'best', [(0, 12), (1, 13), (2, 13), (5, 13)],
     [(5, 8)]),
    ('TestResponseTimeBest', 'test_cross_flow_case', 'best', [(0, 10), (3, 4), (4, 10), (6, 6)], [(4, 6), (6, 0)]),
    ('TestResponseTimeBest', 'test_invalid_value_case', 'best', [(0, 2), (3, 2), (3, 4), (11, 12), (13, 12)],
     [(3, 1), (11, 1)]),
    ('TestResponseTimeWorstWithExternalLatency', 'test_two_column_default_case', 'worst-with-external-latency',
     [(0, 2), (3, 4), (11, 12)], [(3, 9)]),
    ('TestResponseTimeWorstWithExternalLatency', 'test_three_column_default_case', 'worst-with-external-latency',
     [(0, 2), (3, 6), (11, 16)], [(3, 13)]),
    ('TestResponseTimeWorstWithExternalLatency', 'test_single_input_multi_output_case',
     'worst-with-external-latency', [(0, 3), (1, 5), (1, 6), (3, 11), (3, 13)], [(1, 10)]),
    ('TestResponseTimeWorstWithExternalLatency', 'test_multi_input_single_output_case',
     'worst-with-external-latency', [(0, 12), (1, 13), (2, 13), (5, 13)], [(1, 12)]),
    ('TestResponseTimeWorstWithExternalLatency', 'test_drop_case', 'worst-with-external-latency',
     [(0, 12), (1, 13), (2, None), (5, 13)], [(1, 12)]),
    ('TestResponseTimeWorstWithExternalLatency', 'test_cross_flow_case', 'worst-with-external-latency',
     [(0, 10), (3, 4), (4, 10), (6, 6)], [(0, 10), (4, 2)]),
    ('TestResponseTimeWorstWithExternalLatency', 'test_invalid_value_case', 'worst-with-external-latency',
     [(0, 2), (3, 2), (3, 4), (11, 12), (13, 12)], [(3, 9)]),
    ('TestResponseTimeWorst', 'test_two_column_default_case', 'worst', [(0, 2), (3, 4), (11, 12)], [(3, 1), (11, 1)]),
    ('TestResponseTimeWorst', 'test_three_column_default_case', 'worst', [(0, 2), (3, 6), (11, 16)],
     [(3, 3), (11, 5)]),
    ('TestResponseTimeWorst', 'test_single_input_multi_output_case', 'worst', [(0, 4), (1, 5), (1, 6), (1, 13)],
     [(1, 4)]),
    ('TestResponseTimeWorst', 'test_multi_input_single_output_case', 'worst', [(0, 12), (1, 13), (2, 13), (5, 13)],
     [(1, 12)]),
    ('TestResponseTimeWorst', 'test_drop_case', 'worst', [(0, 8), (1, None), (5, 13)], [(1, 12)]),
    ('TestResponseTimeWorst', 'test_cross_flow_case', 'worst', [(0, 10), (3, 4), (4, 10), (6, 6)],
     [(0, 10), (6, 0)]),
    ('TestResponseTimeWorst', 'test_invalid_value_case', 'worst', [(0, 2), (3, 2), (3, 4), (11, 12), (13, 12)],
     [(3, 1), (11, 1)]),
]


def as_trace(records: list[tuple[int, int | None]]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """caret records as (input start times, input index of each output, output times)."""
    starts = sorted({start for start, _ in records})
    matched = [starts.index(start) for start, end in records if end is not None]
    ends = [end for _, end in records if end is not None]
    return np.array(starts, dtype=np.int64), np.array(matched, dtype=np.int64), np.array(ends, dtype=np.int64)


@pytest.mark.parametrize(('cls', 'name', 'case', 'records', 'expected'), CASES,
                         ids=[f'{c[0]}.{c[1]}' for c in CASES])
def test_caret_response_time_case(cls: str, name: str, case: str, records: list[tuple[int, int | None]],
                                  expected: list[tuple[int, int]]) -> None:
    starts, values = response_cases(*as_trace(records))[case]
    assert list(zip(starts.tolist(), (values * NS_PER_MS).round().astype(int).tolist(), strict=True)) == expected


def test_empty_case() -> None:
    """Every class's test_empty_case: no records, no response times."""
    cases = response_cases(*as_trace([]))
    assert {name: len(starts) for name, (starts, _) in cases.items()} == {
        'all': 0, 'best': 0, 'worst': 0, 'worst-with-external-latency': 0}


def test_two_column_default_case_written_as_a_bag(tmp_path) -> None:
    """caret's records (0,2), (3,4), (11,12) as a one-hop bag (ms): all, best, worst hold 2 entries of 1 ms,
    worst-with-external-latency one of 9 ms, measured end to end by `bagfault latency`."""
    arch = tmp_path / 'arch.yaml'
    arch.write_text((FIXTURES / 'caret' / 'one_hop.yaml').read_text().replace('CONTEXT', 'use_latest_message'))
    a, b = synthetic.Stream('/a', 'std_msgs/msg/String', 1.0), synthetic.Stream('/b', 'std_msgs/msg/String', 1.0)
    start = synthetic.DEFAULT_START
    records = sorted([(start + t * NS_PER_MS, stream, b'\x00\x01\x00\x00\x01\x00\x00\x00\x00\x00\x00\x00')
                      for stream, times in ((a, (0, 3, 11)), (b, (2, 4, 12))) for t in times], key=lambda r: r[0])
    bag = tmp_path / 'caret.mcap'
    synthetic.write_mcap(bag, [(stream, time, data) for time, stream, data in records])
    [result] = measure(arch, [bag]).results
    got = {case: values.tolist() for case, (_, values) in result.cases.items()}
    assert got == {'all': [1.0, 1.0], 'best': [1.0, 1.0], 'worst': [1.0, 1.0], 'worst-with-external-latency': [9.0]}
    assert result.latency_ms.tolist() == [2.0, 1.0, 1.0]  # per-sample latency keeps every output
