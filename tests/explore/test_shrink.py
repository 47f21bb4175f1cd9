"""The shrinker on systems given as formulas: each planted threshold is known by construction, so the minimal cause
it must reach is too. Driven as the explorer drives it (candidates out, outcomes in), without runs."""

from __future__ import annotations

import math

from hypothesis import given, settings
from hypothesis import strategies as st

from bagfault.explore.candidate import Candidate, Drawn
from bagfault.explore.records import Failure, Outcome
from bagfault.explore.shrink import Shrinker
from bagfault.scenario import parse_scenario

SPACE = """
injectors:
  - {id: imu, type: imu, input_topic: /imu, output_topic: /imu}
  - {id: odom, type: odom, input_topic: /odom, output_topic: /odom}
assertions:
  - {id: a, type: topic_gap, topic: /imu, max_gap: 1.0}
  - {id: b, type: topic_gap, topic: /odom, max_gap: 1.0}
explore:
  faults:
    - {id: bias, injector_id: imu, start: [0, 10], duration: [0.1, 4.0],
       config: {angular_velocity_z_bias: [0.0, 1.0], linear_acceleration_x_bias: [0.0, 3.0]}}
    - {id: drop, injector_id: odom, start: [0, 10], duration: [0.1, 4.0], config: {drop_probability: 1.0}}
    - {id: delay, injector_id: odom, start: [0, 10], duration: [0.1, 4.0], config: {delay_ms: [0, 500]}}
  confirm: 2
"""


def space(text: str = SPACE):
    explore = parse_scenario(text).explore
    assert explore is not None
    return explore


def candidate(**faults: dict[str, float]) -> Candidate:
    order = ('bias', 'drop', 'delay')
    return Candidate(tuple(Drawn(f, tuple(faults[f].items())) for f in order if f in faults))


def full_bias(**values: float) -> dict[str, float]:
    return {'start': 1.0, 'duration': 3.0, 'config.angular_velocity_z_bias': 0.9,
            'config.linear_acceleration_x_bias': 2.5, **values}


def window(values: dict[str, float]) -> tuple[float, float]:
    return values['start'], values['start'] + values['duration']


def drive(shrinker: Shrinker, system, flaky=lambda n: False) -> list[Candidate]:
    """Run the shrink against `system(candidate) -> (failing set, margins)`; the candidates it asked for."""
    asked = []
    steps = shrinker.steps()
    try:
        candidate = next(steps)
        while True:
            asked.append(candidate)
            failing, margins = system(candidate)
            if flaky(len(asked)):
                failing = frozenset()
            outcome = Outcome('failed' if failing else 'passed', frozenset(failing), margins)
            candidate = steps.send((len(asked), outcome))
    except StopIteration:
        return asked


def shrink(found: Candidate, system, *, confirm: int = 1, text: str = SPACE, flaky=lambda n: False, mode='full'):
    explore = space(text)
    failing, margins = system(found)
    failure = Failure(1, frozenset(failing), 0, 1, found)
    shrinker = Shrinker(explore, failure, Outcome('failed', frozenset(failing), margins), confirm=confirm, mode=mode)
    asked = drive(shrinker, system, flaky)
    return failure, asked


def strength_and_duration(c: Candidate):
    """Fails `a` when the bias is above 0.4 for longer than 1.5 s; its margin is 0.4 - bias (linear)."""
    if 'bias' not in c.ids:
        return frozenset(), {'a': (0.4, '')}
    v = dict(c.drawn('bias').values)
    margin = 0.4 - v['config.angular_velocity_z_bias']
    fails = margin < 0 and v['duration'] > 1.5
    return (frozenset({'a'}) if fails else frozenset()), {'a': (margin if fails or margin > 0 else 0.01, '')}


def test_strength_and_duration_shrink_to_their_thresholds_and_the_decoy_to_its_weakest():
    found = candidate(bias=full_bias(), drop={'start': 4.0, 'duration': 2.0},
                      delay={'start': 2.0, 'duration': 1.0, 'config.delay_ms': 300.0})
    failure, asked = shrink(found, strength_and_duration)
    assert failure.state == 'shrunk' and failure.minimal is not None
    assert failure.minimal.ids == ('bias',)  # ddmin drops the faults that do not matter
    values = dict(failure.minimal.drawn('bias').values)
    assert 0.4 < values['config.angular_velocity_z_bias'] <= 0.4 + 0.01  # within the resolution, 1 % of 1.0
    assert values['config.linear_acceleration_x_bias'] == 0.0  # the decoy: its weakest value, in one run
    assert 1.5 < values['duration'] <= 1.5 + 0.039  # 1 % of 3.9 s
    assert values['start'] == 10.0  # as late as the failure allows: the end of its range
    # the margin (linear in the bias) settles the bias in a few runs, not the seven halvings of 1.0 to 1 %
    bias_runs = [s for s in failure.steps if 'angular_velocity_z_bias' in s.change]
    assert len(bias_runs) <= 4 + 1  # + the second pass's one step below, which passes
    assert len(asked) == failure.shrink_runs <= 22


def test_without_margins_each_strength_is_halved_and_ddmin_alone_keeps_the_values():
    """The benchmark's comparisons: `halving` reaches the same thresholds, the bias by seven halvings of 0.9 to
    1 % (plus its end) instead of the margin's two or three; `faults` drops the faults that do not matter and
    leaves every value as found."""
    found = candidate(bias=full_bias(), drop={'start': 4.0, 'duration': 2.0})
    halved, _ = shrink(found, strength_and_duration, mode='halving')
    values = dict(halved.minimal.drawn('bias').values)
    assert 0.4 < values['config.angular_velocity_z_bias'] <= 0.41
    # the end, 0.9 / 2**7 < 0.01, then the second pass's step below
    assert len([s for s in halved.steps if 'angular_velocity_z_bias' in s.change]) == 1 + 7 + 1
    ddmin, _ = shrink(found, strength_and_duration, mode='faults')
    assert ddmin.minimal == found.without('drop')


def overlap(c: Candidate):
    """Fails `b` when the drop and the delay overlap by more than 0.5 s with a delay above 200 ms: two faults at once.
    No margin (a crash-like verdict): every step halves."""
    if not {'drop', 'delay'} <= set(c.ids):
        return frozenset(), {'b': (None, '')}
    drop, delay = dict(c.drawn('drop').values), dict(c.drawn('delay').values)
    (s1, e1), (s2, e2) = window(drop), window(delay)
    fails = min(e1, e2) - max(s1, s2) > 0.5 and delay['config.delay_ms'] > 200
    return (frozenset({'b'}) if fails else frozenset()), {'b': (None, '')}


def test_two_faults_that_only_fail_together_are_both_kept():
    found = candidate(bias=full_bias(), drop={'start': 3.0, 'duration': 2.0},
                      delay={'start': 3.5, 'duration': 2.0, 'config.delay_ms': 450.0})
    failure, _ = shrink(found, overlap)
    assert failure.minimal is not None and failure.minimal.ids == ('drop', 'delay')
    drop, delay = dict(failure.minimal.drawn('drop').values), dict(failure.minimal.drawn('delay').values)
    assert 200 < delay['config.delay_ms'] <= 205  # 1 % of 500 ms, whole milliseconds
    shared = min(window(drop)[1], window(delay)[1]) - max(window(drop)[0], window(delay)[0])
    assert 0.5 < shared <= 0.5 + 2 * 0.039  # each duration and start moved until the overlap is just enough
    assert overlap(failure.minimal)[0] == {'b'}  # and it still fails


def test_a_step_is_kept_only_when_it_fails_confirm_runs_in_a_row():
    """With confirm 2 and every fourth run passing (a flaky system), no kept step has a run that passed, and the
    minimal still fails the formula."""
    found = candidate(bias=full_bias())
    failure, asked = shrink(found, strength_and_duration, confirm=2, flaky=lambda n: n % 4 == 0)
    assert failure.state == 'shrunk' and failure.minimal is not None
    assert strength_and_duration(failure.minimal)[0] == {'a'}
    confirmed, *kept = [s for s in failure.steps if s.kept]
    assert confirmed.change == 'confirm the original' and confirmed.runs == 1  # its first run was the search's
    assert kept and all(s.runs == 2 for s in kept)
    assert failure.confirmations == 1 + sum(s.runs - 1 for s in failure.steps[1:])  # every run after a step's first


def test_a_failure_that_does_not_fail_again_is_not_shrunk():
    found = candidate(bias=full_bias())
    failure, asked = shrink(found, strength_and_duration, confirm=3, flaky=lambda n: n == 2)
    assert failure.state == 'unconfirmed' and failure.minimal is None and len(asked) == 2


@settings(max_examples=60, deadline=None)
@given(threshold=st.floats(0.05, 0.95), shortest=st.floats(0.2, 3.5), latest=st.floats(0.5, 9.5),
       start=st.floats(0.0, 0.4), linear=st.booleans())
def test_any_planted_threshold_is_reached_within_the_resolution(threshold, shortest, latest, start, linear):
    """A system failing when bias > threshold, duration > shortest and start < latest: every threshold found within
    1 % of its range, whatever they are, with a margin or without."""
    def system(c: Candidate):
        v = dict(c.drawn('bias').values) if 'bias' in c.ids else None
        if v is None:
            return frozenset(), {'a': (1.0, '')}
        margin = threshold - v['config.angular_velocity_z_bias']
        fails = margin < 0 and v['duration'] > shortest and v['start'] < latest
        return (frozenset({'a'}) if fails else frozenset()), {'a': (margin if linear else None, '')}

    found = candidate(bias=full_bias(**{'config.angular_velocity_z_bias': 1.0, 'duration': 4.0, 'start': start}))
    failure, _ = shrink(found, system)
    assert failure.minimal is not None
    v = dict(failure.minimal.drawn('bias').values)
    assert threshold < v['config.angular_velocity_z_bias'] <= threshold + 0.01 + 1e-9
    assert shortest < v['duration'] <= shortest + 0.039 + 1e-9
    assert latest - 0.1 - 1e-9 <= v['start'] < latest
    assert math.isclose(v['config.linear_acceleration_x_bias'], 0.0)


def test_a_margin_that_jumps_costs_one_guess_then_halving():
    """A latched bug: the margin follows the bias slowly while it passes (8.8 - bias) and jumps to -90 once it
    fails (bias > 0.3). The first guess along the line misses; from then on the bracket is halved: the end, one
    guess and the halvings of 0.9 to 1 % (7), and the second pass's step, no more."""
    def latched(c: Candidate):
        bias = dict(c.drawn('bias').values)['config.angular_velocity_z_bias'] if 'bias' in c.ids else 0.0
        fails = bias > 0.3
        return (frozenset({'a'}) if fails else frozenset()), {'a': (-90.0 if fails else 8.8 - bias, '')}

    failure, _ = shrink(candidate(bias=full_bias()), latched)
    v = dict(failure.minimal.drawn('bias').values)
    assert 0.3 < v['config.angular_velocity_z_bias'] <= 0.31
    assert len([s for s in failure.steps if 'angular_velocity_z_bias' in s.change]) <= 1 + 1 + 7 + 1


def test_a_later_pass_shortens_a_window_its_moved_start_allows():
    """A phase bug: the bias fails only while the window overlaps [6, 8) s. From a start of 2 s the first pass
    keeps the window just long enough to reach 6 s, then moves the start as late as 8 s allows; the second pass
    finds that from there the shortest window (0.1 s) fails too."""
    def phase(c: Candidate):
        if 'bias' not in c.ids:
            return frozenset(), {'a': (1.0, '')}
        v = dict(c.drawn('bias').values)
        fails = v['config.angular_velocity_z_bias'] > 0.2 and v['start'] < 8.0 and v['start'] + v['duration'] > 6.0
        return (frozenset({'a'}) if fails else frozenset()), {'a': (None, '')}

    failure, _ = shrink(candidate(bias=full_bias(start=2.0, duration=4.5)), phase)
    v = dict(failure.minimal.drawn('bias').values)
    assert v['duration'] == 0.1 and 8.0 - 0.1 <= v['start'] < 8.0
    assert 0.2 < v['config.angular_velocity_z_bias'] <= 0.21


def test_a_window_held_at_its_end_shrinks_from_its_start():
    """Fails while the window covers [4.3, 4.5] s and ends before 4.6 s: from [2.0, 4.55) neither end moves alone
    (a shorter window ends before 4.5, a later one after 4.6); shortening it from its start, its end kept, takes
    it to [4.3, 4.55)."""
    def held(c: Candidate):
        if 'bias' not in c.ids:
            return frozenset(), {'a': (1.0, '')}
        v = dict(c.drawn('bias').values)
        end = v['start'] + v['duration']
        fails = v['config.angular_velocity_z_bias'] > 0.1 and v['start'] <= 4.3 and 4.5 <= end < 4.6
        return (frozenset({'a'}) if fails else frozenset()), {'a': (None, '')}

    failure, _ = shrink(candidate(bias=full_bias(start=2.0, duration=2.55)), held)
    v = dict(failure.minimal.drawn('bias').values)
    assert 4.3 - 0.039 <= v['start'] <= 4.3 and 0.2 <= v['duration'] <= 0.25 + 0.039 + 1e-9
    assert held(failure.minimal)[0] == {'a'}
