"""Stopping a run from outside: a flag set by a signal or by the caller, and the signal it raises inside.

`StopFlag` is what a Python caller passes to `api.play`, `api.proxy`,
`api.record` or `api.test` and sets from another thread; SIGINT and SIGTERM
set the same flag. `Stopped` is a control-flow signal, not an error: a sink
raises it when the flag is set, and the run loop ends the pass there.
"""

from __future__ import annotations

import threading


class StopFlag:
    """Set once, by a signal handler or the caller; read by the loops that must end."""

    def __init__(self) -> None:
        self._event = threading.Event()
        self.reason = ''

    def set(self, reason: str = 'stop requested') -> None:
        """Ask every loop watching this flag to stop (the first reason is kept)."""
        if not self._event.is_set():
            self.reason = reason
            self._event.set()

    def is_set(self) -> bool:
        """True once the flag has been set."""
        return self._event.is_set()

    def wait(self, timeout: float) -> bool:
        """Sleep up to `timeout` seconds or until the flag is set; True if it is set."""
        return self._event.wait(timeout)


class Stopped(Exception):  # noqa: N818 - a signal, not an error
    """Raised inside a pass when its StopFlag was set; the loop finishes what it has and returns."""
