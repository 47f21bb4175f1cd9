"""The pytest plugin, run by pytest's own pytester in a separate pytest process: scenario files as tests (one per
assertion, at its line), the `bagfault` fixture, and the JUnit XML CI reads."""

from __future__ import annotations

import os
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
import xmlschema
from support.loop import EXAMPLE, rclpy_available

import bagfault.demo.synthetic  # noqa: F401 - numpy loaded before pytester snapshots sys.modules (it cannot load twice)

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from support.helpers import FIXTURES, make_bag

GOOD = """
name: good
bags: [imu.mcap]
injector: {id: imu, type: imu, input_topic: /imu, output_topic: /imu_out}
faults:
  - {id: bias, injector_id: imu, start: 1.0, duration: 1.0, config: {angular_velocity_z_bias: 0.2}}
assertions:
  - {id: bias_activates, type: fault_event, fault_id: bias, state: active, within: 1.5}
  - {id: yaw_rate_bounded, type: field_range, topic: /imu_out, field: angular_velocity.z, min: 0.0, max: 0.5}
"""
BAD = GOOD.replace('name: good', 'name: bad').replace('max: 0.5}', 'max: 0.15}').replace('yaw_rate_bounded',
                                                                                          'yaw_rate_tight')
FIXTURE_TESTS = """
import pytest
import xmlschema

def test_run_returns_the_result(bagfault):
    result = bagfault.run('test_good.bagfault.yaml')
    assert result.output.exists() and not result.failed

def test_a_failed_assertion_fails_the_test(bagfault):
    bagfault.run('test_bad.bagfault.yaml')

def test_check_false_hands_the_failure_back(bagfault):
    result = bagfault.run('test_bad.bagfault.yaml', check=False)
    assert [a.id for a in result.assertions if a.state == 'failed'] == ['yaw_rate_tight']
"""


def line_of(text: str, needle: str) -> int:
    """1-based line of the first line holding `needle`."""
    return next(n for n, line in enumerate(text.splitlines(), 1) if needle in line)


@pytest.fixture
def project(pytester: pytest.Pytester) -> pytest.Pytester:
    make_bag(pytester.path / 'imu.mcap', [('/imu', 'sensor_msgs/msg/Imu', 50.0)], 4.0)
    pytester.makefile('.bagfault.yaml', test_good=GOOD, test_bad=BAD)
    pytester.makepyfile(test_fixture=FIXTURE_TESTS)
    return pytester


def test_scenario_files_and_fixture_tests(project: pytest.Pytester) -> None:
    result = project.runpytest_subprocess('--junitxml=report.xml', '-p', 'no:cacheprovider')
    result.assert_outcomes(passed=5, failed=2)
    result.stdout.fnmatch_lines([
        'yaw_rate_tight failed: at 1.000 s /imu_out angular_velocity.z = 0.3 is outside [[]0, 0.15]',
        'FAILED test_bad.bagfault.yaml::yaw_rate_tight - *',
    ])
    assert 'Traceback' not in result.stdout.str()
    cases = {c.get('name'): c for c in ET.parse(project.path / 'report.xml').getroot().iter('testcase')}
    assert set(cases) == {'bias_activates', 'yaw_rate_bounded', 'yaw_rate_tight', 'test_run_returns_the_result',
                          'test_a_failed_assertion_fails_the_test', 'test_check_false_hands_the_failure_back'}
    tight = cases['yaw_rate_tight']
    assert tight.get('classname') == 'test_bad.bagfault.yaml'
    [failure] = tight.findall('failure')
    assert 'angular_velocity.z' in (failure.get('message') or '')
    written = (project.path / 'test_bad.bagfault.yaml').read_text()
    assert f'test_bad.bagfault.yaml:{line_of(written, "id: yaw_rate_tight")}: yaw_rate_tight failed' in failure.text
    assert cases['test_a_failed_assertion_fails_the_test'].find('failure') is not None
    for schema in ('junit.xsd', 'junit-10.xsd'):  # the common schema and Jenkins' (no properties in a testcase)
        xmlschema.XMLSchema(str(FIXTURES / schema)).validate(str(project.path / 'report.xml'))


def test_junit_xunit1_carries_file_and_line_attributes(project: pytest.Pytester) -> None:
    result = project.runpytest_subprocess('--junitxml=report.xml', '-o', 'junit_family=xunit1',
                                          'test_good.bagfault.yaml', '-p', 'no:cacheprovider')
    result.assert_outcomes(passed=2)
    cases = {c.get('name'): c for c in ET.parse(project.path / 'report.xml').getroot().iter('testcase')}
    activates = cases['bias_activates']
    assert activates.get('file') == 'test_good.bagfault.yaml'
    written = (project.path / 'test_good.bagfault.yaml').read_text()
    assert int(activates.get('line') or -1) == line_of(written, 'id: bias_activates') - 1  # pytest counts from 0


def test_a_scenario_that_cannot_run_is_an_error_of_each_item_with_the_reason(pytester: pytest.Pytester) -> None:
    """Broken setup is a pytest error, a failed assertion a failure, so CI tells the two apart."""
    pytester.makefile('.bagfault.yaml', test_nobag=GOOD.replace('imu.mcap', 'missing.mcap'),
                      test_broken='injector: {id: imu, type: imu\n')
    result = pytester.runpytest_subprocess('-p', 'no:cacheprovider', '--junitxml=report.xml')
    result.assert_outcomes(errors=3)
    result.stdout.fnmatch_lines(['*test_nobag.bagfault.yaml: could not run: *missing.mcap*'])
    result.stdout.fnmatch_lines(['*test_broken.bagfault.yaml: could not run: *'])
    assert 'Traceback' not in result.stdout.str()
    cases = list(ET.parse(pytester.path / 'report.xml').getroot().iter('testcase'))
    assert len(cases) == 3 and all(c.find('error') is not None and c.find('failure') is None for c in cases)


def test_markers_select_scenarios_and_pass_strict_markers(project: pytest.Pytester) -> None:
    offline = project.runpytest_subprocess('-p', 'no:cacheprovider', '--strict-markers', '-m', 'offline')
    offline.assert_outcomes(passed=3, failed=1, deselected=3)  # the four assertions of the two scenario files
    both = project.runpytest_subprocess('-p', 'no:cacheprovider', '--strict-markers', '-m', 'bagfault and not offline')
    both.assert_outcomes(deselected=7)
    loops = project.runpytest_subprocess('-p', 'no:cacheprovider', '--strict-markers', '-m', 'closed_loop')
    loops.assert_outcomes(deselected=7)
    listed = project.runpytest_subprocess('-p', 'no:cacheprovider', '--markers')
    listed.stdout.fnmatch_lines(['@pytest.mark.closed_loop: *', '@pytest.mark.offline: *'])


MANY = GOOD.replace('name: good', 'name: many') + ''.join(
    f'  - {{id: bounded_{n}, type: field_range, topic: /imu_out, field: angular_velocity.z, min: 0.0, max: 0.5}}\n'
    for n in range(6))


def test_under_xdist_a_scenario_file_runs_on_one_worker_and_its_time_is_its_first_setup(
        project: pytest.Pytester) -> None:
    pytest.importorskip('xdist')
    project.makefile('.bagfault.yaml', test_many=MANY)
    project.makepyfile(test_plain='\n'.join(f'def test_plain_{n}():\n    pass\n' for n in range(8)))
    result = project.runpytest_subprocess('-p', 'no:cacheprovider', '-n', '2', '-v', 'test_many.bagfault.yaml',
                                          'test_plain.py')
    result.assert_outcomes(passed=16)
    workers: dict[str, set[str]] = {}
    for line in result.outlines:
        if line.startswith('[gw') and 'PASSED' in line:
            worker, item = line.split()[0], line.split()[-1]
            workers.setdefault(item.split('::')[0], set()).add(worker)
    assert workers['test_many.bagfault.yaml'] in ({'[gw0]'}, {'[gw1]'})  # the file's 8 items, one worker
    # without xdist: the scenario's run is the setup of the file's first item, the slowest phase of the session
    timed = project.runpytest_subprocess('-p', 'no:cacheprovider', '--durations=1', 'test_many.bagfault.yaml',
                                         'test_plain.py')
    timed.stdout.re_match_lines([r'.*s setup\s+test_many\.bagfault\.yaml::bias_activates$'])


@pytest.mark.live
@pytest.mark.closed_loop
@pytest.mark.skipif(not rclpy_available(), reason="rclpy not installed (pip install '.[live]')")
def test_closed_loop_scenario_file_and_fixture(pytester: pytest.Pytester) -> None:
    sys.path.insert(0, str(EXAMPLE))
    try:
        import make_bag as example
    finally:
        sys.path.remove(str(EXAMPLE))
    bag = example.write(pytester.path / 'rover.mcap')
    text = (EXAMPLE / 'test_imu_drift.bagfault.yaml').read_text().replace('cwd: .', f'cwd: {EXAMPLE}')
    pytester.makefile('.bagfault.yaml', test_loop=text)
    pytester.makepyfile(test_loop_fixture=f"""
        def test_detection_disabled(bagfault):
            result = bagfault.test('test_loop.bagfault.yaml', [{str(bag)!r}], rate=2.0, check=False,
                                   system={{'command': '{{python}} monitor.py --no-detection'}})
            assert [a.id for a in result.assertions if a.state == 'failed'] == ['drift_detected']
            assert result.system.heard['/diagnostics'] > 20
    """)
    result = pytester.runpytest_subprocess('-p', 'no:cacheprovider', '-v')
    result.assert_outcomes(passed=5)
    result.stdout.fnmatch_lines(['*test_loop.bagfault.yaml::system_alive PASSED*',
                                 '*test_loop.bagfault.yaml::drift_detected PASSED*'])


ROVER_PACKAGE_XML = """<?xml version="1.0"?>
<package format="3">
  <name>rover_checks</name>
  <version>0.0.1</version>
  <description>A team's scenario folder</description>
  <maintainer email="team@example.com">team</maintainer>
  <license>Apache-2.0</license>
  <test_depend>bagfault</test_depend>
  <export><build_type>ament_python</build_type></export>
</package>
"""
ROVER_SETUP_PY = """from setuptools import setup
setup(name='rover_checks', version='0.0.1', packages=[], extras_require={'test': ['pytest']},
      data_files=[('share/ament_index/resource_index/packages', ['resource/rover_checks']),
                  ('share/rover_checks', ['package.xml'])])
"""


def test_bagfault_builds_in_a_colcon_workspace_and_a_packages_scenarios_run_under_colcon_test(
        tmp_path: Path) -> None:
    import shutil
    import subprocess

    colcon = Path(sys.executable).with_name('colcon')
    if not colcon.exists():
        pytest.skip("colcon not installed (pip install '.[test]')")
    root = Path(__file__).resolve().parents[2]
    src = tmp_path / 'ws' / 'src'
    shutil.copytree(root / 'bagfault', src / 'bagfault' / 'bagfault', ignore=shutil.ignore_patterns('__pycache__'))
    for name in ('pyproject.toml', 'setup.py', 'package.xml', 'README.md', 'LICENSE'):
        shutil.copy(root / name, src / 'bagfault' / name)
    shutil.copytree(root / 'resource', src / 'bagfault' / 'resource')
    rover = src / 'rover_checks'
    (rover / 'resource').mkdir(parents=True)
    (rover / 'resource' / 'rover_checks').touch()
    (rover / 'package.xml').write_text(ROVER_PACKAGE_XML)
    (rover / 'setup.py').write_text(ROVER_SETUP_PY)
    (rover / 'test').mkdir()
    make_bag(rover / 'test' / 'imu.mcap', [('/imu', 'sensor_msgs/msg/Imu', 50.0)], 4.0)
    (rover / 'test' / 'test_good.bagfault.yaml').write_text(GOOD)
    (rover / 'test' / 'test_bad.bagfault.yaml').write_text(BAD)
    workspace = tmp_path / 'ws'
    env = {k: v for k, v in os.environ.items() if not k.startswith(('PYTEST', 'COLCON'))}
    built = subprocess.run([str(colcon), 'build'], cwd=workspace, env=env, capture_output=True, text=True,
                           timeout=300, check=False)
    assert built.returncode == 0, built.stdout + built.stderr
    assert (workspace / 'install' / 'bagfault' / 'share' / 'bagfault' / 'package.xml').exists()
    assert list((workspace / 'install' / 'bagfault' / 'lib').glob('python3*/site-packages/bagfault/cli.py'))
    tested = subprocess.run([str(colcon), 'test', '--packages-select', 'rover_checks'], cwd=workspace, env=env,
                            capture_output=True, text=True, timeout=300, check=False)
    assert tested.returncode == 0, tested.stdout + tested.stderr  # colcon test runs; test-result judges
    results = subprocess.run([str(colcon), 'test-result', '--all'], cwd=workspace, env=env, capture_output=True,
                             text=True, timeout=120, check=False)
    # GOOD and BAD have two assertions each; BAD's yaw_rate_tight fails (0.2 rad/s against max 0.15)
    assert results.returncode == 1, results.stdout + results.stderr
    assert 'Summary: 4 tests, 0 errors, 1 failure, 0 skipped' in results.stdout, results.stdout
    junit = ET.parse(workspace / 'build' / 'rover_checks' / 'pytest.xml').getroot()
    failed = [c.get('name') for c in junit.iter('testcase') if c.find('failure') is not None]
    assert failed == ['yaw_rate_tight']
