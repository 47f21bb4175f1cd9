"""`bagfault proxy`: run a scenario's injectors on live topics until Ctrl-C, SIGTERM or `stop.set()`."""

from __future__ import annotations

import contextlib
from typing import TYPE_CHECKING

from bagfault.engine.result import RunResult, RunStats
from bagfault.live.node import DRAIN, ProxyNode
from bagfault.live.runtime import make_executor, ros_context, spin_until

if TYPE_CHECKING:
    from pathlib import Path

    from bagfault.engine.stop import StopFlag
    from bagfault.live.viewing import OpenView
    from bagfault.spec.model import Scenario


def run_proxy(
    scenario: Scenario,
    *,
    seed: int,
    stop: StopFlag,
    record: Path | None = None,
    use_sim_time: bool = False,
    ros_args: list[str] | None = None,
    view: OpenView | None = None,
) -> RunResult:
    """Proxy until `stop` is set (by a signal or the caller); the recording is complete on return."""


    with ros_context(stop) as context, ProxyNode(scenario, context, stop, seed=seed, record=record,
                                                 use_sim_time=use_sim_time, ros_args=ros_args,
                                                 view=view) as proxy:
        executor = make_executor(context, message_info=record is not None)
        executor.add_node(proxy.node)
        with contextlib.ExitStack() as spinning:
            spinning.callback(executor.shutdown)
            proxy.setup(executor)
            spin_until(executor, stop)
            proxy.drain()
        proxy.close()
        proxy.close_view()
    if proxy.failure is not None:
        raise proxy.failure
    session = proxy.session
    if session is None:
        return RunResult(scenario, [], None, seed, RunStats(), [f'stopped ({stop.reason}) before the proxy started'],
                         list(scenario.warnings), mode='proxy')
    result = session.run.result('proxy', [], record, seed)
    lost = proxy.lost()
    for topic in session.topics:
        result.notes.append(f'{topic.input_topic} -> {topic.output_topic}: {topic.received} received'
                            + (f' ({lost[topic.input_topic]} lost before)' if lost.get(topic.input_topic) else '')
                            + f', {topic.forwarded} published, {topic.malformed} malformed')
    if lost:
        listed = ', '.join(f'{count} of {topic}' for topic, count in lost.items())
        result.warnings.append(f'the proxy lost {sum(lost.values())} input messages before it heard them ({listed}): '
                               'neither forwarded nor recorded (a deeper qos_depth, or fewer topics per proxy)')
    if proxy.unacknowledged:
        result.notes.append(f'{", ".join(proxy.unacknowledged)}: not every subscriber acknowledged the last messages '
                            f'within {DRAIN:g} s of the stop (they may have missed them)')
    if proxy.early:
        result.notes.append(f'{proxy.early} delayed messages were still waiting {DRAIN:g} s after the stop and '
                            'were published then, before their time')
    return result
