"""`--repeat`: runs folded into pass rates and decision-time spreads (the numbers worked out by hand)."""

from __future__ import annotations

from bagfault.assertions.base import AssertionResult
from bagfault.closedloop.repeat import fold
from bagfault.engine.result import RunResult, RunStats
from bagfault.report.model import build
from bagfault.scenario import parse_scenario

NS = 1_000_000_000
SCENARIO = parse_scenario('injector: {id: imu, type: imu, input_topic: /a, output_topic: /b}\n')


def run(origin: int, *verdicts: tuple[str, str, float | None, str]) -> RunResult:
    stats = RunStats(origin=origin, first_time=origin)
    assertions = [AssertionResult(i, 'fault_status', s, None if t is None else origin + round(t * NS), m)  # type: ignore[arg-type]
                  for i, s, t, m in verdicts]
    return RunResult(SCENARIO, [], None, 0, stats, assertions=assertions, mode='test')


def test_pass_rates_and_spread() -> None:
    runs = [
        run(100 * NS, ('detected', 'passed', 3.4, 'ok'), ('alive', 'passed', 13.0, 'ok')),
        run(500 * NS, ('detected', 'passed', 3.6, 'ok'), ('alive', 'passed', 13.0, 'ok')),
        run(900 * NS, ('detected', 'failed', 5.0, 'IMU_DRIFT did not reach CONFIRMED'), ('alive', 'passed', 13.0, 'ok')),
    ]
    folded = fold(runs)
    detected, alive = folded.assertions
    assert detected.state == 'failed'
    assert folded.failed
    # times 3.4, 3.6, 5.0: median 3.6; mean 4.0, stdev sqrt((0.36 + 0.16 + 1.0) / 2) = 0.872
    assert detected.message == ('passed 2 of 3 runs (67%); decided at 3.400 to 5.000 s (median 3.600 s, '
                                'stdev 0.872 s); run 3: IMU_DRIFT did not reach CONFIRMED')
    assert alive.state == 'passed'
    assert alive.message.startswith('passed 3 of 3 runs (100%); decided at 13.000 to 13.000 s')
    assert folded.pass_rates() == {'detected': 2 / 3, 'alive': 1.0}
    report = build(folded)['repeats']
    assert report['runs'] == 3
    assert report['assertions']['detected'] == {'pass_rate': 2 / 3, 'states': ['passed', 'passed', 'failed'],
                                                't_s': [3.4, 3.6, 5.0]}


def test_all_passed_is_a_pass() -> None:
    folded = fold([run(0, ('a', 'passed', 1.0, 'ok')), run(NS, ('a', 'passed', 2.0, 'ok'))])
    assert not folded.failed
    assert folded.assertions[0].state == 'passed'
    assert run(0, ('a', 'failed', 1.0, 'no')).pass_rates() == {'a': 0.0}
