"""bagfault's diagnostics go through `logging` (the `bagfault` logger); the command line shows them.

A library prints nothing: what the API has to say (a plugin that failed to
load, the address of a view, the domain a system under test runs on) is a
log record. The CLI's `console` shows records below WARNING on stdout and
the rest on stderr, each as `bagfault: message`; a program using the API
configures logging as it likes (pytest shows the records with a test).
"""

from __future__ import annotations

import logging
import sys

LOGGER = 'bagfault'
log = logging.getLogger(LOGGER)
log.addHandler(logging.NullHandler())


class _Console(logging.StreamHandler):  # type: ignore[type-arg]
    """Writes to sys.stdout or sys.stderr as they are when a record comes (a test may have replaced them)."""

    def __init__(self, which: str) -> None:
        self.which = which
        super().__init__()

    @property
    def stream(self) -> object:
        """The current stream of that name."""
        return getattr(sys, self.which)

    @stream.setter
    def stream(self, _value: object) -> None:
        pass


def console(*, debug: bool = False) -> None:
    """Show the `bagfault` logger's records: info on stdout, warnings and errors on stderr (once per process)."""
    if any(isinstance(h, _Console) for h in log.handlers):
        return
    form = logging.Formatter('bagfault: %(message)s')
    out, err = _Console('stdout'), _Console('stderr')
    out.addFilter(lambda record: record.levelno < logging.WARNING)
    err.setLevel(logging.WARNING)
    for handler in (out, err):
        handler.setFormatter(form)
        log.addHandler(handler)
    log.setLevel(logging.DEBUG if debug else logging.INFO)
