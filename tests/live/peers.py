"""Separate ROS 2 processes the live tests talk to: publishers, subscribers, parameter and service clients.

    python peers.py publish-imu TOPIC --rate 200 --seconds 5
    python peers.py echo TOPIC TYPE --seconds 5 [--fields a.b c.d]   (JSON lines: receive time, fields)
    python peers.py clock-check TOPIC TYPE --seconds 10                (JSON: order of /clock and stamps)
    python peers.py imu-monitor TOPIC [--limit 0.5]                   (a system under test publishing /diagnostics)
    python peers.py set-param NODE NAME VALUE                          (prints the result)
    python peers.py describe-params NODE PREFIX                        (JSON: descriptors and values)
    python peers.py trigger-server SERVICE --message TEXT
    python peers.py trigger-call SERVICE [--timeout S]                 (prints JSON: success, message, seconds)

Each prints 'ready' on stderr once its endpoints exist.
"""

from __future__ import annotations

import argparse
import importlib
import json
import sys
import time

import rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy


def interface(name: str):
    package, kind, type_name = name.split('/')
    return getattr(importlib.import_module(f'{package}.{kind}'), type_name)


def field(message, path: str):
    value = message
    for part in path.split('.'):
        value = getattr(value, part)
    return value


def publish_imu(args) -> None:
    node = rclpy.create_node('imu_publisher')
    qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT if args.best_effort else ReliabilityPolicy.RELIABLE)
    publisher = node.create_publisher(interface('sensor_msgs/msg/Imu'), args.topic, qos)
    Imu = interface('sensor_msgs/msg/Imu')
    print('ready', file=sys.stderr, flush=True)
    if args.wait_subscriber:
        deadline = time.monotonic() + 30.0
        while not publisher.get_subscription_count() and time.monotonic() < deadline:
            rclpy.spin_once(node, timeout_sec=0.05)
        time.sleep(0.5)  # the subscriber's side of the match may come a moment later
    period = 1.0 / args.rate
    start = time.monotonic()
    k = 0
    while time.monotonic() - start < args.seconds:
        message = Imu()
        message.header.stamp = node.get_clock().now().to_msg()
        message.header.frame_id = 'imu'
        message.angular_velocity.z = 0.001 * (k % 100)
        message.linear_acceleration.z = 9.81
        message.orientation_covariance[0] = float(k)  # sequence number travels in the message
        if args.malformed_every and k % args.malformed_every == args.malformed_every - 1:
            publisher.publish(b'\x00\x01\x00\x00\xff\xff')  # truncated CDR
        else:
            publisher.publish(message)
        k += 1
        rclpy.spin_once(node, timeout_sec=0)
        if k == 1 and args.pause_after_first:  # the first heard alone: a count of losses starts from it
            print('first sent', file=sys.stderr, flush=True)
            time.sleep(args.pause_after_first)
            start += args.pause_after_first
        delay = start + k * period - time.monotonic()
        if delay > 0:
            time.sleep(delay)
    for _ in range(args.tail):  # slow messages after the rest: a listener hears these, so a loss before them
        message = Imu()                # is seen (it is counted at the next message heard)
        message.header.stamp = node.get_clock().now().to_msg()
        message.orientation_covariance[0] = float(k)
        publisher.publish(message)
        k += 1
        time.sleep(0.05)
    from rclpy.duration import Duration
    publisher.wait_for_all_acked(Duration(seconds=5))  # exiting earlier would lose what is still being resent
    print(json.dumps({'published': k}), flush=True)


def echo(args) -> None:
    node = rclpy.create_node('echo_' + args.topic.strip('/').replace('/', '_'))
    qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.BEST_EFFORT if args.best_effort else ReliabilityPolicy.RELIABLE)

    def received(message) -> None:
        row = {'t': time.time(), 'ros': node.get_clock().now().nanoseconds}
        for path in args.fields:
            value = field(message, path)
            row[path] = value if isinstance(value, (int, float, str)) else repr(value)
        print(json.dumps(row), flush=True)

    subscription = node.create_subscription(interface(args.type), args.topic, received, qos)
    print('ready', file=sys.stderr, flush=True)
    end = time.monotonic() + args.seconds
    matched = False
    while time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.05)
        if not matched and subscription.get_publisher_count():
            matched = True
            print('matched', file=sys.stderr, flush=True)  # a publisher was discovered


def clock_check(args) -> None:
    """Receive /clock and a topic; report order and how stamps relate to the clock."""
    node = rclpy.create_node('clock_check')
    state = {'clock': None, 'clock_first': None, 'clock_monotonic': True, 'messages': 0, 'in_order': True,
             'last_stamp': None, 'stamp_after_clock': 0, 'first_wall': None, 'span': 0.0, 'first_stamp': None,
             'final_stamp': None, 'clock_count': 0}

    ticked: list[float | None] = [None]  # wall time of the last /clock tick

    def on_clock(message) -> None:
        value = message.clock.sec * 1_000_000_000 + message.clock.nanosec
        if state['clock'] is not None and value < state['clock']:
            state['clock_monotonic'] = False
        if state['clock_first'] is None:
            state['clock_first'] = value
        state['clock'] = value
        state['clock_count'] += 1
        ticked[0] = time.monotonic()

    def on_message(message) -> None:
        stamp = message.header.stamp.sec * 1_000_000_000 + message.header.stamp.nanosec
        if state['last_stamp'] is not None and stamp <= state['last_stamp']:
            state['in_order'] = False
        state['last_stamp'] = stamp
        state['final_stamp'] = stamp
        if state['first_stamp'] is None:
            state['first_stamp'] = stamp
        state['messages'] += 1
        if state['first_wall'] is None:
            state['first_wall'] = time.monotonic()
        state['span'] = time.monotonic() - state['first_wall']
        if state['clock'] is None or stamp > state['clock'] + 50_000_000:
            state['stamp_after_clock'] += 1

    node.create_subscription(interface('rosgraph_msgs/msg/Clock'), '/clock', on_clock, 10)
    node.create_subscription(interface(args.type), args.topic, on_message, QoSProfile(depth=1000))
    print('ready', file=sys.stderr, flush=True)
    end = time.monotonic() + args.seconds
    while time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.05)
        if args.until_quiet and ticked[0] is not None and time.monotonic() - ticked[0] > args.until_quiet:
            break  # the clock stopped: the player is done
    for key in ('clock', 'last_stamp', 'first_wall'):
        state.pop(key)
    print(json.dumps(state), flush=True)


def imu_monitor(args) -> None:
    """A system under test: ERROR on /diagnostics while |angular_velocity.z| on TOPIC exceeds a limit."""
    node = rclpy.create_node('imu_monitor')
    Array, Status = interface('diagnostic_msgs/msg/DiagnosticArray'), interface('diagnostic_msgs/msg/DiagnosticStatus')
    publisher = node.create_publisher(Array, '/diagnostics', 10)
    last = [0.0]

    def received(message) -> None:
        if time.monotonic() - last[0] < 0.1:
            return
        last[0] = time.monotonic()
        status = Status(name='imu_monitor: drift', hardware_id='imu')
        high = abs(message.angular_velocity.z) > args.limit
        status.level = Status.ERROR if high else Status.OK
        status.message = 'yaw rate implausible' if high else 'ok'
        array = Array(status=[status])
        array.header.stamp = node.get_clock().now().to_msg()
        publisher.publish(array)

    node.create_subscription(interface('sensor_msgs/msg/Imu'), args.topic, received, 10)
    print('ready', file=sys.stderr, flush=True)
    end = time.monotonic() + args.seconds
    while time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.05)


def set_param(args) -> None:
    from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
    from rcl_interfaces.srv import SetParameters

    node = rclpy.create_node('param_client')
    client = node.create_client(SetParameters, f'{args.node}/set_parameters')
    if not client.wait_for_service(timeout_sec=20.0):
        print(json.dumps({'error': 'no parameter service'}), flush=True)
        return
    value = ParameterValue()
    raw = args.value
    if raw in ('true', 'false'):
        value.type, value.bool_value = ParameterType.PARAMETER_BOOL, raw == 'true'
    else:
        try:
            value.type, value.integer_value = ParameterType.PARAMETER_INTEGER, int(raw)
        except ValueError:
            try:
                value.type, value.double_value = ParameterType.PARAMETER_DOUBLE, float(raw)
            except ValueError:
                value.type, value.string_value = ParameterType.PARAMETER_STRING, raw
    request = SetParameters.Request(parameters=[Parameter(name=args.name, value=value)])
    future = client.call_async(request)
    rclpy.spin_until_future_complete(node, future, timeout_sec=20.0)
    result = future.result().results[0]
    print(json.dumps({'successful': result.successful, 'reason': result.reason, 't': time.time()}), flush=True)


def describe_params(args) -> None:
    """List a node's parameters under a prefix and describe them (what rqt_reconfigure does)."""
    from rcl_interfaces.srv import DescribeParameters, GetParameters, ListParameters

    node = rclpy.create_node('param_lister')
    clients = {name: node.create_client(kind, f'{args.node}/{name}') for name, kind in
               (('list_parameters', ListParameters), ('describe_parameters', DescribeParameters),
                ('get_parameters', GetParameters))}
    for client in clients.values():
        client.wait_for_service(timeout_sec=20.0)

    def call(name, request):
        future = clients[name].call_async(request)
        rclpy.spin_until_future_complete(node, future, timeout_sec=20.0)
        return future.result()

    names = [n for n in call('list_parameters', ListParameters.Request()).result.names if n.startswith(args.prefix)]
    described = call('describe_parameters', DescribeParameters.Request(names=names)).descriptors
    values = call('get_parameters', GetParameters.Request(names=names)).values
    out = {}
    for name, descriptor, value in zip(names, described, values, strict=True):
        ranges = [[r.from_value, r.to_value] for r in descriptor.floating_point_range]
        ranges += [[r.from_value, r.to_value] for r in descriptor.integer_range]
        current = {1: value.bool_value, 2: value.integer_value, 3: value.double_value, 4: value.string_value}.get(value.type)
        out[name] = {'type': descriptor.type, 'description': descriptor.description, 'ranges': ranges,
                     'read_only': descriptor.read_only, 'value': current}
    print(json.dumps(out), flush=True)


def trigger_server(args) -> None:
    Trigger = interface('std_srvs/srv/Trigger')
    node = rclpy.create_node('trigger_server')
    calls = []

    def serve(request, response):
        calls.append(time.time())
        response.success = True
        response.message = args.message
        print(json.dumps({'served': len(calls), 't': calls[-1]}), flush=True)
        return response

    node.create_service(Trigger, args.service, serve)
    print('ready', file=sys.stderr, flush=True)
    end = time.monotonic() + args.seconds
    while time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.05)


def trigger_call(args) -> None:
    Trigger = interface('std_srvs/srv/Trigger')
    node = rclpy.create_node('trigger_client')
    client = node.create_client(Trigger, args.service)
    if not client.wait_for_service(timeout_sec=20.0):
        print(json.dumps({'error': 'service not available'}), flush=True)
        return
    started = time.monotonic()
    future = client.call_async(Trigger.Request())
    rclpy.spin_until_future_complete(node, future, timeout_sec=args.timeout)
    seconds = time.monotonic() - started
    if not future.done():
        print(json.dumps({'error': 'no answer', 'seconds': seconds}), flush=True)
        return
    response = future.result()
    print(json.dumps({'success': response.success, 'message': response.message, 'seconds': seconds}), flush=True)


def anchor_calls(args) -> None:
    """Call the anchor's nine services in a fixed order; print each answer as a JSON line."""
    names = ['ListFaults', 'SetFaultState', 'SetFaultState', 'GetFaultStatus', 'SetFaultConfig', 'SetFaultConfig',
             'GetFaultConfig', 'GetFaultSchema', 'GetScenario', 'RequestReport', 'ReloadScenario', 'ListFaults']
    fault = args.fault
    requests = [{}, {'fault_id': 'no_such_fault', 'active': True}, {'fault_id': fault, 'active': True}, {},
                {'fault_id': fault, 'key': 'gain', 'value': '2'},
                {'fault_id': fault, 'key': 'angular_velocity_z_bias', 'value': '0.2'}, {'fault_id': fault},
                {'fault_id': fault}, {}, {}, {}, {}]
    node = rclpy.create_node('anchor_client')
    for name, fields in zip(names, requests, strict=True):
        kind = interface(f'ros2_fault_injection/srv/{name}')
        snake = ''.join(f'_{c.lower()}' if c.isupper() else c for c in name).lstrip('_')
        client = node.create_client(kind, f'/fault_injection/{snake}')
        if not client.wait_for_service(timeout_sec=20.0):
            print(json.dumps({'service': name, 'error': 'not available'}), flush=True)
            return
        future = client.call_async(kind.Request(**fields))
        rclpy.spin_until_future_complete(node, future, timeout_sec=20.0)
        answer = future.result()
        row = {'service': name}
        for slot in answer.get_fields_and_field_types():
            value = getattr(answer, slot)
            if slot == 'faults':
                value = [{'fault_id': f.fault_id, 'injector_id': f.injector_id, 'state': f.state, 'details': f.details}
                         for f in value]
            elif not isinstance(value, (str, bool, int, float)):
                value = list(value)
            row[slot] = value
        print(json.dumps(row), flush=True)


def main() -> None:
    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers(dest='command', required=True)
    p = sub.add_parser('publish-imu')
    p.add_argument('topic')
    p.add_argument('--rate', type=float, default=200.0)
    p.add_argument('--seconds', type=float, default=5.0)
    p.add_argument('--best-effort', action='store_true')
    p.add_argument('--malformed-every', type=int, default=0)
    p.add_argument('--wait-subscriber', action='store_true', help='start once a subscriber is matched')
    p.add_argument('--pause-after-first', type=float, default=0.0, help='seconds between the first and the rest')
    p.add_argument('--tail', type=int, default=0, help='messages at 20 Hz after the rest')
    p = sub.add_parser('echo')
    p.add_argument('topic')
    p.add_argument('type')
    p.add_argument('--seconds', type=float, default=5.0)
    p.add_argument('--fields', nargs='*', default=[])
    p.add_argument('--best-effort', action='store_true')
    p = sub.add_parser('clock-check')
    p.add_argument('topic')
    p.add_argument('type')
    p.add_argument('--seconds', type=float, default=10.0)
    p.add_argument('--until-quiet', type=float, default=0.0, help='end once /clock was silent this long')
    p = sub.add_parser('imu-monitor')
    p.add_argument('topic')
    p.add_argument('--limit', type=float, default=0.5)
    p.add_argument('--seconds', type=float, default=20.0)
    p = sub.add_parser('set-param')
    p.add_argument('node')
    p.add_argument('name')
    p.add_argument('value')
    p = sub.add_parser('describe-params')
    p.add_argument('node')
    p.add_argument('prefix')
    p = sub.add_parser('trigger-server')
    p.add_argument('service')
    p.add_argument('--message', default='motors enabled')
    p.add_argument('--seconds', type=float, default=30.0)
    p = sub.add_parser('trigger-call')
    p.add_argument('service')
    p.add_argument('--timeout', type=float, default=10.0)
    p = sub.add_parser('anchor-calls')
    p.add_argument('fault')
    args = parser.parse_args()
    rclpy.init()
    try:
        {'publish-imu': publish_imu, 'echo': echo, 'clock-check': clock_check, 'imu-monitor': imu_monitor, 'set-param': set_param, 'trigger-server': trigger_server,
         'trigger-call': trigger_call, 'describe-params': describe_params, 'anchor-calls': anchor_calls}[args.command](args)
    finally:
        rclpy.try_shutdown()


if __name__ == '__main__':
    main()
