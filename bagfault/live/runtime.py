"""rclpy start-up and shut-down shared by proxy, play and record: a private context, clean stops.

SIGINT and SIGTERM set the caller's StopFlag instead of raising inside a
callback, so every command leaves its spin loop normally and finalises its
recording.
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading
from importlib import metadata
from typing import TYPE_CHECKING, Any

from bagfault import settings
from bagfault.io.types import DISTROS
from bagfault.live import require_rclpy
from bagfault.log import log

if TYPE_CHECKING:
    from collections.abc import Iterator

    from bagfault.engine.stop import StopFlag


@contextlib.contextmanager
def ros_context(stop: StopFlag, domain_id: int | None = None) -> Iterator[Any]:
    """An initialised rclpy context (on `domain_id`, else ROS_DOMAIN_ID); SIGINT, SIGTERM and SIGHUP set `stop`."""
    require_rclpy()
    import rclpy  # noqa: PLC0415
    import rclpy.context  # noqa: PLC0415
    from rclpy.signals import SignalHandlerOptions  # noqa: PLC0415

    context = rclpy.context.Context()
    rclpy.init(args=[], context=context, domain_id=domain_id,  # not sys.argv: --ros-args are per node
               signal_handler_options=SignalHandlerOptions.NO)
    previous = {}
    if threading.current_thread() is threading.main_thread():
        for number in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
            previous[number] = signal.signal(number, lambda n, _f: stop.set(signal.Signals(n).name))
    try:
        yield context
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)
        with contextlib.suppress(Exception):
            rclpy.shutdown(context=context)


def spin_until(executor: Any, stop: StopFlag, period: float = 0.05) -> None:
    """Run callbacks until `stop` is set; a failing callback is reported and the node keeps running."""
    while not stop.is_set():
        try:
            executor.spin_once(timeout_sec=period)
        except Exception:  # noqa: BLE001 - one bad callback must not take the proxy down
            log.exception('error in a callback (the proxy keeps running)')


def make_executor(context: Any, *, message_info: bool = False) -> Any:
    """The executor of a node that forwards messages: rclpy's events executor (C++ event queue, a fraction of
    the Python executor's cost per message) where this rclpy has it, else the single-threaded one.
    BAGFAULT_EXECUTOR=single forces the latter, and so does `message_info` (callbacks that take each message's
    info, its sequence number: the events executor fails on them)."""
    from rclpy.executors import SingleThreadedExecutor  # noqa: PLC0415

    if settings.executor() != 'single' and not message_info:
        try:
            from rclpy.experimental.events_executor import EventsExecutor  # noqa: PLC0415
        except ImportError:
            pass
        else:
            return EventsExecutor(context=context)
    return SingleThreadedExecutor(context=context)


def running_distro() -> str:
    """The distro of the rclpy this process runs: `ROS_DISTRO` of a sourced install, else the distro in the name
    of the installed `ros-DISTRO-rclpy` wheel; '' when neither says."""
    named = os.environ.get('ROS_DISTRO', '').strip()
    if named:
        return named
    for distro in DISTROS:
        try:
            metadata.version(f'ros-{distro}-rclpy')
        except metadata.PackageNotFoundError:
            continue
        return distro
    return ''
