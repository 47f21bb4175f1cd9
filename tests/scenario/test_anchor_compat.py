"""The anchor's own scenario files mean what bagfault's own fixture scenarios mean, and run the same.

bagfault's tests run on tests/fixtures/scenarios so they stand without
../shared; these tests tie each fixture to the ros2_fault_injection file it
stands in for.
"""

from __future__ import annotations

import pytest
from support.helpers import FIXTURES, raw_messages, third_party

from bagfault import api
from bagfault.scenario import load_scenario

PAIRS = [('multi_injector_faults.yaml', 'rover_multi.yaml'), ('imu_faults.yaml', 'imu.yaml'),
         ('odom_faults.yaml', 'odom.yaml'), ('scan_faults.yaml', 'scan.yaml'),
         ('trigger_service_faults.yaml', 'trigger.yaml'), ('service_integration_faults.yaml', 'nested_odom.yaml')]


def model(path):
    scenario = load_scenario(path)
    return ([(i.id, i.type, i.input_topic, i.output_topic, i.qos_depth, i.proxy_service, i.target_service)
             for i in scenario.injectors],
            [(f.id, f.injector_id, f.active_on_startup, f.start, f.duration, f.config) for f in scenario.faults],
            [(a.id, a.type, a.within, a.params) for a in scenario.assertions])


@pytest.mark.parametrize(('anchor', 'own'), third_party(PAIRS, arity=2))
def test_fixture_scenario_means_what_the_anchor_file_means(anchors, anchor, own):
    assert model(anchors / anchor) == model(FIXTURES / 'scenarios' / own)


def test_anchor_multi_injector_file_runs_as_the_fixture_does(anchors, tmp_path):
    bag = FIXTURES / 'rover_20s.mcap'
    theirs = api.run(anchors / 'multi_injector_faults.yaml', [bag], tmp_path / 'anchor.mcap', seed=3)
    ours = api.run(FIXTURES / 'scenarios' / 'rover_multi.yaml', [bag], tmp_path / 'own.mcap', seed=3)
    assert raw_messages(tmp_path / 'anchor.mcap') == raw_messages(tmp_path / 'own.mcap')
    assert [(r.id, r.state, r.time) for r in theirs.assertions] == [(r.id, r.state, r.time) for r in ours.assertions]
