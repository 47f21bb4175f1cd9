"""`bagfault play` into real subscribers and `bagfault record`; play --record equals an offline run."""

from __future__ import annotations

import signal
import time
from pathlib import Path

from support.helpers import NS, counts, make_bag, raw_messages
from support.toolchain import assert_toolchain_opens

STREAMS = [('/sensors/imu_raw', 'sensor_msgs/msg/Imu', 100.0), ('/odom_raw', 'nav_msgs/msg/Odometry', 50.0),
           ('/scan_raw', 'sensor_msgs/msg/LaserScan', 10.0)]


def test_play_with_clock_into_a_subscriber_and_record_reads_back_the_same_counts(graph, tmp_path: Path) -> None:
    bag = make_bag(tmp_path / 'rover.mcap', STREAMS, 4.0)
    recorded = tmp_path / 'recorded.mcap'
    recorder = graph.bagfault('record', '--all', '-o', str(recorded), '--duration', '9', name='record')
    graph.wait_for(recorder, 'bagfault record ready')
    checker = graph.peer('clock-check', '/sensors/imu_raw', 'sensor_msgs/msg/Imu', '--seconds', '8', name='check')
    graph.wait_for(checker, 'ready')
    play = graph.bagfault('play', str(bag), '--clock', '--rate', '2', '--delay', '2', name='play')
    assert play.wait(timeout=60) == 0
    checker.wait(timeout=30)
    checked = graph.lines(checker)[-1]
    assert checked['messages'] == 400, checked  # every message of the topic, in stamp order
    assert checked['in_order'] and checked['clock_monotonic']
    assert checked['clock_first'] == 1_700_000_000 * NS  # /clock carries bag time
    assert checked['stamp_after_clock'] == 0  # no message arrived before /clock reached its time
    assert 1.6 < checked['span'] < 2.6  # 3.99 s of bag at rate 2, paced on the wall clock
    assert recorder.wait(timeout=60) == 0
    found = counts(recorded)
    expected = counts(bag)
    assert {topic: found[topic] for topic in expected} == dict(expected)
    assert found['/clock'] > 100
    info = assert_toolchain_opens(recorded, tmp_path, distro='jazzy')  # the running rclpy's (ros-jazzy wheels)
    hashes = {topic['name']: topic['type_description_hash'] for topic, _ in info['topics']}
    assert hashes['/clock'].startswith('RIHS01_')  # as rclpy reports it for the publisher


def test_play_applies_the_scenario_and_its_recording_equals_the_offline_run(graph, tmp_path: Path) -> None:
    bag = make_bag(tmp_path / 'rover.mcap', STREAMS, 3.0)
    scenario = tmp_path / 'drift.yaml'
    scenario.write_text("""
injector: {id: odom, type: odom, input_topic: /odom_raw, output_topic: /odom}
faults:
  - {id: drift, injector_id: odom, start: 1.0, duration: 1.0, config: {x_bias: 1.0, x_noise_stddev: 0.1}}
""")
    offline = tmp_path / 'offline.mcap'
    run = graph.bagfault('run', str(scenario), str(bag), '-o', str(offline), '--seed', '4', name='run')
    assert run.wait(timeout=60) == 0
    echo = graph.peer('echo', '/odom', 'nav_msgs/msg/Odometry', '--seconds', '10', '--fields',
                      'pose.pose.position.x', name='echo')
    graph.wait_for(echo, 'ready')
    played = tmp_path / 'played.mcap'
    play = graph.bagfault('play', str(scenario), str(bag), '--rate', '2', '--seed', '4', '--delay', '2',
                          '--record', str(played), name='play')
    assert play.wait(timeout=60) == 0
    live, reference = raw_messages(played), raw_messages(offline)
    assert set(live) == set(reference)
    for topic in reference:  # same bytes at the same bag times: the same injector code on the same clock
        assert live[topic] == reference[topic], topic
    assert_toolchain_opens(played, tmp_path, distro='jazzy')
    assert_toolchain_opens(offline, tmp_path, distro='')  # the bag names no distro
    echo.wait(timeout=30)
    seen = [row['pose.pose.position.x'] for row in graph.lines(echo)]
    published = [m for _, _, m in reference['/odom']]
    assert len(seen) == len(published) == 150


def test_plain_play_loops_until_stopped(graph, tmp_path: Path) -> None:
    bag = make_bag(tmp_path / 'short.mcap', [('/sensors/imu_raw', 'sensor_msgs/msg/Imu', 50.0)], 1.0)
    played = tmp_path / 'played.mcap'
    play = graph.bagfault('play', str(bag), '--loop', '--rate', '4', '--delay', '0', '--record', str(played),
                          name='play')
    time.sleep(4.0)
    assert graph.stop(play) == 0
    times = [t for t, _, _ in raw_messages(played)['/sensors/imu_raw']]
    assert len(times) > 2 * 50  # more than two passes of the 1 s bag
    assert times == sorted(times) and len(set(times)) == len(times)  # the timeline continues across passes
    assert 'passes' in play.out_path.read_text()


def test_loop_names_every_pass_black_box_and_leaves_no_partial_file(graph, tmp_path: Path) -> None:
    bag = make_bag(tmp_path / 'short.mcap', [('/imu', 'sensor_msgs/msg/Imu', 50.0)], 1.0)
    scenario = tmp_path / 'spike.yaml'
    scenario.write_text("""
injector: {id: imu, type: imu, input_topic: /imu, output_topic: /imu_out}
faults:
  - {id: spike, injector_id: imu, start: 0.3, duration: 0.3, config: {linear_acceleration_z_bias: 10.0}}
fault_manager:
  conditions: [{topic: /imu_out, when: {field: linear_acceleration.z, above: 15.0}, code: SPIKE}]
  snapshots: {default_topics: [/imu_out], duration_sec: 0.2, duration_after_sec: 0.1}
""")
    played = tmp_path / 'played.mcap'
    play = graph.bagfault('play', str(scenario), str(bag), '--loop', '--rate', '4', '--delay', '0',
                          '--record', str(played), name='play')
    time.sleep(5.0)
    assert graph.stop(play) == 0
    passes = int(play.out_path.read_text().split(' messages in ')[1].split(' pass')[0])
    assert passes >= 3
    boxes = sorted((p.name for p in tmp_path.glob('played.blackbox.*')), key=lambda name: int(name.split('.')[3]))
    # one black box per pass that reached its confirmation (the last may have been stopped before it)
    assert boxes[:passes - 1] == [f'played.blackbox.SPIKE.{n}.mcap' for n in range(1, passes)]
    assert len(boxes) in (passes - 1, passes)
    assert [p.name for p in tmp_path.iterdir() if p.name.endswith('.partial')] == []
    for box in tmp_path.glob('played.blackbox.*'):
        assert counts(box)['/imu_out'] > 0


def test_play_waits_for_every_acknowledgement_and_says_when_a_subscriber_gave_none(graph, tmp_path: Path) -> None:
    bag = make_bag(tmp_path / 'imu.mcap', [('/sensors/imu_raw', 'sensor_msgs/msg/Imu', 50.0)], 3.0)
    play = graph.bagfault('play', str(bag), '--wait-for', '/sensors/imu_raw', name='play')
    echo = graph.peer('echo', '/sensors/imu_raw', 'sensor_msgs/msg/Imu', '--seconds', '300', name='echo')
    graph.wait_for_line(echo)
    echo.send_signal(signal.SIGSTOP)  # alive to DDS (its lease lasts 20 s) but never acknowledging again
    stopped = time.monotonic()
    try:
        assert play.wait(timeout=60) == 0
        waited = time.monotonic() - stopped
    finally:
        echo.send_signal(signal.SIGCONT)
    out = play.out_path.read_text()
    assert '/sensors/imu_raw: not every subscriber acknowledged the last messages within 5 s' in out, out
    assert waited > 5.0  # at most 3 s of bag left to play, then the whole wait for acknowledgements


PARAMETER_SCENARIO = """
injector: {id: odom, type: odom, input_topic: /odom_raw, output_topic: /odom}
faults:
  - {id: bias, injector_id: odom, active_on_startup: false, config: {x_bias: 0.5}}
"""


def _x(data: bytes) -> float:
    """pose.pose.position.x of a CDR nav_msgs/Odometry, read with rosbags."""
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_HUMBLE).deserialize_cdr(data, 'nav_msgs/msg/Odometry').pose.pose.position.x


def test_play_takes_fault_parameters_and_records_the_events_whatever_the_topics(graph, tmp_path: Path) -> None:
    bag = make_bag(tmp_path / 'rover.mcap', STREAMS, 2.0)
    scenario = tmp_path / 'bias.yaml'
    scenario.write_text(PARAMETER_SCENARIO)
    played = tmp_path / 'played.mcap'
    play = graph.bagfault('play', str(scenario), str(bag), '--rate', '2', '--delay', '1', '--record', str(played),
                          '--topics', '/odom', '--ros-args', '-p', 'bias.active:=true', '-p', 'bias.x_bias:=2.0',
                          name='play')
    assert play.wait(timeout=60) == 0, play.err_path.read_text()
    found = counts(played)
    assert set(found) == {'/odom', '/fault_injection/events'}  # the event topic whatever --topics says
    raw = {t: _x(d) for t, _, d in raw_messages(bag)['/odom_raw']}
    recorded = raw_messages(played)['/odom']
    assert len(recorded) == len(raw) == 100
    assert all(abs(_x(d) - raw[t] - 2.0) < 1e-9 for t, _, d in recorded)  # on from the first message, 2.0 not 0.5
    assert f'output    {played}  ({sum(found.values())} messages' in play.out_path.read_text()


def test_play_refuses_an_unknown_fault_parameter_in_one_line(graph, tmp_path: Path) -> None:
    bag = make_bag(tmp_path / 'rover.mcap', STREAMS, 1.0)
    scenario = tmp_path / 'bias.yaml'
    scenario.write_text(PARAMETER_SCENARIO)
    play = graph.bagfault('play', str(scenario), str(bag), '--ros-args', '-p', 'bias.y_bais:=1.0', name='play')
    assert play.wait(timeout=60) == 2
    error = play.err_path.read_text().strip()
    assert error.count('\n') == 0 and 'Traceback' not in error
    assert "'y_bais' is not a key of fault 'bias'" in error and 'x_bias' in error and 'active' in error


def test_the_players_parameter_services_answer_and_switch_a_fault(graph, tmp_path: Path) -> None:
    bag = make_bag(tmp_path / 'rover.mcap', STREAMS, 6.0)
    scenario = tmp_path / 'bias.yaml'
    scenario.write_text(PARAMETER_SCENARIO)
    played = tmp_path / 'played.mcap'
    echo = graph.peer('echo', '/odom', 'nav_msgs/msg/Odometry', '--seconds', '30', name='echo')
    graph.wait_for(echo, 'ready')
    play = graph.bagfault('play', str(scenario), str(bag), '--delay', '1', '--record', str(played), name='play')
    described = graph.call('describe-params', '/bagfault_player', 'bias.')
    assert described['bias.active']['value'] is False and described['bias.x_bias']['value'] == 0.5
    graph.wait_for_line(echo)  # playing: the switch comes after the first messages
    switched = graph.call('set-param', '/bagfault_player', 'bias.active', 'true')
    assert switched['successful'] is True
    refused = graph.call('set-param', '/bagfault_player', 'bias.nope', '1.0')
    assert refused['successful'] is False and "'nope' is not a key" in refused['reason']
    assert play.wait(timeout=60) == 0, play.err_path.read_text()
    from support.helpers import decoded

    [(switch_time, event)] = decoded(played, ['/fault_injection/events'])['/fault_injection/events']
    assert (event.fault_id, event.state, event.source) == ('bias', 'active', 'manual')
    raw = {t: _x(d) for t, _, d in raw_messages(bag)['/odom_raw']}
    shifted = {t: round(_x(d) - raw[t], 9) for t, _, d in raw_messages(played)['/odom']}
    assert {d for t, d in shifted.items() if t < switch_time} == {0.0}
    assert {d for t, d in shifted.items() if t >= switch_time} == {0.5}


def test_record_counts_what_it_lost_and_says_so(graph, tmp_path: Path) -> None:
    """A burst the recorder cannot take (it is stopped, SIGSTOP, while most of it goes by: on a loaded machine a
    burst alone sometimes was not more than it takes): what was recorded plus what it says it lost is what the
    publisher sent, per the publisher's own count (under load `play --clock --record` kept 210 of 400 messages
    of a topic and nothing said so). The count is in the summary, the output's metadata and one stderr line."""
    import json

    from mcap.reader import make_reader

    recorded = tmp_path / 'burst.mcap'
    recorder = graph.bagfault('record', '/burst', '-o', str(recorded), '--duration', '25', name='record')
    graph.wait_for(recorder, 'bagfault record ready')
    published = graph.burst_past_a_stopped_listener(recorder, '/burst')
    assert recorder.wait(timeout=60) == 0, recorder.err_path.read_text()  # type: ignore[attr-defined]
    with recorded.open('rb') as stream:
        reader = make_reader(stream)
        kept = sum(1 for _ in reader.iter_messages())
        [meta] = [m for m in reader.iter_metadata() if m.name == 'bagfault.recording']
    lost = json.loads(meta.metadata['lost']).get('/burst', 0)
    assert json.loads(meta.metadata['received']) == {'/burst': kept}
    assert kept + lost == published, (kept, lost, published)
    assert lost > 0, 'the burst was meant to be more than the recorder takes'
    out = recorder.out_path.read_text()  # type: ignore[attr-defined]
    err = recorder.err_path.read_text()  # type: ignore[attr-defined]
    assert f'{kept:>9}  /burst  (lost {lost})' in out
    assert f'bagfault: warning: the recording lost {lost} messages ({lost} of /burst)' in err


def test_play_with_clock_carries_out_a_clock_fault_and_records_what_clock_said(graph, tmp_path: Path) -> None:
    """`play --clock` with a clock fault: /clock runs 1 s behind bag time from 1.0 s to 2.0 s (its trace in the
    recording's /bagfault/clock, at the bag time it was said), the played messages keep their stamps (the
    recorded streams are the bag's), the fault's events say what /clock did."""
    from support.helpers import decoded

    bag = make_bag(tmp_path / 'rover.mcap', STREAMS, 3.0)
    scenario = tmp_path / 'clock.yaml'
    scenario.write_text('injectors:\n  - {id: clk, type: clock}\nfaults:\n'
                        '  - {id: back, injector_id: clk, start: 1.0, duration: 1.0, config: {jump_s: -1.0}}\n')
    played = tmp_path / 'played.mcap'
    play = graph.bagfault('play', str(scenario), str(bag), '--clock', '--record', str(played), '--delay', '0.5',
                          name='play')
    assert play.wait(timeout=60) == 0, play.err_path.read_text()  # type: ignore[attr-defined]
    origin = min(t for t, _, _ in raw_messages(bag)['/sensors/imu_raw'])
    said_at = {t - origin: m.clock.sec * NS + m.clock.nanosec - origin
               for t, m in decoded(played, ['/bagfault/clock'])['/bagfault/clock']}
    assert said_at[NS] == 0 and said_at[2 * NS] == 2 * NS  # the last word at each edge: the new clock
    assert all(said == bag_time - NS for bag_time, said in said_at.items() if NS <= bag_time < 2 * NS)
    assert all(said == bag_time for bag_time, said in said_at.items() if bag_time < NS or bag_time >= 2 * NS)
    assert raw_messages(played)['/sensors/imu_raw'] == raw_messages(bag)['/sensors/imu_raw']  # as in the bag
    events = [m.details for _, m in decoded(played, ['/fault_injection/events'])['/fault_injection/events']]
    assert events == [f'config={{jump_s=-1.0}}; /clock jumps by -1 s to {origin / NS:.3f} s',
                      'config={jump_s=-1.0}; /clock follows bag time again']
