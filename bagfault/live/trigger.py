"""Live half of the `trigger_service` injector: a std_srvs/srv/Trigger proxy with the anchor's meaning.

Clients call `proxy_service`; the request goes to `target_service` unless an
active fault says otherwise. `delay_ms` (longest active) delays the answer,
`force_failure` answers success=false with `failure_message` without calling
the target. A target that is not there, or does not answer within
TARGET_TIMEOUT, gives success=false with a message that says so instead of
a client that hangs.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.task import Future

from bagfault.faults.combine import strongest
from bagfault.live.ros import interface_class

if TYPE_CHECKING:
    from bagfault.live.session import LiveSession
    from bagfault.spec.model import InjectorSpec

TARGET_WAIT = 0.1  # seconds to wait for the target to be discovered
TARGET_TIMEOUT = 2.0  # seconds to wait for the target's answer
# The anchor's response texts (trigger_service_fault_injector.cpp), so clients that match on them keep working.
DEFAULT_FAILURE = 'Injected service failure'
UNAVAILABLE = 'Trigger service unavailable'
TIMEOUT = 'Trigger service timeout'


class TriggerProxy:
    """Serves proxy_service and forwards to target_service."""

    def __init__(self, node: Any, spec: InjectorSpec, session: LiveSession) -> None:
        self.node = node
        self.spec = spec
        self.session = session
        self.calls = 0
        self.in_flight = 0  # calls not answered yet
        self.stopping = False
        self._waits: list[Future] = []
        trigger = interface_class('std_srvs/srv/Trigger')
        group = ReentrantCallbackGroup()
        assert spec.proxy_service and spec.target_service
        self.client = node.create_client(trigger, spec.target_service, callback_group=group)
        self.service = node.create_service(trigger, spec.proxy_service, self.handle, callback_group=group)

    def _after(self, seconds: float, *, delay: bool = False) -> Future:
        """A future done after `seconds` of the node's clock (a fault's `delay` ends early when the proxy stops)."""
        future = Future()

        def fire() -> None:
            if not (future.done() or future.cancelled()):
                future.set_result(True)

        def release(_future: Future) -> None:
            timer.cancel()
            if timer in self.node.timers:
                self.node.destroy_timer(timer)

        timer = self.node.create_timer(seconds, fire)
        future.add_done_callback(release)
        if delay:
            self._waits = [w for w in self._waits if not w.done()] + [future]
            if self.stopping:
                fire()
        return future

    def release(self) -> None:
        """The proxy stops: calls waiting out a delay go on now, so every client gets its answer."""
        self.stopping = True
        for wait in self._waits:
            if not wait.done():
                wait.set_result(True)

    async def handle(self, request: Any, response: Any) -> Any:
        """One call: delay, forced failure, or forward; kept in the recording."""
        self.calls += 1
        self.in_flight += 1
        delay = [0]
        outcome = ['forwarded']
        try:
            answer = await self._handle(request, response, delay, outcome)
            self.session.service_call(str(self.spec.proxy_service), str(self.spec.target_service), outcome[0],
                                      bool(answer.success), str(answer.message), delay[0])
            return answer
        finally:
            self.in_flight -= 1

    async def _handle(self, request: Any, response: Any, delay: list[int], outcome: list[str]) -> Any:
        active = self.session.active_faults(self.spec.id)
        delay_ms, _ = strongest(active, 'delay_ms')
        delay[0] = int(delay_ms)
        if delay_ms > 0:
            await self._after(delay_ms / 1000.0, delay=True)
        failing = next((f for f in active if f.config.get('force_failure')), None)
        if failing is not None:
            outcome[0] = 'forced_failure'
            response.success = False
            response.message = str(failing.config.get('failure_message', DEFAULT_FAILURE))
            return response
        if not self.client.service_is_ready():
            await self._after(TARGET_WAIT)
        if not self.client.service_is_ready():
            outcome[0] = 'unavailable'
            response.success = False
            self.node.get_logger().warning(f'Trigger service {self.spec.target_service!r} is not available')
            response.message = UNAVAILABLE
            return response
        answer = self.client.call_async(request)
        done = Future()
        answer.add_done_callback(lambda _f: done.done() or done.set_result('answer'))
        timeout = self._after(TARGET_TIMEOUT)
        timeout.add_done_callback(lambda _f: done.done() or done.set_result('timeout'))
        if await done == 'timeout':
            outcome[0] = 'timeout'
            response.success = False
            self.node.get_logger().warning(f'Trigger service {self.spec.target_service!r} did not respond in time')
            response.message = TIMEOUT
            return response
        timeout.cancel()
        reply = answer.result()
        response.success = reply.success
        response.message = reply.message
        return response


class ServiceHost:
    """A second node, spun by the Python executor in its own thread, for the service proxies: their calls
    wait (delays, the target's answer) as coroutines, which the events executor of the message path cannot
    run. Its name is the proxy's with `_services`; the proxy's --ros-args apply to it but for `__node`."""

    def __init__(self, name: str, context: Any, ros_args: list[str] | None) -> None:
        import threading  # noqa: PLC0415

        from rclpy.executors import SingleThreadedExecutor  # noqa: PLC0415

        from bagfault.live.ros import make_node  # noqa: PLC0415

        kept = [a for i, a in enumerate(ros_args or []) if not _names_node(ros_args or [], i)]
        self.node = make_node(f'{name}_services', context, kept)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._spin, name='bagfault-services', daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        while not self._done.is_set():
            try:
                self.executor.spin_once(timeout_sec=0.05)
            except Exception:  # noqa: BLE001 - shutting down
                return

    def close(self) -> None:
        """Stop the thread and the node."""
        self._done.set()
        self._thread.join(timeout=2.0)
        self.executor.shutdown()
        self.node.destroy_node()


def _names_node(args: list[str], index: int) -> bool:
    """True for a `-r __node:=X` pair (either word) in ROS arguments."""
    word = args[index]
    if word.startswith(('__node:=', '__name:=')):
        return index > 0 and args[index - 1] in ('-r', '--remap')
    return word in ('-r', '--remap') and index + 1 < len(args) and args[index + 1].startswith(('__node:=', '__name:='))
