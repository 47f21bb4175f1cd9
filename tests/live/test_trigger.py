"""trigger_service_faults.yaml through `bagfault proxy` with a real Trigger server and client."""

from __future__ import annotations

import time
from pathlib import Path


def test_forced_failure_delay_and_missing_target(graph, scenarios: Path) -> None:
    proxy = graph.bagfault('proxy', str(scenarios / 'trigger.yaml'), name='proxy')
    graph.wait_for(proxy, 'bagfault proxy ready')

    # no target yet: a clear failure at once instead of a hanging client
    answer = graph.call('trigger-call', '/enable_motors')
    assert answer == {'success': False, 'message': 'Trigger service unavailable',  # the anchor's text
                      'seconds': answer['seconds']}
    assert answer['seconds'] < 1.0

    server = graph.peer('trigger-server', '/enable_motors_raw', '--message', 'motors enabled', '--seconds', '60',
                        name='server')
    graph.wait_for(server, 'ready')
    deadline = time.monotonic() + 20
    while True:  # until the proxy has discovered the target, calls fail as above
        answer = graph.call('trigger-call', '/enable_motors')
        if answer['success'] or time.monotonic() > deadline:
            break
        time.sleep(0.5)
    assert answer['success'] is True and answer['message'] == 'motors enabled'
    served_before = len(graph.lines(server))

    assert graph.call('set-param', '/bagfault', 'enable_motors_delay.active', 'true')['successful']
    answer = graph.call('trigger-call', '/enable_motors')
    assert answer['success'] is True and answer['message'] == 'motors enabled'
    assert 2.0 <= answer['seconds'] < 3.5  # delay_ms: 2000

    assert graph.call('set-param', '/bagfault', 'enable_motors_delay.active', 'false')['successful']
    assert graph.call('set-param', '/bagfault', 'enable_motors_forced_failure.active', 'true')['successful']
    answer = graph.call('trigger-call', '/enable_motors')
    assert answer['success'] is False and answer['message'] == 'Injected enable_motors failure'
    assert answer['seconds'] < 1.0
    assert len(graph.lines(server)) == served_before + 1  # the forced failure never reached the target

    changed = graph.call('set-param', '/bagfault', 'enable_motors_forced_failure.failure_message', 'motor bus down')
    assert changed['successful']
    assert graph.call('trigger-call', '/enable_motors')['message'] == 'motor bus down'
    assert graph.stop(proxy) == 0
