"""A Python caller's `StopFlag.set()` ends `api.proxy`, `api.play` and `api.record` within a second."""

from __future__ import annotations

import json
import textwrap
from pathlib import Path

import pytest
from support.helpers import counts, make_bag

DRIVER = textwrap.dedent("""
    import json, sys, threading, time
    from bagfault import api
    from bagfault.engine.stop import StopFlag

    kind, target, out = sys.argv[1], sys.argv[2], sys.argv[3]
    stop = StopFlag()
    box = {}

    def work():
        if kind == 'proxy':
            box['result'] = api.proxy(target, record=out, stop=stop)
        elif kind == 'play':
            box['result'] = api.play(None, [target], loop=True, record=out, delay=0.0, stop=stop)
        else:
            box['result'] = api.record([], out, every=True, stop=stop)

    thread = threading.Thread(target=work)
    thread.start()
    time.sleep(4.0)
    running = thread.is_alive()
    started = time.monotonic()
    stop.set('caller')
    thread.join(10.0)
    result = box.get('result')
    print(json.dumps({'running_before': running, 'alive_after': thread.is_alive(),
                      'seconds': time.monotonic() - started,
                      'notes': list(getattr(result, 'notes', [])), 'reason': getattr(result, 'reason', None)}))
""")

SCENARIO = """
injector: {id: imu, type: imu, input_topic: /imu_raw, output_topic: /imu}
faults:
  - {id: bias, injector_id: imu, config: {angular_velocity_z_bias: 0.1}}
"""


@pytest.mark.parametrize('kind', ['proxy', 'play', 'record'])
def test_stop_flag_set_by_the_caller_ends_the_command_within_a_second(graph, tmp_path: Path, kind: str) -> None:
    driver = tmp_path / 'driver.py'
    driver.write_text(DRIVER)
    if kind == 'proxy':
        target = tmp_path / 'scenario.yaml'
        target.write_text(SCENARIO)
    else:
        target = make_bag(tmp_path / 'bag.mcap', [('/imu_raw', 'sensor_msgs/msg/Imu', 100.0)], 1.0)
    out = tmp_path / 'out.mcap'
    if kind == 'record':
        graph.bagfault('play', str(target), '--loop', '--delay', '0', name='player')
    process = graph.start(str(driver), kind, str(target), str(out), name=kind)
    assert process.wait(timeout=60) == 0, process.err_path.read_text()
    report = json.loads(process.out_path.read_text().splitlines()[-1])
    assert report['running_before'] is True  # it was still working when the flag was set
    assert report['alive_after'] is False
    assert report['seconds'] < 1.0
    assert out.exists()  # stopped cleanly: the recording is complete under its name
    if kind == 'play':
        assert any('stopped by caller' in note for note in report['notes'])
        assert counts(out)['/imu_raw'] > 100  # more than one pass of the 1 s bag went out
    if kind == 'record':
        assert report['reason'] == 'caller'
