"""The `bagfault` command (`bagfault` and `python -m bagfault`): the command line, loaded inside its own handling
of Ctrl-C, SIGTERM and SIGHUP, so a signal while it loads is one line and exit 2 as at any later instant."""

from __future__ import annotations

import atexit
import os
import signal
import sys

STOPPED: list[str] = []  # set when a signal came while the command line loaded


def _interrupt(number: int, _frame: object) -> None:
    raise KeyboardInterrupt(signal.Signals(number).name)


def run() -> int:
    """Load the command line and run it; a signal before it has its own handlers is said in one line."""
    for number in (signal.SIGTERM, signal.SIGHUP):  # as Ctrl-C, from here on (the command line does the same)
        signal.signal(number, _interrupt)
    try:
        from bagfault.cli import main  # noqa: PLC0415 - within the handler: a signal here is no traceback
    except (KeyboardInterrupt, RuntimeError) as caught:  # (one while a dataclass is made comes as RuntimeError)
        from bagfault.errors import interrupt_inside  # noqa: PLC0415 - loaded already, by then

        exc = interrupt_inside(caught)
        if exc is None:
            raise
        how = f'stopped by {exc}' if str(exc).startswith('SIG') else 'interrupted'
        sys.stderr.write(f'bagfault: {how}; nothing was written under the requested names\n')
        STOPPED.append(how)
        return 2
    code = main()
    for number in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):  # finished, outputs published: a signal now
        signal.signal(number, signal.SIG_IGN)  # would only turn the exit code into a death by signal
    return code


def _leave(code: int) -> None:
    """Exit with `code`. After a signal, without the interpreter's own end: under `python -m` CPython 3.10-3.11
    end a process with SIGINT when a KeyboardInterrupt went through an exec() of a string on its way (every
    dataclass is made so), however it was handled; the exit handlers still run, every file is closed already."""
    cli = sys.modules.get('bagfault.cli')
    if not (STOPPED or getattr(cli, 'INTERRUPTED', None)):
        sys.exit(code)
    sys.stdout.flush()
    sys.stderr.flush()
    atexit._run_exitfuncs()
    os._exit(code)


if __name__ == '__main__':
    _leave(run())
