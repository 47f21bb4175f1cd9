"""End-to-end path latency from bag data, vectorised with numpy.

A bag holds per message the recorder's receive time (log_time) and, for
stamped types, header.stamp. Each message of the path's last topic is
traced back hop by hop to a first-topic message:
- `inherit_unique_stamp`: the input with the same header.stamp, the latest
  one received before the output when stamps repeat;
- `use_latest_message` and `callback_chain` (which bag data cannot tell
  apart), and `tilde` (with a note): the latest input received at or before
  the output.
A hop with no message context ends the measurement at that node's input, as
caret's record merge stops there. Latency = output log_time - matched
first-topic log_time (or its header.stamp with stamp_origin). CARET's
response-time cases (all, best, worst, worst-with-external-latency) follow
caret_analyze's ResponseMapAll on the same (input, output) records.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from bagfault.errors import LatencyError
from bagfault.units import MS

if TYPE_CHECKING:
    from bagfault.latency.architecture import Architecture, MessageContext, NamedPath

STAMP_CONTEXTS = {'inherit_unique_stamp'}


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
    cases: dict[str, tuple[np.ndarray, np.ndarray]]  # CASES -> (start times ns, response times ms)
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
CASES = ('all', 'best', 'worst', 'worst-with-external-latency')


def response_cases(starts: np.ndarray, matched: np.ndarray, ends: np.ndarray) -> dict[str, Case]:
    """caret_analyze's ResponseMapAll over path records: one per (input, output) pair, and one without an end
    per input no output reflects. `starts` holds every input's start time (receive time or stamp), `matched`
    the input index of each output at time `ends`."""
    outputs: dict[int, list[int | None]] = {}
    for index, end in zip(matched.tolist(), ends.tolist(), strict=True):
        outputs.setdefault(index, []).append(end)
    records = sorted(((start, end) for index, start in enumerate(starts.tolist())
                      for end in outputs.get(index, [None])), key=lambda r: (r[0], r[1] is None, r[1] or 0))
    cases = _cases(_responses(records))
    return {name: (np.array([s for s, _ in rows], dtype=np.int64), np.array([r for _, r in rows]) / MS)
            for name, rows in cases.items()}


def _responses(records: list[tuple[int, int | None]]) -> list[tuple[int, int]]:
    """(start, end) pairs, one end per start (the least), in a reversed walk where a record without an end takes
    the earliest end after it; the earliest output is left out (it may miss inputs)."""
    by_start: dict[int, int] = {}
    least: int | None = None
    for start, maybe_end in reversed(records):
        end = least if maybe_end is None else maybe_end
        if end is None or start > end:
            continue  # nothing after it yet, or reversed timestamps: caret ignores the record
        if start not in by_start or end < by_start[start]:
            by_start[start] = end
        least = end if least is None else min(least, end)
    return sorted((s, e) for s, e in by_start.items() if e != least)


def _cases(pairs: list[tuple[int, int]]) -> dict[str, list[tuple[int, int]]]:
    """(start, latency ns) rows of each response case: every pair; per output, its latest input (best) and its
    earliest (worst); and the input before the earliest (worst with external latency)."""
    best: dict[int, int] = {}
    worst: dict[int, int] = {}
    external: dict[int, tuple[int, int]] = {}
    for (previous, _), (start, end) in itertools.pairwise(pairs):
        if end not in external or start < external[end][0]:
            external[end] = (start, previous)
    for start, end in pairs:
        best[end] = max(best.get(end, start), start)
        worst[end] = min(worst.get(end, start), start)
    return {'all': [(s, e - s) for s, e in pairs],
            'best': sorted((s, e - s) for e, s in best.items()),
            'worst': sorted((s, e - s) for e, s in worst.items()),
            'worst-with-external-latency': sorted((p, e - p) for e, (_, p) in external.items())}


def measured_hops(architecture: Architecture, path: NamedPath, notes: list[str],
                  ) -> tuple[list[str], list[tuple[str, str, str, MessageContext | None]]]:
    """The topics and hops measured: up to the input of the first node without a message context."""
    topics, hops = path.topics, architecture.hops(path)
    for number, (node, in_topic, out_topic, context) in enumerate(hops):
        if context is None:
            notes.append(f'node {node} has no message context for {in_topic} -> {out_topic} (and no callback '
                         f'chain); measurement ends at its input {in_topic}, as caret_analyze does')
            return topics[:number + 1], hops[:number]
    return topics, hops


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
    notes: list[str] = []
    topics, hops = measured_hops(architecture, path, notes)
    for topic in topics:
        if topic not in series or series[topic].times.size == 0:
            notes.append(f'topic {topic} has no messages')
    last = series.get(topics[-1], TopicSeries.empty())
    index = np.arange(last.times.size)
    valid = np.full(last.times.size, len(topics) > 1)  # a path cut at its first topic measures nothing
    for hop in reversed(hops):
        found = _hop_inputs(hop, series, np.clip(index, 0, None), notes)
        valid &= found >= 0
        index = np.where(valid, found, -1)
    first = series.get(topics[0], TopicSeries.empty())
    matched = index[valid]
    sample_times = last.times[valid]
    starts = first.times
    if stamp_origin:
        if first.stamps is None:
            raise LatencyError(f'stamp origin needs header stamps on {topics[0]}')
        starts = first.stamps
    latency = (sample_times - starts[matched]) / MS
    dropped = int(first.times.size - np.unique(matched).size)
    return PathResult(path.name, topics, sample_times, first.times[matched], latency, dropped,
                      int(first.times.size), response_cases(starts, matched, sample_times), notes)


def _hop_inputs(hop: tuple[str, str, str, MessageContext | None], series: dict[str, TopicSeries],
                outputs: np.ndarray, notes: list[str]) -> np.ndarray:
    """For each of the hop's output messages (indexes into its output topic), the index of the input message it
    reflects (-1 for none): the same header stamp for inherit_unique_stamp, else the latest before it."""
    node, in_topic, out_topic, context = hop
    source = series.get(in_topic, TopicSeries.empty())
    target = series.get(out_topic, TopicSeries.empty())
    kind = context.context_type if context else ''
    if kind == 'tilde':
        notes.append(f'node {node}: context tilde cannot be followed on bag data; using the latest message')
    if kind not in STAMP_CONTEXTS:
        return _latest_before(source.times, target.times[outputs])
    if source.stamps is None or target.stamps is None:
        raise LatencyError(f'node {node}: inherit_unique_stamp needs header stamps on {in_topic} and {out_topic}')
    return _latest_same_stamp(source.times, source.stamps, target.times[outputs], target.stamps[outputs])


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
