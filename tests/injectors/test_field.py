"""`field` injector: each operation exactly, any message type, paths checked before the run."""

from __future__ import annotations

import math
import re
import textwrap

import numpy as np
import pytest
from rosbags.typesys import Stores, get_typestore
from support.helpers import NS, decoded, make_bag, run_inline

from bagfault.demo import synthetic
from bagfault.errors import EngineError
from bagfault.faults.fieldpath import leaf_paths
from bagfault.scenario import ScenarioError, parse_scenario

START = synthetic.DEFAULT_START


@pytest.fixture(scope='module')
def bag(tmp_path_factory):
    return make_bag(tmp_path_factory.mktemp('bag') / 'in.mcap',
                    [('/odom', 'nav_msgs/msg/Odometry', 10.0), ('/scan', 'sensor_msgs/msg/LaserScan', 5.0),
                     ('/joints', 'sensor_msgs/msg/JointState', 10.0), ('/tf', 'tf2_msgs/msg/TFMessage', 10.0)],
                    6.0)


def field_run(tmp_path, bag, topic, operations, start=1.0, duration=3.0, **kw):
    text = f"""
        injector: {{id: f, type: field, input_topic: {topic}, output_topic: {topic}_out}}
        faults:
          - id: op
            injector_id: f
            start: {start}
            duration: {duration}
            config:
              operations: {operations}
    """
    out, result = run_inline(tmp_path, text, bag, **kw)
    data = decoded(out, [topic, f'{topic}_out'])
    return list(zip(data[topic], data[f'{topic}_out'], strict=True))


def inside(time):
    return 1.0 <= (time - START) / NS < 4.0


def test_add_scale_set_clamp(tmp_path, bag):
    rows = field_run(tmp_path, bag, '/odom', """
                - {op: add, path: pose.pose.position.x, value: 1.5}
                - {op: scale, path: pose.pose.position.y, value: -2.0}
                - {op: set, path: twist.twist.linear.x, value: 3.0}
                - {op: clamp, path: pose.pose.position.z, min: 0.25}""")
    for (time, a), (_, b) in rows:
        pa, pb = a.pose.pose.position, b.pose.pose.position
        if inside(time):
            assert (pb.x - pa.x, pb.y, b.twist.twist.linear.x, pb.z) == pytest.approx((1.5, -2.0 * pa.y, 3.0, 0.25))
        else:
            assert (pb.x, pb.y, pb.z, b.twist.twist.linear.x) == (pa.x, pa.y, pa.z, a.twist.twist.linear.x)


def test_noise_nan_on_arrays(tmp_path, bag):
    rows = field_run(tmp_path, bag, '/scan', """
                - {op: noise, path: 'ranges[*]', stddev: 0.1}
                - {op: nan, path: 'intensities[3]'}""")
    deltas = []
    for (time, a), (_, b) in rows:
        finite = np.isfinite(a.ranges)
        if inside(time):
            deltas += list(b.ranges[finite] - a.ranges[finite])
            assert math.isnan(b.intensities[3]) and b.intensities[2] == a.intensities[2]
        else:
            assert np.array_equal(b.ranges, a.ranges) and np.array_equal(b.intensities, a.intensities)
    assert np.std(deltas) == pytest.approx(0.1, rel=0.05)


def test_uniform_noise_stuck_drift(tmp_path, bag):
    rows = field_run(tmp_path, bag, '/joints', """
                - {op: uniform_noise, path: 'position[*]', low: -0.5, high: 0.5}
                - {op: stuck, path: 'velocity[*]'}
                - {op: drift, path: 'effort[0]', rate: 2.0}""")
    held = None
    for (time, a), (_, b) in rows:
        if inside(time):
            d = b.position - a.position
            assert np.all((d >= -0.5) & (d <= 0.5)) and np.any(d != 0)
            held = a.velocity if held is None else held
            assert np.array_equal(b.velocity, held)
            assert b.effort[0] - a.effort[0] == pytest.approx(2.0 * ((time - START) / NS - 1.0), abs=1e-9)
        else:
            assert np.array_equal(b.velocity, a.velocity)


def test_nested_array_path(tmp_path, bag):
    rows = field_run(tmp_path, bag, '/tf', "[{op: add, path: 'transforms[*].transform.translation.z', value: 0.7}]")
    for (time, a), (_, b) in rows:
        dz = [tb.transform.translation.z - ta.transform.translation.z for ta, tb in zip(a.transforms, b.transforms, strict=True)]
        assert dz == pytest.approx([0.7, 0.7] if inside(time) else [0.0, 0.0])


def test_batch_equals_per_message(tmp_path, bag):
    ops = "[{op: noise, path: 'ranges[*]', stddev: 0.1}, {op: uniform_noise, path: range_max, low: 0, high: 1}]"
    fast = field_run(tmp_path, bag, '/scan', ops)
    slow = field_run(tmp_path, bag, '/scan', ops, batch=False)
    assert [(t, list(b.ranges), b.range_max) for (t, _), (_, b) in fast] == \
           [(t, list(b.ranges), b.range_max) for (t, _), (_, b) in slow]


def test_misspelled_path_fails_validation_with_the_closest_path():
    text = textwrap.dedent("""
        injector: {id: f, type: field, input_topic: /odom, output_topic: /o, message_type: nav_msgs/msg/Odometry}
        faults:
          - {id: x, injector_id: f, config: {operations: [{op: add, path: pose.pose.postion.x, value: 1}]}}
    """)
    with pytest.raises(ScenarioError) as info:
        parse_scenario(text)
    message = str(info.value)
    assert 'faults[0].config' in message and 'nav_msgs/msg/Odometry' in message
    assert 'closest valid path: pose.pose.position.x' in message


def test_misspelled_path_fails_at_run_start_without_message_type(tmp_path, bag):
    with pytest.raises(EngineError) as info:
        field_run(tmp_path, bag, '/odom', '[{op: add, path: twist.twist.angular.zz, value: 1}]')
    assert 'nav_msgs/msg/Odometry' in str(info.value) and 'closest valid path: twist.twist.angular.z' in str(info.value)
    assert not (tmp_path / 'out.mcap').exists()


@pytest.mark.parametrize(('ops', 'problem'), [
    ('[{op: explode, path: a}]', "unknown op 'explode'"),
    ('[{op: add, path: a}]', 'add needs value'),
    ('[{op: noise, path: a, stddev: -1}]', 'stddev must be 0 or more'),
    ('[{op: clamp, path: a}]', 'clamp needs min and/or max'),
    ('[{op: set, path: a, value: 1, extra: 2}]', 'set takes value, not extra'),
    ('[{op: add, path: "a[", value: 1}]', 'is not a field name'),
])
def test_operation_structure_is_validated(ops, problem):
    text = ('injector: {id: f, type: field, input_topic: /a, output_topic: /b}\n'
            f'faults: [{{id: x, injector_id: f, config: {{operations: {ops}}}}}]\n')
    with pytest.raises(ScenarioError, match=problem.replace('[', r'\[')):
        parse_scenario(text)


def test_operation_type_checks(tmp_path, bag):
    with pytest.raises(EngineError, match=re.escape('nan needs a float field, header.stamp.sec is a int32')):
        field_run(tmp_path, bag, '/odom', '[{op: nan, path: header.stamp.sec}]')
    with pytest.raises(EngineError, match=re.escape('needs a number, header.frame_id')):
        field_run(tmp_path, bag, '/odom', '[{op: add, path: header.frame_id, value: 1}]')


def rosbags_rs_topics(external):
    bag = external / 'rosbags-rs/tests/test_bags/test_bag_mcap'
    from bagfault.io.sources import open_source

    source = open_source(bag)
    channels = list(source.channels)
    source.close()
    store = get_typestore(Stores.ROS2_FOXY)
    out = []
    for channel in channels:
        from bagfault.io.types import TypeCatalog

        codec = TypeCatalog(channels, None).codec(channel.msgtype)
        paths = leaf_paths(channel.msgtype, codec.store, numeric=True) if codec else []
        numeric = [p for p in paths if '[*]' not in p and not p.startswith('header.')]
        if numeric:
            out.append((channel.topic, channel.msgtype, numeric[0]))
    _ = store
    return bag, out


def test_field_injector_on_every_rosbags_rs_type(tmp_path, external):
    bag, cases = rosbags_rs_topics(external)
    assert len(cases) >= 60
    injectors = '\n'.join(f'  - {{id: i{n}, type: field, input_topic: {topic}, output_topic: {topic}_out}}'
                          for n, (topic, _, _) in enumerate(cases))
    faults = '\n'.join(
        f'  - {{id: f{n}, injector_id: i{n}, active_on_startup: true, '
        f'config: {{operations: [{{op: add, path: "{path}", value: 1}}]}}}}'
        for n, (_, _, path) in enumerate(cases))
    out, _ = run_inline(tmp_path, f'injectors:\n{injectors}\nfaults:\n{faults}\n', bag)
    data = decoded(out, [t for t, _, _ in cases] + [f'{t}_out' for t, _, _ in cases])

    for topic, msgtype, path in cases:
        before, after = data[topic], data[f'{topic}_out']
        assert len(before) == len(after) == 2, topic
        names = path.split('.')
        for (_, a), (_, b) in zip(before, after, strict=True):
            old, new = a, b
            for name in names:
                old, new = getattr(old, name), getattr(new, name)
            if isinstance(old, (bool, np.bool_)):
                continue  # a bool field: adding 1 sets it, which the type allows
            saturated = old == new and old in (255, 65535, 2**32 - 1, 127, 32767, 2**31 - 1, 2**63 - 1, 2**64 - 1)
            assert new - old == pytest.approx(1.0, abs=1e-3) or saturated, (topic, msgtype, path, old, new)
