"""Which node runs which job on a Ray cluster (campaign.placement), simulated with jobs of equal length: the
downloads (a node's first job of a bag) and the campaign's length in job-lengths are worked out by hand."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from bagfault.campaign.placement import Placement


def simulate(bags: list[str], slots: dict[str, int], limit: int | None = None) -> tuple[list[tuple[int, str]], int]:
    """Every job handed out as CPUs free up, each taking one time step: (job, node) in order, and the steps."""
    placement = Placement.of(bags, slots)
    handed: list[tuple[int, str]] = []
    step = 0
    while placement.pending:
        started = placement.assign(limit)
        assert started or any(placement.busy.values()), 'nothing runs and jobs wait'
        handed += started
        step += 1
        for _, node in started:  # every job of this step ends with it
            placement.finished(node)
    return handed, step


def downloads(handed: list[tuple[int, str]], bags: list[str]) -> int:
    return len({(node, bags[i]) for i, node in handed})


def test_four_bags_of_twelve_jobs_on_three_nodes() -> None:
    """The bench's campaign: A, B and C take b0, b1, b2 (3 downloads, 12 rounds); then A takes b3 (no node holds
    it) and B and C take b3 too (11 and 10 of its jobs wait on one and two nodes: more than 2 rounds), 3 more
    downloads; its 12 jobs take 4 rounds. Ray's own spread would download every bag on every node (12)."""
    bags = [f'b{k}' for k in range(4) for _ in range(12)]
    handed, steps = simulate(bags, {'A': 1, 'B': 1, 'C': 1})
    assert sorted(i for i, _ in handed) == list(range(48))
    assert downloads(handed, bags) == 6  # hit rate 42/48
    assert steps == 16  # 48 jobs / 3 nodes: nothing lost to locality
    assert {bags[i] for i, node in handed[:3]} == {'b0', 'b1', 'b2'}


def test_a_bag_nearly_done_is_not_fetched_again() -> None:
    """Two bags of 4 and 6 jobs, two nodes: B's bag has 2 jobs left when A is done (2 rounds, not more): A waits
    rather than download it. 2 downloads, 6 steps."""
    bags = ['a'] * 4 + ['b'] * 6
    handed, steps = simulate(bags, {'A': 1, 'B': 1})
    assert downloads(handed, bags) == 2
    assert steps == 6
    assert [bags[i] for i, node in handed if node == 'A'] == ['a'] * 4


def test_a_node_with_two_cpus_runs_its_own_bag_twice_over() -> None:
    bags = ['a'] * 4 + ['b'] * 4
    handed, steps = simulate(bags, {'A': 2, 'B': 2})
    assert downloads(handed, bags) == 2
    assert steps == 2
    assert {(bags[i], node) for i, node in handed} == {('a', 'A'), ('b', 'B')}


def test_the_limit_caps_the_jobs_running() -> None:
    bags = ['a'] * 3 + ['b'] * 3
    placement = Placement.of(bags, {'A': 2, 'B': 2})
    assert len(placement.assign(limit=3)) == 3
    assert placement.assign(limit=3) == []


def test_a_lost_node_s_bag_goes_to_another_node() -> None:
    bags = ['a'] * 5 + ['b'] * 5
    placement = Placement.of(bags, {'A': 1, 'B': 1})
    assert placement.assign() == [(0, 'A'), (5, 'B')]
    placement.nodes({'B': 1})  # A gone with its running job (Ray runs that one again elsewhere)
    placement.finished('A')
    placement.finished('B')
    assert placement.assign() == [(6, 'B')]  # its own bag first
    for _ in range(4):  # b's 4 jobs, then a's: no node holds a any more
        placement.finished('B')
        (index, node), = placement.assign()
    assert (index, node) == (1, 'B')


@settings(max_examples=200, deadline=None)
@given(st.lists(st.integers(1, 20), min_size=1, max_size=6), st.lists(st.integers(1, 3), min_size=1, max_size=4))
def test_every_job_runs_once_and_no_cpu_idles_long(sizes: list[int], cpus: list[int]) -> None:
    """Any bags and nodes: every job is handed out exactly once, never more at a time than a node's CPUs, each
    bag fetched at most once per node; and the campaign takes at most 2 steps more than an even spread with
    one extra round per node (the rounds a node may wait rather than fetch a bag again)."""
    bags = [f'b{k}' for k, size in enumerate(sizes) for _ in range(size)]
    slots = {f'n{k}': c for k, c in enumerate(cpus)}
    placement = Placement.of(bags, slots)
    handed: list[tuple[int, str]] = []
    steps = 0
    while placement.pending:
        started = placement.assign()
        assert all(placement.busy[n] <= slots[n] for n in slots)
        handed += started
        steps += 1
        for _, node in started:
            placement.finished(node)
    assert sorted(i for i, _ in handed) == list(range(len(bags)))
    assert downloads(handed, bags) <= len(slots) * len(sizes)
    even = -(-len(bags) // sum(cpus))
    assert steps <= even + max(sizes) // min(cpus) + 3  # never worse than one bag's jobs run after the rest
