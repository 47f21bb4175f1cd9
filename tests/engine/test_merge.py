"""Time-ordered merge: order, ties, bounded buffer."""

from __future__ import annotations

from bagfault.engine.merge import TimeOrderedMerge


def rec(time, order, rank=0, counter=0):
    return (time, order, rank, counter, f'{time}/{order}')


def test_releases_up_to_horizon_and_holds_the_rest():
    merge = TimeOrderedMerge()
    out = list(merge.release([rec(1, 0), rec(5, 1, 1, 1), rec(2, 2)], horizon=2, is_sorted=False))
    assert [r[:2] for r in out] == [(1, 0), (2, 2)]
    assert len(merge) == 1
    out = list(merge.release([rec(3, 3), rec(6, 4)], horizon=6, is_sorted=True))
    assert [r[:2] for r in out] == [(3, 3), (5, 1), (6, 4)]
    assert len(merge) == 0


def test_ties_keep_input_order_and_events_first():
    merge = TimeOrderedMerge()
    out = list(merge.release([rec(5, 3, 1, 0), rec(5, 3, 0, 1), rec(5, 3, -1, 2), rec(5, 2, 1, 3)], 5, is_sorted=False))
    assert [(r[1], r[2]) for r in out] == [(2, 1), (3, -1), (3, 0), (3, 1)]


def test_drain_returns_everything_in_order():
    merge = TimeOrderedMerge()
    list(merge.release([rec(9, 0), rec(7, 1)], horizon=0, is_sorted=False))
    assert [r[0] for r in merge.drain()] == [7, 9]
