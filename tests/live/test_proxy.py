"""`bagfault proxy` between real processes: parameters switch faults, the recording holds what happened."""

from __future__ import annotations

import json
import shutil
import signal
import time
from pathlib import Path

import pytest
from support.helpers import NS, decoded
from support.toolchain import assert_toolchain_opens

BASE_Z = 0.001  # the publisher sends angular_velocity.z = 0.001 * (k % 100), k in orientation_covariance[0]


def delta_z(message) -> float:
    k = int(message.orientation_covariance[0])
    return message.angular_velocity.z - BASE_Z * (k % 100)


def test_imu_bias_switched_on_through_a_parameter(graph, scenarios: Path, tmp_path: Path) -> None:
    record = tmp_path / 'proxy.mcap'
    proxy = graph.bagfault('proxy', str(scenarios / 'imu.yaml'), '--record', str(record), name='proxy')
    graph.wait_for(proxy, 'bagfault proxy ready')
    echo = graph.peer('echo', '/sensors/imu', 'sensor_msgs/msg/Imu', '--seconds', '60',
                      '--fields', 'angular_velocity.z', 'orientation_covariance', name='echo')
    diagnostics = graph.peer('echo', '/diagnostics', 'diagnostic_msgs/msg/DiagnosticArray', '--seconds', '60',
                             '--fields', 'status', name='diagnostics')
    graph.wait_for(echo, 'ready')
    publisher = graph.peer('publish-imu', '/sensors/imu_raw', '--rate', '200', '--seconds', '60', name='imu')
    time.sleep(3.0)
    rejected = graph.call('set-param', '/bagfault', 'imu_dropout.drop_probability', '1.5')
    assert rejected['successful'] is False and '1.0' in rejected['reason']
    switched = graph.call('set-param', '/bagfault', 'imu_yaw_rate_bias.active', 'true')
    assert switched['successful'] is True
    time.sleep(2.0)  # biased messages after the switch, however long the calls took on a loaded machine
    graph.stop(publisher)
    time.sleep(0.5)
    graph.stop(echo)
    graph.stop(diagnostics)
    assert graph.stop(proxy, signal.SIGINT) == 0

    # the subscriber saw the bias only after the switch, and then on every message
    received = graph.lines(echo)
    assert len(received) > 600
    deltas = []
    for row in received:
        k = int(row['orientation_covariance'].split('[')[1].split(',')[0].split('.')[0])
        deltas.append(round(row['angular_velocity.z'] - BASE_Z * (k % 100), 9))
    assert set(deltas) == {0.0, 0.05}
    first = deltas.index(0.05)
    assert all(d == 0.0 for d in deltas[:first]) and all(d == 0.05 for d in deltas[first:])
    assert abs(received[first]['t'] - switched['t']) < 0.5

    # /diagnostics: the fault went from OK inactive to WARN active
    states = [row['status'] for row in graph.lines(diagnostics)]
    assert any("name='bagfault: fault imu_yaw_rate_bias', message='inactive'" in s for s in states)
    assert any("name='bagfault: fault imu_yaw_rate_bias', message='active'" in s for s in states)

    # the recording: raw and mutated topics and the event, the bias exactly from the event on
    topics = decoded(record, ['/sensors/imu_raw', '/sensors/imu', '/fault_injection/events'])
    (event_time, event), = topics['/fault_injection/events']
    assert (event.fault_id, event.state, event.source) == ('imu_yaw_rate_bias', 'active', 'manual')
    assert all(delta_z(m) == 0.0 for _, m in topics['/sensors/imu_raw'])
    outputs = topics['/sensors/imu']
    assert len(outputs) == len(topics['/sensors/imu_raw']) > 600
    assert all(round(delta_z(m), 9) == (0.05 if t >= event_time else 0.0) for t, m in outputs)
    assert any(t < event_time for t, _ in outputs) and any(t >= event_time for t, _ in outputs)
    assert_toolchain_opens(record, tmp_path, distro='jazzy')


def test_stop_by_sigterm_finalises_the_recording_and_bagfault_check_reads_it(graph, scenarios: Path,
                                                                              tmp_path: Path) -> None:
    scenario = tmp_path / 'imu.yaml'
    scenario.write_text((scenarios / 'imu.yaml').read_text() + """
assertions:
  - {id: bias_seen, type: fault_event, fault_id: imu_yaw_rate_bias, state: active}
""")
    record = tmp_path / 'proxy.mcap'
    proxy = graph.bagfault('proxy', str(scenario), '--record', str(record), '--json', str(tmp_path / 'live.json'),
                           name='proxy')
    graph.wait_for(proxy, 'bagfault proxy ready')
    time.sleep(1.0)  # time zero is the proxy's start; the first message comes later
    publisher = graph.peer('publish-imu', '/sensors/imu_raw', '--rate', '100', '--seconds', '1',
                           '--wait-subscriber', name='imu')
    publisher.wait(timeout=60)  # 100 messages, however long the publisher took to start
    time.sleep(0.3)
    assert not record.exists()
    assert graph.stop(proxy, signal.SIGTERM) == 1  # the assertion never saw its event: failed, exit 1
    assert 'FAIL  bias_seen' in proxy.out_path.read_text()
    assert [p.name for p in tmp_path.iterdir() if p.name.endswith('.partial')] == []
    counts = {topic: len(messages) for topic, messages in decoded(record).items()}
    assert counts['/sensors/imu_raw'] == counts['/sensors/imu'] > 50
    check = graph.bagfault('check', str(scenario), str(record), '--json', str(tmp_path / 'check.json'), name='check')
    assert check.wait(timeout=60) == 1
    assert 'not observed before the end of the bag' in check.out_path.read_text()
    live, checked = (json.loads((tmp_path / name).read_text()) for name in ('live.json', 'check.json'))
    first = min(t for messages in decoded(record).values() for t, _ in messages)
    assert live['time']['origin_ns'] < first - 500_000_000  # zero was well before the first recorded message
    assert checked['time']['origin_ns'] == live['time']['origin_ns']  # and `check` puts it at the same place


def test_reload_service_applies_new_faults_and_refuses_layout_changes(graph, scenarios: Path, tmp_path: Path) -> None:
    scenario = tmp_path / 'imu.yaml'
    shutil.copy(scenarios / 'imu.yaml', scenario)
    proxy = graph.bagfault('proxy', str(scenario), name='proxy')
    graph.wait_for(proxy, 'bagfault proxy ready')
    described = graph.call('describe-params', '/bagfault', 'imu_')
    drop = described['imu_dropout.drop_probability']
    assert drop['ranges'] == [[0.0, 1.0]] and drop['value'] == 0.2 and 'dropped' in drop['description']
    assert described['imu_dropout.active']['value'] is False
    assert described['imu_delay.delay_ms']['value'] == 100 and described['imu_delay.delay_ms']['ranges'][0][0] == 0
    assert described['imu_yaw_rate_bias.linear_acceleration_x_bias']['value'] == 0.0  # unset key: schema default
    text = scenario.read_text()
    scenario.write_text(text.replace('angular_velocity_z_bias: 0.05', 'angular_velocity_z_bias: 0.25'))
    answer = graph.call('trigger-call', '/bagfault/reload_scenario')
    assert answer['success'] is True and 'reloaded imu.yaml' in answer['message']
    assert graph.call('describe-params', '/bagfault', 'imu_yaw')['imu_yaw_rate_bias.angular_velocity_z_bias'][
        'value'] == 0.25  # the parameter follows the reloaded file
    scenario.write_text(text.replace('output_topic: /sensors/imu', 'output_topic: /sensors/imu_other'))
    answer = graph.call('trigger-call', '/bagfault/reload_scenario')
    assert answer['success'] is False and 'endpoints' in answer['message']
    scenario.write_text(text.replace('drop_probability: 0.2', 'drop_probability: 2.0'))
    answer = graph.call('trigger-call', '/bagfault/reload_scenario')
    assert answer['success'] is False and 'drop_probability' in answer['message']
    assert graph.stop(proxy) == 0
    log = proxy.err_path.read_text()
    assert 'imu_yaw_rate_bias: config_updated (reload) config={angular_velocity_z_bias=0.25}' in log


@pytest.mark.parametrize('case', ['late_publisher_and_restart', 'qos_mismatch', 'malformed'])
def test_robust_against_publishers_that_come_go_mismatch_or_send_garbage(graph, tmp_path: Path, case: str) -> None:
    scenario = tmp_path / 'imu.yaml'
    options = {'malformed': ', on_malformed: drop', 'qos_mismatch': ', reliability: reliable'}.get(case, '')
    # (an injector that sets its reliability keeps it: a best-effort publisher cannot connect, and is named)
    scenario.write_text(f"""
injector: {{id: imu, type: imu, input_topic: /imu_raw, output_topic: /imu{options}}}
faults:
  - {{id: bias, injector_id: imu, active_on_startup: true, config: {{angular_velocity_z_bias: 1.0}}}}
""")
    proxy = graph.bagfault('proxy', str(scenario), name='proxy')
    graph.wait_for(proxy, 'bagfault proxy ready')
    echo = graph.peer('echo', '/imu', 'sensor_msgs/msg/Imu', '--seconds', '30', '--fields', 'angular_velocity.z',
                      name='echo')
    graph.wait_for(echo, 'ready')
    time.sleep(1.0)
    if case == 'late_publisher_and_restart':
        for _ in range(2):  # a publisher appears late, stops, and a new one starts
            graph.peer('publish-imu', '/imu_raw', '--rate', '100', '--seconds', '3', name='imu').wait(timeout=30)
    elif case == 'qos_mismatch':
        graph.peer('publish-imu', '/imu_raw', '--rate', '100', '--seconds', '2', '--best-effort',
                   name='best_effort').wait(timeout=30)
        graph.peer('publish-imu', '/imu_raw', '--rate', '100', '--seconds', '3', name='imu').wait(timeout=30)
    else:
        graph.peer('publish-imu', '/imu_raw', '--rate', '100', '--seconds', '4', '--malformed-every', '10',
                   name='imu').wait(timeout=30)
    time.sleep(0.5)
    assert proxy.poll() is None  # still running
    assert graph.stop(proxy) == 0
    received = graph.lines(echo)
    assert received and all(row['angular_velocity.z'] >= 1.0 for row in received)
    log = proxy.err_path.read_text()
    summary = proxy.out_path.read_text()
    if case == 'late_publisher_and_restart':
        assert len(received) > 2 * 150  # both publishers got through (2 x 300 sent; discovery eats up to 1 s each)
    elif case == 'qos_mismatch':
        assert log.count('incompatible QoS') == 1 and 'Still running' in log
        assert len(received) > 150  # the compatible publisher's 300 got through, minus discovery
    else:
        assert 'malformed message #1' in log and 'dropped' in log
        malformed = int(summary.split(' malformed')[0].rsplit(', ', 1)[1])
        assert malformed >= 25  # every 10th of 400, minus discovery
        assert len(received) > 200


def test_use_sim_time_follows_clock_from_a_played_bag(graph, tmp_path: Path) -> None:
    from support.helpers import make_bag

    bag = make_bag(tmp_path / 'imu.mcap', [('/sensors/imu_raw', 'sensor_msgs/msg/Imu', 100.0)], 6.0)
    scenario = tmp_path / 'imu.yaml'
    scenario.write_text("""
injector: {id: imu, type: imu, input_topic: /sensors/imu_raw, output_topic: /sensors/imu}
faults:
  - {id: bias, injector_id: imu, start: 2.0, duration: 2.0, config: {linear_acceleration_x_bias: 1.0}}
""")
    record = tmp_path / 'proxy.mcap'
    proxy = graph.bagfault('proxy', str(scenario), '--use-sim-time', '--record', str(record), name='proxy')
    graph.wait_for(proxy, 'proxy /sensors/imu_raw')
    play = graph.bagfault('play', str(bag), '--clock', '--rate', '2', '--delay', '1.5', name='play')
    assert play.wait(timeout=60) == 0
    time.sleep(0.5)
    assert graph.stop(proxy) == 0
    topics = decoded(record, ['/sensors/imu_raw', '/sensors/imu', '/fault_injection/events'])
    events = [(t, e.state) for t, e in topics['/fault_injection/events']]
    assert [state for _, state in events] == ['active', 'inactive']
    start, end = events[0][0], events[1][0]
    assert end - start == 2 * NS  # scheduled on sim time: exactly the duration apart
    raw = {m.header.stamp.sec * NS + m.header.stamp.nanosec: m for _, m in topics['/sensors/imu_raw']}
    biased = 0
    for time_ns, message in topics['/sensors/imu']:
        stamp = message.header.stamp.sec * NS + message.header.stamp.nanosec
        bias = 1.0 if start <= time_ns < end else 0.0
        assert message.linear_acceleration.x == raw[stamp].linear_acceleration.x + bias
        biased += bias == 1.0
    # every message the proxy received inside the window went out biased; about 2 s of a 100 Hz stream, less what a
    # busy machine lost before the proxy (the recording's raw topic shows the same losses: 535 of 600 beside a suite)
    received = sum(start <= t < end for t, _ in topics['/sensors/imu_raw'])
    assert biased == received
    assert 50 <= received <= 250
    # sim time: the recording's clock is the bag's clock
    assert abs(min(t for t, _ in topics['/sensors/imu_raw']) - min(raw)) < NS


def test_fault_manager_sees_the_live_system_detect_the_fault(graph, tmp_path: Path) -> None:
    """Bias switched on -> the system under test reports on /diagnostics -> the oracle confirms in time."""
    scenario = tmp_path / 'detect.yaml'
    scenario.write_text("""
injector: {id: imu, type: imu, input_topic: /sensors/imu_raw, output_topic: /sensors/imu}
faults:
  - {id: drift, injector_id: imu, config: {angular_velocity_z_bias: 1.0}}
fault_manager:
  confirmation_threshold: -3
  diagnostics: {codes: {'imu_monitor: drift': IMU_DRIFT}}
assertions:
  - {id: detected, type: fault_status, code: IMU_DRIFT, status: CONFIRMED, after: drift, within: 2.0}
""")
    monitor = graph.peer('imu-monitor', '/sensors/imu', '--seconds', '30', name='monitor')
    graph.wait_for(monitor, 'ready')
    record = tmp_path / 'proxy.mcap'
    proxy = graph.bagfault('proxy', str(scenario), '--record', str(record), name='proxy')
    graph.wait_for(proxy, 'bagfault proxy ready')
    assert 'watching /diagnostics' in proxy.err_path.read_text()
    publisher = graph.peer('publish-imu', '/sensors/imu_raw', '--rate', '100', '--seconds', '7', name='imu')
    time.sleep(3.0)
    assert graph.call('set-param', '/bagfault', 'drift.active', 'true')['successful']
    publisher.wait(timeout=30)
    assert graph.stop(proxy) == 0, proxy.out_path.read_text()
    assert 'PASS  detected' in proxy.out_path.read_text()
    topics = decoded(record, ['/diagnostics', '/fault_manager/events', '/fault_injection/events'])
    (switched, _), = topics['/fault_injection/events']
    assert all(s.name == 'imu_monitor: drift' for _, m in topics['/diagnostics'] for s in m.status)  # not our own
    confirmed = [t for t, e in topics['/fault_manager/events'] if e.fault.fault_code == 'IMU_DRIFT'
                 and e.fault.status == 'CONFIRMED']
    assert confirmed and 0 < confirmed[0] - switched < 2 * NS


def test_delayed_messages_leave_the_proxy_when_due(graph, tmp_path: Path) -> None:
    scenario = tmp_path / 'late.yaml'
    scenario.write_text("""
injector: {id: imu, type: imu, input_topic: /imu_raw, output_topic: /imu}
faults:
  - {id: late, injector_id: imu, active_on_startup: true, config: {delay_ms: 200}}
""")
    record = tmp_path / 'proxy.mcap'
    proxy = graph.bagfault('proxy', str(scenario), '--record', str(record), name='proxy')
    graph.wait_for(proxy, 'bagfault proxy ready')
    graph.peer('publish-imu', '/imu_raw', '--rate', '100', '--seconds', '3', name='imu').wait(timeout=30)
    time.sleep(0.5)
    assert graph.stop(proxy) == 0
    topics = decoded(record, ['/imu_raw', '/imu'])
    received = {int(m.orientation_covariance[0]): t for t, m in topics['/imu_raw']}
    sent = {int(m.orientation_covariance[0]): t for t, m in topics['/imu']}
    assert len(sent) == len(received) > 100
    lags = sorted(sent[k] - received[k] for k in sent)
    assert lags[0] >= 200_000_000  # never early
    assert lags[len(lags) // 2] < 220_000_000  # and on time: the delay line wakes at the due time


def test_a_stopped_proxy_waits_for_acknowledgements_and_says_which_topic_missed_them(graph, scenarios: Path) -> None:
    proxy = graph.bagfault('proxy', str(scenarios / 'imu.yaml'), name='proxy')
    graph.wait_for(proxy, 'bagfault proxy ready')
    echo = graph.peer('echo', '/sensors/imu', 'sensor_msgs/msg/Imu', '--seconds', '300', name='echo')
    graph.wait_for(echo, 'ready')
    publisher = graph.peer('publish-imu', '/sensors/imu_raw', '--rate', '100', '--seconds', '60', name='imu')
    graph.wait_for_line(echo)
    echo.send_signal(signal.SIGSTOP)  # alive to DDS (its lease lasts 20 s) but never acknowledging again
    try:
        time.sleep(0.5)
        graph.stop(publisher)
        stopped = time.monotonic()
        assert graph.stop(proxy, signal.SIGINT) == 0
        waited = time.monotonic() - stopped
    finally:
        echo.send_signal(signal.SIGCONT)
    out = proxy.out_path.read_text()
    assert '/sensors/imu: not every subscriber acknowledged the last messages within 2 s of the stop' in out, out
    assert waited > 2.0


def test_a_best_effort_publisher_that_comes_later_is_heard_through_the_default_qos(graph, scenarios: Path,
                                                                                  tmp_path: Path) -> None:
    """A sensor driver offers best effort; the proxy's input asked for reliable (no publisher at its start) and
    adapts, as rosbag2's recorder does; its output stays reliable, so a reliable subscriber gets every message."""
    record = tmp_path / 'proxy.mcap'
    proxy = graph.bagfault('proxy', str(scenarios / 'imu.yaml'), '--record', str(record), name='proxy')
    graph.wait_for(proxy, 'bagfault proxy ready')
    echo = graph.peer('echo', '/sensors/imu', 'sensor_msgs/msg/Imu', '--seconds', '60', '--fields',
                      'orientation_covariance', name='echo')
    graph.wait_for(echo, 'ready')
    publisher = graph.peer('publish-imu', '/sensors/imu_raw', '--best-effort', '--rate', '100', '--seconds', '3',
                           '--wait-subscriber', name='imu')
    assert publisher.wait(timeout=60) == 0
    time.sleep(1.0)
    graph.stop(echo)
    assert graph.stop(proxy, signal.SIGINT) == 0
    numbers = [int(row['orientation_covariance'].split('[')[1].split(',')[0].split('.')[0])
               for row in graph.lines(echo)]
    # heard within the first second after the match (a loaded machine's proxy may match the writer a moment after
    # the writer matched it: the first messages are lost before it), and from the first heard on, best effort on
    # loopback loses none or hardly any
    assert numbers and numbers[0] < 100 and numbers == sorted(numbers), numbers[:5]
    assert len(numbers) >= (300 - numbers[0]) - 5, (numbers[0], len(numbers))
    assert 'subscription now best_effort' in proxy.err_path.read_text()
    assert decoded(record, ['/sensors/imu_raw'])['/sensors/imu_raw'][-1][1].orientation_covariance[0] == numbers[-1]


def test_a_recording_proxy_counts_what_its_input_lost_and_says_so(graph, scenarios: Path, tmp_path: Path) -> None:
    """A burst the proxy cannot take (it is stopped, SIGSTOP, while most of it goes by, its input queue of 10
    overflowing): what it received plus what it says its input lost is what the publisher sent, per the
    publisher's own count; the count is in the summary, one stderr warning and the recording's metadata."""
    from mcap.reader import make_reader

    record = tmp_path / 'proxy.mcap'
    proxy = graph.bagfault('proxy', str(scenarios / 'imu.yaml'), '--record', str(record), name='proxy')
    graph.wait_for(proxy, 'bagfault proxy ready')
    published = graph.burst_past_a_stopped_listener(proxy, '/sensors/imu_raw')
    time.sleep(1.0)
    assert graph.stop(proxy, signal.SIGINT) == 0, proxy.err_path.read_text()
    with record.open('rb') as stream:
        reader = make_reader(stream)
        raw = sum(1 for _ in reader.iter_messages(topics=['/sensors/imu_raw']))
        [meta] = [m for m in reader.iter_metadata() if m.name == 'bagfault.recording']
    lost = json.loads(meta.metadata['lost']).get('/sensors/imu_raw', 0)
    assert json.loads(meta.metadata['received']) == {'/sensors/imu_raw': raw}
    assert raw + lost == published, (raw, lost, published)
    assert lost > 0, 'the burst was meant to be more than the proxy takes'
    out, err = proxy.out_path.read_text(), proxy.err_path.read_text()
    assert f'/sensors/imu_raw -> /sensors/imu: {raw} received ({lost} lost before)' in out, out
    assert f'the proxy lost {lost} input messages before it heard them ({lost} of /sensors/imu_raw)' in err, err
