"""Every error bagfault raises on purpose, in one tree: catch `BagfaultError` for all of them.

Each package raises its own subclass. The command line prints any of them
as one line and exits with code 2 ("could not run"); anything else that
escapes is a bug. Control-flow signals (`bagfault.engine.stop.Stopped`) are
not part of this tree.

    BagfaultError
    ├── UsageError            api/cli: a bad argument or option value
    ├── ScenarioError         scenario/: a scenario file cannot be used (every problem listed)
    ├── FieldValueError       schema.py: a config value does not fit its field
    ├── InjectorError         injectors/, faults/
    │   ├── InjectorConfigError   a cross-field check of options or a fault config failed
    │   ├── FieldPathError        a field path does not exist in a message type
    │   └── MalformedMessageError a message cannot take a fault (truncated CDR, inconsistent sizes)
    ├── EngineError           engine/: the scenario does not fit these inputs
    ├── IoError               io/
    │   ├── InputError            an input bag is missing, unreadable, corrupt or unsupported
    │   └── OutputError           an output cannot be written
    ├── AssertionSetupError   assertions/: an assertion cannot judge these topics
    ├── FaultManagerError     fault_manager/
    ├── LatencyError          latency/
    ├── LiveError             live/
    │   └── ReloadError           a reloaded scenario is refused; the running one stays
    ├── ClosedLoopError       closedloop/
    └── CampaignError         campaign/
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass


def one_line(exc: BaseException) -> str:
    """Another library's exception as one line of text (YAML and parser messages span several)."""
    return ' '.join(str(exc).split()) or type(exc).__name__


class BagfaultError(Exception):
    """A problem with the user's input, scenario, options or environment: exit code 2, one line."""


class UsageError(BagfaultError):
    """A command-line argument or API option has a value that cannot work."""


@dataclass(frozen=True)
class Problem:
    """One thing wrong in a scenario, with its place in the file."""

    file: str
    where: str
    path: str
    message: str

    def __str__(self) -> str:
        place = self.file + (f':{self.where}' if self.where else '') + (f': {self.path}' if self.path else '')
        return f'{place}: {self.message}' if place else self.message


class ScenarioError(BagfaultError):
    """A scenario cannot be used; carries every problem found, and the warnings found beside them (told with
    the errors: a misspelt key that made a fault do nothing is often why)."""

    def __init__(self, problems: list[Problem] | str, warnings: Sequence[Problem | str] = ()) -> None:
        if isinstance(problems, str):  # about no place in particular
            problems = [Problem('', '', '', problems)]
        self.problems = problems
        self.warnings = list(warnings)
        super().__init__('\n'.join(str(p) for p in problems))


class FieldValueError(BagfaultError):
    """A config value does not fit its field; the message says why."""


class InjectorError(BagfaultError):
    """An injector cannot work as configured, or a message cannot take a fault."""


class InjectorConfigError(InjectorError):
    """An injector's options or a fault config fail a cross-field check."""


class FieldPathError(InjectorError):
    """A field path is malformed or does not exist in a message type."""


class MalformedMessageError(InjectorError):
    """A message cannot be decoded or does not hold what its fault needs."""


class EngineError(BagfaultError):
    """The scenario cannot run on these inputs (wrong type, undecodable topic, ...)."""


class IoError(BagfaultError):
    """Reading or writing a bag failed."""


class InputError(IoError):
    """An input bag is missing, unreadable, corrupt or unsupported."""


class OutputError(IoError):
    """An output cannot be written."""


class AssertionSetupError(BagfaultError):
    """An assertion cannot judge the topics and types of this run."""


class FaultManagerError(BagfaultError):
    """The fault manager oracle cannot watch the topics and types of this run."""


class LatencyError(BagfaultError):
    """An architecture file or a path latency measurement cannot be used."""


class LiveError(BagfaultError):
    """Live mode cannot start or continue (rclpy missing, type not installed, bad argument)."""


class ReloadError(LiveError):
    """A reloaded scenario is invalid or changes the injector layout; the running one stays."""


class ClosedLoopError(BagfaultError):
    """The system under test cannot be started, never became ready, or cannot be stopped.

    `tail` holds the last lines the system wrote, shown under the message.
    """

    def __init__(self, message: str, *, tail: Sequence[str] = ()) -> None:
        super().__init__(message)
        self.tail = list(tail)


class CampaignError(BagfaultError):
    """A campaign file or plan cannot be used."""


class ExploreError(BagfaultError):
    """An exploration cannot start or go on (no space, no bag, a folder that holds another)."""


def interrupt_inside(exc: BaseException) -> KeyboardInterrupt | None:
    """The Ctrl-C or stop signal another exception carries as its cause or context (Python wraps an exception
    raised in __set_name__ in a RuntimeError: a signal while a module's dataclass is made arrives so), or None."""
    seen: set[int] = set()
    current: BaseException | None = exc
    while current is not None and id(current) not in seen:
        if isinstance(current, KeyboardInterrupt):
            return current
        seen.add(id(current))
        current = current.__cause__ or current.__context__
    return None
