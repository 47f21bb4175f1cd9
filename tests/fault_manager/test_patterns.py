"""What a user writes as a name or a pattern is matched whole and in linear time: a value with a newline added is
refused wherever the value without it is accepted (a `$` anchor lets one final newline through), and correlation
wildcards match as medkit's regex_match of the pattern with * as .* does, without backtracking."""

from __future__ import annotations

import re
import time

import pytest
from hypothesis import given
from hypothesis import strategies as st

from bagfault.fault_manager.correlation import wildcard
from bagfault.fault_manager.model import valid_code
from bagfault.scenario import ScenarioError, parse_scenario

CODES = st.text(alphabet='ABCxyz019_.-', min_size=1, max_size=40).filter(lambda c: '..' not in c)


@given(CODES)
def test_a_fault_code_with_a_newline_is_refused(code):
    """medkit's validation refuses "ABC\\n"; so does every place bagfault reads a code."""
    assert valid_code(code)
    assert not valid_code(code + '\n') and not valid_code('\n' + code)


@pytest.mark.parametrize('where', ['report', 'assertion'])
def test_a_scenario_naming_a_code_with_a_newline_is_refused(where):
    report = ', report: {code: "ABC\\n"}' if where == 'report' else ''
    text = ('injectors: [{id: imu, type: imu, input_topic: /imu, output_topic: /imu}]\n'
            f'faults: [{{id: f, injector_id: imu, start: 1.0{report}}}]\n'
            'fault_manager: {}\n')
    if where == 'assertion':
        text += 'assertions: [{id: a, type: fault_status, code: "ABC\\n", status: CONFIRMED}]\n'
    with pytest.raises(ScenarioError) as caught:
        parse_scenario(text)
    assert 'is not a fault code' in str(caught.value)


@given(pattern=st.text(alphabet='AB*', max_size=8), code=st.text(alphabet='AB\n', max_size=10))
def test_wildcards_match_as_medkits_regex_does(pattern, code):
    """The reference: * as .* (which never crosses a newline, as in ECMAScript's regex), the rest literal, the
    whole code."""
    reference = re.fullmatch('.*'.join(re.escape(p) for p in pattern.split('*')), code) is not None
    assert wildcard(pattern).match(code) == reference


def test_a_wildcard_that_would_backtrack_matches_in_linear_time():
    """`A*A*...*B` against 5000 A's makes a backtracking regex take exponential time; here it is one scan."""
    pattern, code = '*'.join(['A'] * 30) + '*B', 'A' * 5000
    began = time.perf_counter()
    assert not wildcard(pattern).match(code) and wildcard(pattern).match(code + 'B')
    assert time.perf_counter() - began < 0.5
