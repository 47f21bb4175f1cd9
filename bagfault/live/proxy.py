"""`bagfault proxy`: run a scenario's injectors on live topics until Ctrl-C or SIGTERM."""

from __future__ import annotations

from typing import TYPE_CHECKING

from bagfault.live.runtime import StopFlag, ros_context, spin_until

if TYPE_CHECKING:
    from pathlib import Path

    from bagfault.api import RunResult
    from bagfault.scenario.model import Scenario


def run_proxy(
    scenario: Scenario,
    *,
    seed: int,
    record: Path | None = None,
    use_sim_time: bool = False,
    stop: StopFlag | None = None,
) -> RunResult:
    """Proxy until `stop` is set (by a signal or the caller); the recording is complete on return."""
    from rclpy.executors import SingleThreadedExecutor  # noqa: PLC0415

    from bagfault.api import RunResult  # noqa: PLC0415
    from bagfault.live.node import ProxyNode  # noqa: PLC0415

    stop = stop or StopFlag()
    with ros_context(stop) as context:
        proxy = ProxyNode(scenario, context, stop, seed=seed, record=record, use_sim_time=use_sim_time)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(proxy.node)
        finished = False
        try:
            proxy.setup(executor)
            spin_until(executor, stop)
            finished = True
        finally:
            if finished:
                proxy.close()
            else:
                if proxy.delay is not None:
                    proxy.delay.stop()
                if proxy.recording is not None:
                    proxy.recording.abort()
                proxy.node.destroy_node()
            executor.shutdown()
    session = proxy.session
    notes = list(scenario.warnings)
    if session is None:
        from bagfault.engine.pipeline import RunStats  # noqa: PLC0415

        return RunResult(scenario, [], None, seed, RunStats(), [*notes, f'stopped ({stop.reason}) before the proxy started'],
                         mode='proxy')
    stats = session.stats
    for topic in session.topics:
        notes.append(f'{topic.input_topic} -> {topic.output_topic}: {topic.received} received, '
                     f'{topic.forwarded} published, {topic.malformed} malformed')
    if proxy.unsent:
        notes.append(f'{proxy.unsent} delayed messages were still waiting at the stop and were not sent')
    result = RunResult(scenario, [], record, seed, stats, notes, mode='proxy')
    session.oracles.fill(result)
    return result
