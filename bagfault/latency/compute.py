"""End-to-end path latency from bag data, vectorised with numpy.

A bag holds per message the recorder's receive time (log_time) and, for
stamped types, header.stamp. Each message of the path's last topic is
traced back hop by hop to a first-topic message:
- `inherit_unique_stamp`: the input with the same header.stamp, the latest
  one received before the output when stamps repeat;
- `use_latest_message` and `callback_chain` (which bag data cannot tell
  apart), and `tilde`/`UNDEFINED` as a fallback: the latest input received
  at or before the output.
Latency = output log_time - matched first-topic log_time (or its
header.stamp with stamp_origin). CARET's response-time cases follow: best
(first output per input), worst (first output minus the previous answered
input) and all (every input to the first output that reflects it or a
later input).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from bagfault.errors import LatencyError

if TYPE_CHECKING:
    from bagfault.latency.architecture import Architecture, NamedPath

STAMP_CONTEXTS = {'inherit_unique_stamp'}
NS_PER_MS = 1_000_000


@dataclass
class TopicSeries:
    """Receive times (ns, sorted) and header stamps (ns, or None) of one topic."""

    times: np.ndarray
    stamps: np.ndarray | None = None

    @classmethod
    def empty(cls) -> TopicSeries:
        """A topic with no messages."""
        return cls(np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64))


@dataclass
class PathResult:
    """Samples and response-time cases of one path (all times ns, latencies ms)."""

    name: str
    topics: list[str]
    sample_times: np.ndarray
    input_times: np.ndarray
    latency_ms: np.ndarray
    dropped: int
    inputs: int
    best: tuple[np.ndarray, np.ndarray]
    worst: tuple[np.ndarray, np.ndarray]
    all_cases: tuple[np.ndarray, np.ndarray]
    notes: list[str] = field(default_factory=list)


def _latest_before(inputs: np.ndarray, outputs: np.ndarray) -> np.ndarray:
    """Index of the latest input with time <= output time, -1 when none."""
    return np.searchsorted(inputs, outputs, side='right') - 1


def _latest_same_stamp(in_times: np.ndarray, in_stamps: np.ndarray, out_times: np.ndarray,
                       out_stamps: np.ndarray) -> np.ndarray:
    """Index of the latest input with the output's stamp received at or before it, -1 when none."""
    if in_times.size == 0 or out_times.size == 0:
        return np.full(out_times.size, -1, dtype=np.int64)
    _, inverse = np.unique(np.concatenate([in_stamps, out_stamps]), return_inverse=True)
    in_ids, out_ids = inverse[: in_stamps.size], inverse[in_stamps.size:]
    ranks_all = np.unique(np.concatenate([in_times, out_times]))
    scale = np.int64(ranks_all.size + 1)
    in_keys = in_ids.astype(np.int64) * scale + np.searchsorted(ranks_all, in_times)
    out_keys = out_ids.astype(np.int64) * scale + np.searchsorted(ranks_all, out_times)
    order = np.argsort(in_keys, kind='stable')
    position = np.searchsorted(in_keys[order], out_keys, side='right') - 1
    valid = position >= 0
    found = np.where(valid, order[np.clip(position, 0, None)], -1)
    same = valid & (in_ids[np.clip(found, 0, None)] == out_ids)
    return np.where(same, found, -1)


Case = tuple[np.ndarray, np.ndarray]  # start times (ns), latencies (ms)


def _cases(input_times: np.ndarray, sample_times: np.ndarray, matched: np.ndarray,
           first_times: np.ndarray) -> tuple[Case, Case, Case]:
    """best, worst and all response-time cases as (start time, latency ms) arrays."""
    if matched.size == 0:
        empty = (np.zeros(0, dtype=np.int64), np.zeros(0))
        return empty, empty, empty
    order = np.lexsort((sample_times, matched))
    inputs_sorted, outputs_sorted = matched[order], sample_times[order]
    first = np.ones(inputs_sorted.size, dtype=bool)
    first[1:] = inputs_sorted[1:] != inputs_sorted[:-1]
    answered = inputs_sorted[first]               # distinct first-topic indexes, ascending
    first_out = outputs_sorted[first]             # their first output
    starts = first_times[answered]
    best = (starts, (first_out - starts) / NS_PER_MS)
    worst = (starts[1:], (first_out[1:] - starts[:-1]) / NS_PER_MS)
    position = np.searchsorted(starts, input_times, side='left')
    reached = position < starts.size
    all_starts = input_times[reached]
    all_cases = (all_starts, (first_out[position[reached]] - all_starts) / NS_PER_MS)
    return best, worst, all_cases


def path_latency(
    architecture: Architecture,
    path: NamedPath,
    series: dict[str, TopicSeries],
    *,
    stamp_origin: bool = False,
) -> PathResult:
    """Compute every end-to-end sample of a path from per-topic series."""
    if not path.usable:
        raise LatencyError(f'path {path.name} cannot be measured: {"; ".join(path.problems)}')
    topics = path.topics
    notes: list[str] = []
    for topic in topics:
        if topic not in series or series[topic].times.size == 0:
            notes.append(f'topic {topic} has no messages')
    last = series.get(topics[-1], TopicSeries.empty())
    index = np.arange(last.times.size)
    valid = np.ones(last.times.size, dtype=bool)
    hops = architecture.hops(path)
    for node, in_topic, out_topic, context in reversed(hops):
        source = series.get(in_topic, TopicSeries.empty())
        target = series.get(out_topic, TopicSeries.empty())
        kind = context.context_type if context else 'UNDEFINED'
        if kind in ('tilde', 'UNDEFINED'):
            notes.append(f'node {node}: context {kind} cannot be followed on bag data; using the latest message')
        safe = np.clip(index, 0, None)
        if kind in STAMP_CONTEXTS:
            if source.stamps is None or target.stamps is None:
                raise LatencyError(f'node {node}: inherit_unique_stamp needs header stamps on {in_topic} and '
                                   f'{out_topic}')
            found = _latest_same_stamp(source.times, source.stamps, target.times[safe], target.stamps[safe])
        else:
            found = _latest_before(source.times, target.times[safe])
        valid &= found >= 0
        index = np.where(valid, found, -1)
    first = series.get(topics[0], TopicSeries.empty())
    matched = index[valid]
    sample_times = last.times[valid]
    if stamp_origin:
        if first.stamps is None:
            raise LatencyError(f'stamp origin needs header stamps on {topics[0]}')
        origin = first.stamps[matched]
    else:
        origin = first.times[matched]
    latency = (sample_times - origin) / NS_PER_MS
    dropped = int(first.times.size - np.unique(matched).size)
    best, worst, all_cases = _cases(first.times, sample_times, matched, first.times)
    return PathResult(path.name, topics, sample_times, first.times[matched], latency, dropped,
                      int(first.times.size), best, worst, all_cases, notes)


STATISTICS = ('min', 'mean', 'p50', 'p95', 'p99', 'max')


def statistics(values: np.ndarray) -> dict[str, Any]:
    """count, min, mean, p50, p95, p99, max (ms); None values when empty."""
    if values.size == 0:
        return {'count': 0, **dict.fromkeys(STATISTICS)}
    return {
        'count': int(values.size),
        'min': float(values.min()),
        'mean': float(values.mean()),
        'p50': float(np.percentile(values, 50)),
        'p95': float(np.percentile(values, 95)),
        'p99': float(np.percentile(values, 99)),
        'max': float(values.max()),
    }


def window_mask(times: np.ndarray, windows: list[tuple[int, int | None]]) -> np.ndarray:
    """True for times inside any [start, end) window (end None: to the end)."""
    mask = np.zeros(times.size, dtype=bool)
    for start, end in windows:
        mask |= (times >= start) & (times < (end if end is not None else np.iinfo(np.int64).max))
    return mask


def by_fault(result: PathResult, windows: dict[str, list[tuple[int, int | None]]]) -> dict[str, dict[str, Any]]:
    """Statistics before / during / after each fault, samples classified by their first-topic time."""
    out = {}
    for fault_id, spans in windows.items():
        during = window_mask(result.input_times, spans)
        first, last_end = spans[0][0], spans[-1][1]
        before = (result.input_times < first) & ~during
        after = (~during & ~before) if last_end is not None else np.zeros(result.input_times.size, dtype=bool)
        out[fault_id] = {name: statistics(result.latency_ms[mask])
                         for name, mask in (('before', before), ('during', during), ('after', after))}
    return out
