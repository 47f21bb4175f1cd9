"""Scheduler: exact activation times on bag time, every schedule kind."""

from __future__ import annotations

import textwrap

import pytest

from bagfault.engine.activation import Activation
from bagfault.engine.scheduler import FaultScheduler
from bagfault.scenario import parse_scenario

NS = 1_000_000_000
ORIGIN = 1_700_000_000 * NS


def scenario(faults: str):
    return parse_scenario(textwrap.dedent("""
        injector: {id: imu, type: imu, input_topic: /a, output_topic: /b}
        faults:
    """) + textwrap.indent(textwrap.dedent(faults), '  '))


def timeline(sched: FaultScheduler, until: float) -> list[tuple[float, str, str, str]]:
    events = sched.advance(ORIGIN + round(until * NS))
    return [((e.time - ORIGIN) / NS, e.fault_id, e.state, e.source) for e in events]


def test_startup_scheduled_and_manual_faults():
    s = scenario("""
        - {id: boot, injector_id: imu, active_on_startup: true, duration: 2.0, config: {angular_velocity_z_bias: 1}}
        - {id: win, injector_id: imu, start: 5.0, duration: 10.0, config: {angular_velocity_z_bias: 1}}
        - {id: open, injector_id: imu, start: 7.5, config: {angular_velocity_z_bias: 1}}
        - {id: manual, injector_id: imu, config: {angular_velocity_z_bias: 1}}
    """)
    sched = FaultScheduler(s, ORIGIN, 0)
    assert sched.next_time() == ORIGIN
    assert timeline(sched, 100) == [
        (0.0, 'boot', 'active', 'startup'),
        (2.0, 'boot', 'inactive', 'scheduled'),  # the anchor's stop timer says scheduled (fault_scheduler.cpp)
        (5.0, 'win', 'active', 'scheduled'),
        (7.5, 'open', 'active', 'scheduled'),
        (15.0, 'win', 'inactive', 'scheduled'),
    ]
    assert set(sched.active) == {'open'}


def test_advance_is_inclusive_and_incremental():
    s = scenario('- {id: win, injector_id: imu, start: 5.0, duration: 1.0, config: {}}\n')
    sched = FaultScheduler(s, ORIGIN, 0)
    assert timeline(sched, 4.999999999) == []
    assert timeline(sched, 5.0) == [(5.0, 'win', 'active', 'scheduled')]
    assert sched.active['win'] == ORIGIN + 5 * NS
    assert sched.next_time() == ORIGIN + 6 * NS


def test_cli_activation_windows_replace_the_schedule():
    s = scenario("""
        - {id: manual, injector_id: imu, config: {}}
        - {id: win, injector_id: imu, start: 5.0, duration: 10.0, config: {}}
    """)
    sched = FaultScheduler(s, ORIGIN, 0, [Activation.parse('manual@2.5+1'), Activation.parse('win'),
                                         Activation.parse('manual@10')])
    assert timeline(sched, 100) == [
        (0.0, 'win', 'active', 'cli'),
        (2.5, 'manual', 'active', 'cli'),
        (3.5, 'manual', 'inactive', 'cli'),
        (10.0, 'manual', 'active', 'cli'),
    ]


@pytest.mark.parametrize('text', ['', '@x', 'f@1+y', 'f@-1'])
def test_bad_activation_text(text):
    with pytest.raises(ValueError):
        Activation.parse(text)


def test_repeat_inside_window():
    s = scenario('- {id: r, injector_id: imu, start: 1.0, duration: 5.0, repeat: {period: 2.0, on: 0.5}, config: {}}\n')
    events = timeline(FaultScheduler(s, ORIGIN, 0), 100)
    assert [(t, state) for t, _, state, _ in events] == [
        (1.0, 'active'), (1.5, 'inactive'), (3.0, 'active'), (3.5, 'inactive'), (5.0, 'active'), (5.5, 'inactive'),
    ]


def test_repeat_without_end_keeps_going_lazily():
    s = scenario('- {id: r, injector_id: imu, repeat: {period: 1.0, on: 0.25}, config: {}}\n')
    events = timeline(FaultScheduler(s, ORIGIN, 0), 1000.0)
    assert len(events) == 2001 and events[-1][:3] == (1000.0, 'r', 'active')


def test_random_activations_are_seeded_and_hold():
    s = scenario('- {id: p, injector_id: imu, probability_per_second: 0.5, hold: 0.2, config: {}}\n')
    first = timeline(FaultScheduler(s, ORIGIN, 7), 2000)
    again = timeline(FaultScheduler(s, ORIGIN, 7), 2000)
    other = timeline(FaultScheduler(s, ORIGIN, 8), 2000)
    assert first == again and first != other
    ons = [t for t, _, state, _ in first if state == 'active']
    offs = [t for t, _, state, _ in first if state == 'inactive']
    assert all(off - on == pytest.approx(0.2) for on, off in zip(ons, offs, strict=True))
    # rate of arrivals ~ 0.5/s over the time not held
    assert len(ons) / (2000 - 0.2 * len(ons)) == pytest.approx(0.5, rel=0.1)


def test_after_follows_its_trigger():
    s = scenario("""
        - {id: t, injector_id: imu, start: 2.0, duration: 3.0, config: {}}
        - {id: a, injector_id: imu, after: {fault: t, delay: 0.5}, config: {}}
        - {id: b, injector_id: imu, after: {fault: t, delay: 1.0}, duration: 0.25, config: {}}
    """)
    assert timeline(FaultScheduler(s, ORIGIN, 0), 100) == [
        (2.0, 't', 'active', 'scheduled'),
        (2.5, 'a', 'active', 'scheduled'),
        (3.0, 'b', 'active', 'scheduled'),
        (3.25, 'b', 'inactive', 'scheduled'),
        (5.0, 't', 'inactive', 'scheduled'),
        (5.5, 'a', 'inactive', 'scheduled'),
    ]


def test_event_details_use_the_anchor_format():
    s = scenario('- {id: f, injector_id: imu, start: 1, config: {linear_acceleration_z_bias: 0.20, angular_velocity_z_bias: 1}}\n')
    [event] = FaultScheduler(s, ORIGIN, 0).advance(ORIGIN + 2 * NS)
    assert event.details == 'config={angular_velocity_z_bias=1, linear_acceleration_z_bias=0.20}'
    assert event.injector_id == 'imu'


def test_describe_fault_and_config_update_as_the_anchors_own_tests_say():
    """ros2_fault_injection test/utils/test_fault_description.cpp: DescribeFaultFormatsFault (start 1000 ms,
    duration 500 ms, x_bias 1.0) and DescribeConfigUpdateFormatsUpdate; a fault without start is manual-only."""
    from bagfault.scenario import parse_scenario
    from bagfault.spec.model import describe_config_update

    s = parse_scenario('injector: {id: o, type: odom, input_topic: /a, output_topic: /b}\nfaults:\n'
                       '  - {id: odom_bias, injector_id: o, start: 1.0, duration: 0.5, config: {x_bias: 1.0}}\n'
                       '  - {id: manual, injector_id: o, config: {x_bias: 1.0, drop_probability: 0.5}}\n')
    assert s.fault('odom_bias').describe_fault() == 'scheduled, start=1000ms, duration=500ms, config={x_bias=1.0}'
    assert s.fault('manual').describe_fault() == 'manual-only, config={drop_probability=0.5, x_bias=1.0}'
    assert describe_config_update('x_bias', '2.0') == 'config_update={x_bias=2.0}'


def test_a_switch_from_outside_is_detailed_with_describe_fault_and_the_current_config():
    """fault_service_manager.cpp handle_set_fault_state: details = describe_fault(the injector's current
    config); the scheduler's own events keep describe_config."""
    from bagfault.engine.fault_state import FaultState

    state = FaultState(scenario('- {id: f, injector_id: imu, start: 1, config: {angular_velocity_z_bias: 1}}\n'))
    state.scheduler = FaultScheduler(state.scenario, ORIGIN, 0)
    [scheduled] = state.scheduler.advance(ORIGIN + 2 * NS)
    assert scheduled.details == 'config={angular_velocity_z_bias=1}'
    state.configure('f', 'angular_velocity_z_bias', 2.5)
    event = state.switch('f', False, ORIGIN + 3 * NS, 'manual')
    assert event is not None and event.details == 'scheduled, start=1000ms, config={angular_velocity_z_bias=2.5}'


class _Counted(list):
    """A fault list that counts how many of its elements are looked at."""

    looked = 0

    def __iter__(self):
        for item in super().__iter__():
            _Counted.looked += 1
            yield item

    def __getitem__(self, index):
        _Counted.looked += 1
        return super().__getitem__(index)


@pytest.mark.parametrize('duplicate', [False, True])
def test_asking_which_faults_are_active_costs_the_active_ones_not_all(duplicate):
    """An injector with 3000 fault windows, one at a time active, asked after each of its 6000 changes: the
    answer equals the plain filter's, and the faults looked at stay near 3000 + 6000 (a look at every fault
    per change made a run of 30 000 windows quadratic: 15 of its 24 s). A fault id defined twice is in the
    answer twice, as the plain filter has it."""
    count = 3000
    text = ''.join(f'- {{id: f{i}, injector_id: imu, start: {i * 0.01:.2f}, duration: 0.005, '
                   'config: {angular_velocity_z_bias: 0.1}}\n' for i in range(count))
    if duplicate:
        text += '- {id: f7, injector_id: imu, start: 0.07, duration: 0.005, config: {angular_velocity_z_bias: 0.2}}\n'
    s = scenario(text)
    sched = FaultScheduler(s, seed=0, origin=ORIGIN)
    faults = _Counted(s.faults)
    answers, expected = [], []
    _Counted.looked = 0
    for step in range(2 * count):
        sched.advance(ORIGIN + round(step * 0.005 * NS) + 1)
        answers.append([(a.spec.id, a.spec.config) for a in sched.active_of(faults)])
        expected.append([(f.id, f.config) for f in s.faults if f.id in sched.active])
    assert answers == expected
    assert sum(1 for a in answers if a) >= count - 1  # windows were active: the check means something
    if duplicate:
        assert [len(a) for a in answers if a and a[0][0] == 'f7'] == [2]
    assert _Counted.looked < 4 * count
