"""Injectors that act on the system under test and its clock (`process`, `clock`): schema here, acts in the loop.

Their faults are scheduled as every other fault; what a change does (a signal
to a process, a warp of /clock) needs a running system, so the closed loop
(`bagfault test`) carries them out when their events come due, and `play
--clock` the clock's. Offline they are refused: there is nothing to act on.
"""

from __future__ import annotations

from typing import Any, ClassVar

from bagfault.errors import InjectorConfigError
from bagfault.schema import Key, boolean, choice, double

SIGNALS = ('SIGKILL', 'SIGTERM', 'SIGINT', 'SIGQUIT', 'SIGABRT', 'SIGSEGV', 'SIGHUP')
MAX_JUMP = 3600.0  # seconds a clock jump may move the clock, either way


class SystemInjector:
    """Base of injectors whose faults act on the running system, not on a stream of messages."""

    type_name: ClassVar[str] = ''
    description: ClassVar[str] = ''
    fields: ClassVar[tuple[Key, ...]] = ()
    options: ClassVar[tuple[Key, ...]] = ()
    actions: ClassVar[tuple[str, ...]] = ()  # config keys of which a fault sets exactly one
    live_only: ClassVar[bool] = True
    message_types: ClassVar[tuple[str, ...]] = ()
    acts_on: ClassVar[str] = 'system'  # what a mode must offer: 'system' (a running system) or 'clock' (its /clock)
    needs: ClassVar[str] = 'a running system (`bagfault test`)'

    @classmethod
    def check_options(cls, options: dict[str, Any]) -> None:
        """Cross-field checks of injector options."""

    @classmethod
    def check_fault(cls, config: dict[str, Any], options: dict[str, Any]) -> None:
        """Exactly one action per fault."""
        chosen = [key for key in cls.actions if key in config and config[key] is not False]
        if len(chosen) != 1:
            raise InjectorConfigError(f'a {cls.type_name} fault sets exactly one of {", ".join(cls.actions)} '
                                      f'({"none" if not chosen else ", ".join(chosen)} given)')

    @classmethod
    def check_schedule(cls, config: dict[str, Any], has_end: bool) -> str | None:
        """A problem of a fault whose schedule has no end (`has_end` False), else None."""
        return None

    @classmethod
    def field(cls, key: str) -> Key | None:
        """Schema entry for a fault config key."""
        return next((x for x in cls.fields if x.name == key), None)


class ProcessInjector(SystemInjector):
    """Pause, kill (and restart) or starve a process of the system under test for the fault's window."""

    type_name = 'process'
    description = ('A process of the system under test: paused (SIGSTOP/SIGCONT), killed (and restarted at the end '
                   'of the window) or held to a fraction of a core for the window (`bagfault test` only).')
    options: ClassVar[tuple[Key, ...]] = (
        Key('target', 'target', "Which process: 'system' (the whole tree), {node: /NAME} (the process "
                    'hosting that node) or {command: REGEX} (command lines of the tree that match).', required=True),
    )
    fields: ClassVar[tuple[Key, ...]] = (
        boolean('pause', 'SIGSTOP at the start of the window, SIGCONT at its end: the process misses the window.'),
        boolean('kill', 'Send `signal` at the start of the window.'),
        choice('signal', 'The signal a kill sends.', SIGNALS),
        boolean('restart', 'A killed process starts again at the end of the window (at once without one), with its '
                'command line, environment and working directory.'),
        double('cpu_limit', 'At most this fraction of one core for the window (cgroup v2 cpu.max where writable, '
               'else a SIGSTOP/SIGCONT duty cycle; 1.0: no limit).', 1.0, minimum=0.01, maximum=1.0),
    )
    actions = ('pause', 'kill', 'cpu_limit')

    @classmethod
    def check_fault(cls, config: dict[str, Any], options: dict[str, Any]) -> None:
        """One action; signal and restart only with kill; the whole system is not killed for good."""
        super().check_fault(config, options)
        for key in ('signal', 'restart'):
            if key in config and not config.get('kill'):
                raise InjectorConfigError(f'{key} goes with kill: true')
        if config.get('kill') and options.get('target') == 'system' and not config.get('restart'):
            raise InjectorConfigError('kill of the whole system without restart: true would end the run, not '
                                      'fault it (kill one process, or restart it)')


class ClockInjector(SystemInjector):
    """Stall, jump or slow the /clock the system follows, for the fault's window."""

    type_name = 'clock'
    description = ('The /clock the system under test follows: stalled (nothing played meanwhile), jumped by '
                   '`jump_s` or run at `rate` x bag time for the window (`bagfault test`, `play --clock`).')
    fields: ClassVar[tuple[Key, ...]] = (
        boolean('stall', 'The clock stands still for the window while nothing is played, then goes on.'),
        double('jump_s', 'The clock jumps by this many seconds (negative: back) at the start of the window and '
               'back at its end.', 0.0, minimum=-MAX_JUMP, maximum=MAX_JUMP),
        double('rate', 'The clock runs at this factor of bag time for the window, then jumps back to it.', 1.0,
               minimum=0.01, maximum=100.0),
    )
    actions = ('stall', 'jump_s', 'rate')
    acts_on = 'clock'
    needs = 'a /clock bagfault publishes (`bagfault test`, `play --clock`)'

    @classmethod
    def check_schedule(cls, config: dict[str, Any], has_end: bool) -> str | None:
        """A stall needs an end: without one nothing would ever be played again."""
        if config.get('stall') and not has_end:
            return 'a clock stall needs a duration (nothing is played while it lasts)'
        return None

