"""Live mode as ROS users run it: --ros-args (node name, namespace, remaps, -p), parameter conventions, guarded
sim time, a clean stop that loses nothing, events on the graph, play's usual options, record's offered QoS.
Every process is real; expected values come from what the peers sent."""

from __future__ import annotations

import itertools
import json
import signal
import time
from pathlib import Path

from mcap.exceptions import McapError
from mcap.records import Channel as McapChannel
from mcap.records import Message as McapMessage
from mcap.stream_reader import StreamReader
from support.helpers import decoded, make_bag

IMU = 'sensor_msgs/msg/Imu'


def z_values(graph, process) -> list[float]:
    return [row['angular_velocity.z'] for row in graph.lines(process)]


def raw_z(values: list[float], bias: float) -> bool:
    """Every value is a publisher value (0.001 * k for k < 100) plus `bias`."""
    return all(abs(round((v - bias) * 1000) - (v - bias) * 1000) < 1e-6 and -1e-9 < v - bias < 0.1 for v in values)


def test_two_proxies_by_name_namespace_and_remaps_controlled_apart(graph, scenarios: Path) -> None:
    imu = str(scenarios / 'imu.yaml')
    first = graph.bagfault('proxy', imu, '--ros-args', '-r', '__node:=imu_faults', '-r', '__ns:=/robot1',
                           '-r', '/sensors/imu:=/robot1/imu', '-p', 'imu_yaw_rate_bias.active:=true', name='first')
    second = graph.bagfault('proxy', imu, '--ros-args', '-r', '__node:=imu_faults', '-r', '__ns:=/robot2',
                            '-r', '/sensors/imu:=/robot2/imu', name='second')
    for proxy in (first, second):
        graph.wait_for(proxy, 'bagfault proxy ready')
    one = graph.peer('echo', '/robot1/imu', IMU, '--seconds', '9', '--fields', 'angular_velocity.z', name='one')
    two = graph.peer('echo', '/robot2/imu', IMU, '--seconds', '9', '--fields', 'angular_velocity.z', name='two')
    graph.wait_for(one, 'ready')
    graph.wait_for(two, 'ready')
    publisher = graph.peer('publish-imu', '/sensors/imu_raw', '--rate', '50', '--seconds', '6', name='imu')
    time.sleep(2.0)
    done = graph.call('set-param', '/robot2/imu_faults', 'imu_yaw_rate_bias.active', 'true')
    assert done['successful']
    switched = done['t']  # when the answer came
    # an integer for a floating-point key is that number
    done = graph.call('set-param', '/robot1/imu_faults', 'imu_yaw_rate_bias.angular_velocity_z_bias', '1')
    assert done['successful']
    changed = done['t']
    unknown = graph.call('set-param', '/robot1/imu_faults', 'imu_yaw_rate_bais.active', 'true')
    assert not unknown['successful']
    assert unknown['reason'].startswith("imu_yaw_rate_bais.active: no fault 'imu_yaw_rate_bais' here (faults: ")
    wrong_key = graph.call('set-param', '/robot1/imu_faults', 'imu_yaw_rate_bias.gain', '2.0')
    assert "'gain' is not a key of fault 'imu_yaw_rate_bias' (keys: active, " in wrong_key['reason']
    publisher.wait(timeout=30)
    for proxy in (first, second):
        assert graph.stop(proxy) == 0
    one.wait(timeout=30)
    two.wait(timeout=30)
    rows_one, rows_two = graph.lines(one), graph.lines(two)
    assert len(rows_one) > 200 and len(rows_two) > 200
    # robot1: biased from the start by -p (0.05), then by 1.0; robot2: untouched until its own switch
    before = [r['angular_velocity.z'] for r in rows_one if r['t'] < changed - 0.2]
    after = [r['angular_velocity.z'] for r in rows_one if r['t'] > changed + 0.5]
    assert before and raw_z(before, 0.05)
    assert after and raw_z(after, 1.0)
    clean = [r['angular_velocity.z'] for r in rows_two if r['t'] < switched - 0.2]
    biased = [r['angular_velocity.z'] for r in rows_two if r['t'] > switched + 0.5]
    assert clean and raw_z(clean, 0.0)
    assert biased and raw_z(biased, 0.05)


def test_bad_ros_arguments_and_refused_overrides_are_one_line(graph, scenarios: Path) -> None:
    imu = str(scenarios / 'imu.yaml')
    for args, text in ((['-r', 'broken'], '--ros-args -r broken: '),
                       (['-p', 'imu_dropout.drop_probability:=2.0'], 'imu_dropout.drop_probability')):
        proxy = graph.bagfault('proxy', imu, '--ros-args', *args, name='bad')
        assert proxy.wait(timeout=60) == 2
        err = proxy.err_path.read_text()
        assert text in err and 'Traceback' not in err
    run = graph.bagfault('validate', imu, '--ros-args', '-r', '__node:=x', name='validate')
    assert run.wait(timeout=60) == 2
    assert 'only proxy, play, record make a ROS node' in run.err_path.read_text()


def test_sim_time_without_clock_and_endless_delays_are_refused_and_events_go_out_as_json(graph, scenarios: Path) -> None:
    events = graph.peer('echo', '/bagfault/events', 'std_msgs/msg/String', '--seconds', '300', '--fields', 'data',
                        name='events')
    graph.wait_for(events, 'ready')
    proxy = graph.bagfault('proxy', str(scenarios / 'imu.yaml'), name='proxy')
    graph.wait_for(proxy, 'bagfault proxy ready')
    refused = graph.call('set-param', '/bagfault', 'use_sim_time', 'true')
    assert not refused['successful'] and 'nothing publishes /clock' in refused['reason']
    endless = graph.call('set-param', '/bagfault', 'imu_delay.delay_ms', '1000000000000')
    assert not endless['successful'] and 'Max: 3600000' in endless['reason']
    assert graph.call('set-param', '/bagfault', 'imu_delay.active', 'true')['successful']
    time.sleep(1.0)
    assert graph.stop(proxy) == 0
    graph.stop(events)
    seen = [json.loads(row['data']) for row in graph.lines(events)]
    switched = [e for e in seen if e['topic'] == '/fault_injection/events' and e['fault_id'] == 'imu_delay']
    assert [e['state'] for e in switched] == ['active']
    assert switched[0]['source'] == 'manual' and switched[0]['type'] == 'ros2_fault_injection/msg/FaultEvent'
    assert switched[0]['t_s'] > 0 and isinstance(switched[0]['stamp_ns'], int)


def test_a_clean_stop_publishes_delayed_messages_and_answers_delayed_calls(graph, tmp_path: Path) -> None:
    scenario = tmp_path / 'slow.yaml'
    scenario.write_text("""
injectors:
  - {id: imu, type: imu, input_topic: /imu_raw, output_topic: /imu, message_type: sensor_msgs/msg/Imu}
  - {id: motors, type: trigger_service, proxy_service: /enable_motors, target_service: /enable_motors_raw}
faults:
  - {id: late, injector_id: imu, active_on_startup: true, config: {delay_ms: 1500}}
  - {id: slow_motors, injector_id: motors, active_on_startup: true, config: {delay_ms: 8000}}
""")
    record = tmp_path / 'stop.mcap'
    graph.peer('trigger-server', '/enable_motors_raw', '--message', 'motors on', name='server')
    echo = graph.peer('echo', '/imu', IMU, '--seconds', '20', '--fields', 'orientation_covariance', name='echo')
    graph.wait_for(echo, 'ready')
    proxy = graph.bagfault('proxy', str(scenario), '--record', str(record), name='proxy')
    graph.wait_for(proxy, 'bagfault proxy ready')
    graph.wait_for(echo, 'matched')  # message_type: the proxy's /imu exists before any input; count from here
    publisher = graph.peer('publish-imu', '/imu_raw', '--rate', '100', '--seconds', '2', '--wait-subscriber',
                           name='imu')
    caller = graph.peer('trigger-call', '/enable_motors', '--timeout', '15', name='call')
    publisher.wait(timeout=30)
    sent = graph.lines(publisher)[-1]['published']
    time.sleep(0.3)  # 1.2 s of messages still in the delay line, the call about 5 s from its answer
    assert graph.stop(proxy, signal.SIGINT) == 0
    caller.wait(timeout=30)
    answer = graph.lines(caller)[-1]
    assert answer['success'] is True and answer['message'] == 'motors on'
    assert answer['seconds'] < 6.0  # answered at the stop (about 3 s after the call), not after its whole delay
    time.sleep(0.5)
    echo.send_signal(signal.SIGINT)
    echo.wait(timeout=30)
    assert len(graph.lines(echo)) == sent  # every delayed message went out
    assert 'delayed messages were still waiting' not in proxy.out_path.read_text()  # all on time within 2 s
    calls = decoded(record, ['/bagfault/service_calls'])['/bagfault/service_calls']
    assert [json.loads(m.data) for _, m in calls] == [
        {'service': '/enable_motors', 'target': '/enable_motors_raw', 'outcome': 'forwarded', 'success': True,
         'message': 'motors on', 'delay_ms': 8000}]
    assert len(decoded(record, ['/imu'])['/imu']) == sent


def test_play_waits_for_its_subscriber_remaps_filters_and_skips(graph, tmp_path: Path) -> None:
    bag = make_bag(tmp_path / 'bag.mcap', [('/sensors/imu_raw', IMU, 50.0), ('/odom_raw', 'nav_msgs/msg/Odometry',
                                                                             20.0)], 3.0)
    play = graph.bagfault('play', str(bag), '--wait-for', '/imu_in', '--remap', '/sensors/imu_raw:=/imu_in',
                          '--topics', '/sensors/imu_raw', '--start-offset', '1', name='play')
    time.sleep(3.0)  # the player waits for this subscriber, however late it comes
    assert play.poll() is None
    echo = graph.peer('echo', '/imu_in', IMU, '--seconds', '300', '--fields', 'header.stamp.sec', name='echo')
    odom = graph.peer('echo', '/odom_raw', 'nav_msgs/msg/Odometry', '--seconds', '300', name='odom')
    assert play.wait(timeout=60) == 0
    time.sleep(0.5)
    graph.stop(echo)  # they listened from before the first message to after the last, however slow the machine
    graph.stop(odom)
    assert len(graph.lines(echo)) == 100  # 50 Hz over bag seconds [1, 3): none lost, none of the first second
    assert graph.lines(odom) == []  # not among --topics


def test_record_keeps_the_qos_the_publisher_offered(graph, tmp_path: Path) -> None:
    out = tmp_path / 'qos.mcap'
    recorder = graph.bagfault('record', '/imu_be', '-o', str(out), '--duration', '5', name='record')
    graph.wait_for(recorder, 'bagfault record ready')
    graph.peer('publish-imu', '/imu_be', '--rate', '50', '--seconds', '3', '--best-effort', name='imu')
    assert recorder.wait(timeout=60) == 0
    import yaml
    from mcap.reader import make_reader
    with out.open('rb') as stream:
        summary = make_reader(stream).get_summary()
    [channel] = [c for c in summary.channels.values() if c.topic == '/imu_be']
    [offered] = yaml.safe_load(channel.metadata['offered_qos_profiles'])
    assert offered['reliability'] == 2  # RMW_QOS_POLICY_RELIABILITY_BEST_EFFORT, the form every distro reads
    assert offered['depth'] != 100  # not the recorder's own subscription depth


def test_proxy_record_keeps_what_each_topics_publishers_offer(graph, scenarios: Path, tmp_path: Path) -> None:
    """A best-effort sensor into `proxy --record`: its input channel is recorded best-effort with the type hash the
    publisher reports, as `record --all` records it; the output channel with what the proxy itself offers."""
    import yaml
    from mcap.reader import make_reader

    out = tmp_path / 'proxy.mcap'
    proxy = graph.bagfault('proxy', str(scenarios / 'imu.yaml'), '--record', str(out), name='proxy')
    graph.wait_for(proxy, 'bagfault proxy ready')
    graph.peer('publish-imu', '/sensors/imu_raw', '--rate', '50', '--seconds', '3', '--best-effort',
               name='imu').wait(timeout=30)
    assert graph.stop(proxy) == 0
    with out.open('rb') as stream:
        channels = {c.topic: c for c in make_reader(stream).get_summary().channels.values()}
    raw, faulty = channels['/sensors/imu_raw'], channels['/sensors/imu']
    [offered] = yaml.safe_load(raw.metadata['offered_qos_profiles'])
    assert offered['reliability'] == 2  # RMW_QOS_POLICY_RELIABILITY_BEST_EFFORT: what the sensor offered
    assert raw.metadata['topic_type_hash'].startswith('RIHS01_')
    [own] = yaml.safe_load(faulty.metadata['offered_qos_profiles'])
    assert own['reliability'] == 1  # the proxy offers reliable (it reaches both kinds of subscriber)
    assert faulty.metadata['topic_type_hash'] == raw.metadata['topic_type_hash']


def complete_chunk_messages(partial: Path, topic: str) -> list[int]:
    """Log times of the topic's messages in a cut-short MCAP's complete chunks, as the `mcap` library's stream
    reader reads them front to back until the file ends mid-record."""
    times = []
    channels = set()
    with partial.open('rb') as stream:
        try:
            for record in StreamReader(stream).records:
                if isinstance(record, McapChannel) and record.topic == topic:
                    channels.add(record.id)
                elif isinstance(record, McapMessage) and record.channel_id in channels:
                    times.append(record.log_time)
        except McapError:
            pass  # the chunk being written when the process died
    return times


def test_a_killed_recording_is_recovered_up_to_its_last_second(graph, scenarios: Path, tmp_path: Path) -> None:
    record = tmp_path / 'killed.mcap'
    proxy = graph.bagfault('proxy', str(scenarios / 'imu.yaml'), '--record', str(record), name='proxy')
    graph.wait_for(proxy, 'bagfault proxy ready')
    publisher = graph.peer('publish-imu', '/sensors/imu_raw', '--rate', '500', '--seconds', '10', name='imu')
    graph.wait_for(publisher, 'ready')
    time.sleep(4.0)
    proxy.kill()  # SIGKILL: no handler, no finish
    killed_at = time.time_ns()
    proxy.wait(timeout=10)
    assert not record.exists()
    [partial] = tmp_path.glob('.killed.mcap.*.partial')
    flushed = complete_chunk_messages(partial, '/sensors/imu_raw')
    recover = graph.bagfault('recover', str(record), name='recover')
    assert recover.wait(timeout=60) == 0, recover.err_path.read_text()
    assert 'cut short' in recover.out_path.read_text()
    raw = decoded(record, ['/sensors/imu_raw'])['/sensors/imu_raw']
    # every message of every chunk completed before the kill, as an independent reader finds them in the partial
    assert sorted(t for t, _ in raw) == sorted(flushed) and len(raw) >= 100
    numbers = [int(m.orientation_covariance[0]) for _, m in raw]
    # in order, and no chunk missing in between: a chunk is completed every second (LIVE_FLUSH; 1 MB would hold
    # more than 2000 of these), so a missing one leaves a gap of about 500; what a busy machine's DDS drops between
    # publisher and proxy leaves shorter ones (55 in a row beside a second suite, 2026-12-07)
    gaps = [b - a for a, b in itertools.pairwise(numbers)]
    assert min(gaps) >= 1 and max(gaps) < 250, max(gaps)
    # up to its last second: a chunk is completed at least every second (LIVE_FLUSH), so what was heard more than a
    # second before the kill is in the file (two seconds more for a loaded machine's compression thread and disk)
    assert killed_at - raw[-1][0] < 3_000_000_000, (killed_at - raw[-1][0]) / 1e9


def test_play_clock_rate_between_messages(graph, tmp_path: Path) -> None:
    bag = make_bag(tmp_path / 'slow.mcap', [('/sensors/imu_raw', IMU, 2.0)], 3.0)  # 6 messages over 2.5 s
    counts = {}
    for hz in ('10', '100'):
        checker = graph.peer('clock-check', '/sensors/imu_raw', IMU, '--seconds', '30', '--until-quiet', '1.0',
                             name=f'clock{hz}')
        graph.wait_for(checker, 'ready')
        play = graph.bagfault('play', str(bag), '--clock', hz, '--wait-for', '/sensors/imu_raw', name=f'play{hz}')
        assert play.wait(timeout=60) == 0
        checker.wait(timeout=30)
        counts[hz] = graph.lines(checker)[-1]['clock_count']
    # 2.5 s between the first and the last message: about 25 ticks at 10 Hz and 250 at 100 Hz (plus one per message)
    assert 15 <= counts['10'] <= 40
    assert 150 <= counts['100'] <= 300
