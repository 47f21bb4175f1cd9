"""The `system_under_test:` section: what `bagfault test` starts, when it is ready, what it records.

    system_under_test:
      command: ['{python}', monitor.py]   # a list, or a string split like a shell would (run without one)
      shell: false                        # true: the string runs in /bin/sh
      env: {MONITOR_LIMIT: '0.05'}
      cwd: .                              # relative to the scenario file
      ready:                              # all of them, each with its own timeout (seconds, default 30)
        - {topic: /diagnostics, publisher: true}
        - {topic: /diagnostics, message: true}
        - {subscribes: played}            # or a list of topics the system must subscribe to
        - {service: /enable_motors}
        - {delay: 1.5}
      record: all                         # or a list of topics the system publishes
      stop_timeout: 5.0                   # SIGINT, then SIGTERM, then SIGKILL, this long apart
      use_sim_time: true                  # pass `--ros-args -p use_sim_time:=true` (ros2 launch: use_sim_time:=true)
      tail: 1.0                           # seconds of bag time recorded after the last message

`{python}` in the command is the interpreter running bagfault. Without
`ready`, the system is ready once it subscribes to a topic the bag plays
and every such subscription is matched (at most 30 s).
"""

from __future__ import annotations

import shlex
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from bagfault.spec import sections
from bagfault.spec.names import absolute_topic
from bagfault.spec.reader import Read, Reader

if TYPE_CHECKING:
    from collections.abc import Callable, Mapping

    from bagfault.spec.yamlnodes import PathKey

ReadyKind = Literal['publisher', 'message', 'subscribes', 'service', 'delay', 'default']
DEFAULT_TIMEOUT = 30.0


@dataclass(frozen=True)
class ReadyCondition:
    """One thing the system must show before the bag starts playing."""

    kind: ReadyKind
    name: str = ''  # topic or service
    topics: tuple[str, ...] | Literal['played'] = 'played'  # for `subscribes`
    seconds: float = 0.0  # for `delay`
    timeout: float = DEFAULT_TIMEOUT

    def describe(self) -> str:
        """What is awaited, for messages."""
        if self.kind == 'publisher':
            return f'a publisher on {self.name}'
        if self.kind == 'message':
            return f'a first message on {self.name}'
        if self.kind == 'service':
            return f'the service {self.name}'
        if self.kind == 'delay':
            return f'{self.seconds:g} s'
        if self.kind == 'subscribes':
            which = 'every played topic' if self.topics == 'played' else ', '.join(self.topics)
            return f'subscriptions to {which}'
        return 'a matched subscription to a topic the bag plays'


@dataclass
class SystemUnderTest:
    """How to start, wait for, record and stop the system under test."""

    command: list[str] = field(default_factory=list)
    shell: bool = False
    env: dict[str, str] = field(default_factory=dict)
    cwd: Path | None = None
    ready: list[ReadyCondition] = field(default_factory=list)
    record: list[str] | Literal['all'] = 'all'
    publishes: list[str] = field(default_factory=list)  # topics of the bag the system publishes: not played
    stop_timeout: float = 5.0
    use_sim_time: bool = True
    tail: float = 1.0

    def conditions(self) -> list[ReadyCondition]:
        """The ready conditions, or the default one."""
        return self.ready or [ReadyCondition('default')]



def parse_system(node: object, path: PathKey, problem: Callable[[PathKey, str], None],
                 base: Path | None) -> SystemUnderTest | None:
    """Check and read the section; every problem reported at its place."""
    read = Reader(problem).read(sections.SYSTEM, node, path)
    if read is None:
        return None
    system = SystemUnderTest(shell=read.get('shell'), stop_timeout=read.get('stop_timeout'),
                             tail=read.get('tail'), use_sim_time=read.get('use_sim_time'))
    system.command = _command(read, system.shell, path, problem)
    system.env = _env(read.get('env', {}), path, problem)
    if 'cwd' in read:
        system.cwd = (base / read.get('cwd')) if base is not None else Path(read.get('cwd'))
    system.ready = [c for i, item in enumerate(read.get('ready', []))
                    if (c := _condition(item, (*path, 'ready', i), problem))]
    system.record = _record(read.get('record'), path, problem)
    system.publishes = _publishes(read.get('publishes', []), path, problem)
    return system


def _record(record: object, path: PathKey, problem: Callable[[PathKey, str], None]) -> Literal['all'] | list[str]:
    """What `test` records of the system: 'all' or a list of topics (a problem and 'all' for anything else)."""
    if record == 'all':
        return 'all'
    if isinstance(record, list) and all(isinstance(t, str) and t for t in record):
        return list(record)
    problem((*path, 'record'), "must be 'all' or a list of topics")
    return 'all'


def _publishes(publishes: object, path: PathKey, problem: Callable[[PathKey, str], None]) -> list[str]:
    """The topics the system publishes, made absolute (a problem and none for anything but topics)."""
    publishes = [publishes] if isinstance(publishes, str) else publishes
    if isinstance(publishes, list) and all(isinstance(t, str) and t.strip() for t in publishes):
        return [absolute_topic(t) for t in publishes]
    problem((*path, 'publishes'), 'must be a topic or a list of topics')
    return []


def _command(read: Read, shell: bool, path: PathKey, problem: Callable[[PathKey, str], None]) -> list[str]:
    """The command line: one string for the shell, else split as a shell would (or given as a list)."""
    command = read.get('command')
    argv = _argv(command, shell)
    if argv is None:
        argv = []
        if 'command' in read.given:
            problem((*path, 'command'), 'must be a command line: a string or a list of arguments')
    if any('\0' in part for part in argv):
        problem((*path, 'command'), 'holds a NUL character, which no command line can carry')
    return argv


def _argv(command: object, shell: bool) -> list[str] | None:
    """A command's arguments (one string for the shell), or None when it is no command line."""
    if isinstance(command, str) and command.strip():
        return [command] if shell else shlex.split(command)
    if isinstance(command, list) and command and all(isinstance(c, (str, int, float)) for c in command):
        return [str(c) for c in command]
    return None


def _env(env: dict[Any, Any], path: PathKey, problem: Callable[[PathKey, str], None]) -> dict[str, str]:
    """Variables the system gets beside bagfault's environment (values as text)."""
    if not all(isinstance(k, str) and isinstance(v, (str, int, float, bool)) for k, v in env.items()):
        problem((*path, 'env'), f'must be {sections.SYSTEM.key("env").what}')  # type: ignore[union-attr]
        return {}
    out = {k: _text(v) for k, v in env.items()}
    for name, value in out.items():
        if not name or '=' in name or '\0' in name:
            problem((*path, 'env', name), 'not a variable name (empty, or holds = or NUL)')
        elif '\0' in value:
            problem((*path, 'env', name), 'the value holds a NUL character, which no environment can carry')
    return out


def _condition(item: object, path: PathKey, problem: Callable[[PathKey, str], None]) -> ReadyCondition | None:
    if not isinstance(item, dict):
        problem(path, 'must be a mapping such as {topic: /x, publisher: true}, {subscribes: played}, '
                      '{service: /s} or {delay: 1.0}')
        return None
    read = Reader(problem).read(sections.READY, item, path)
    assert read is not None
    timeout = read.get('timeout')
    if 'topic' in read.given:
        if 'topic' not in read:
            return None
        kind: ReadyKind = 'message' if read.get('message') else 'publisher'
        return ReadyCondition(kind, name=read.get('topic'), timeout=timeout)
    if 'subscribes' in read.given:
        return _subscribes(read.get('subscribes'), timeout, path, problem)
    if 'service' in read.given:
        return ReadyCondition('service', name=read.get('service'), timeout=timeout) if 'service' in read else None
    if 'delay' in read.given:
        return ReadyCondition('delay', seconds=read.get('delay', 0.0))
    problem(path, 'needs one of topic, subscribes, service or delay')
    return None


def _subscribes(value: object, timeout: float, path: PathKey, problem: Callable[[PathKey, str], None],
                ) -> ReadyCondition | None:
    """Ready once the system subscribes to what is played, or to the topics listed."""
    if value == 'played':
        return ReadyCondition('subscribes', timeout=timeout)
    if isinstance(value, list) and value and all(isinstance(t, str) for t in value):
        return ReadyCondition('subscribes', topics=tuple(value), timeout=timeout)
    problem((*path, 'subscribes'), "must be 'played' or a list of topics")
    return None


def _text(value: object) -> str:
    if isinstance(value, bool):
        return 'true' if value else 'false'
    return str(value)


def ready_spec(text: str) -> dict[str, object]:
    """A `--ready` value as its YAML form: publisher:/t, message:/t, subscribes:played|/a,/b, service:/s,
    delay:1.5, each optionally followed by @TIMEOUT (seconds)."""
    body, _, timeout = text.partition('@')
    kind, _, value = body.partition(':')
    node: dict[str, object]
    if kind in ('publisher', 'message'):
        node = {'topic': value, kind: True}
    elif kind == 'subscribes':
        node = {'subscribes': 'played' if value in ('', 'played') else value.split(',')}
    elif kind == 'service':
        node = {'service': value}
    elif kind == 'delay':
        node = {'delay': _number(value)}
    else:
        node = {kind: value}  # reported as unknown by the check
    if timeout:
        node['timeout'] = _number(timeout)
    return node


def _number(text: str) -> object:
    try:
        return float(text)
    except ValueError:
        return text


def system_from(node: object, overrides: Mapping[str, object], problem: Callable[[PathKey, str], None],
                base: Path | None) -> SystemUnderTest | None:
    """The scenario's section (a mapping or None) with command-line values in place of its keys; `env`
    values are added to the scenario's."""
    merged: dict[str, object] = dict(node) if isinstance(node, dict) else {}
    for key, value in overrides.items():
        if key == 'env' and isinstance(value, dict) and isinstance(merged.get('env'), dict):
            merged['env'] = {**merged['env'], **value}  # type: ignore[dict-item]
        else:
            merged[key] = value
    if not merged:
        problem(('system_under_test',), 'bagfault test needs a system under test: a `system_under_test:` '
                                        'section with a command, or --command')
        return None
    return parse_system(merged, ('system_under_test',), problem, base)


def command_line(system: SystemUnderTest, python: str) -> list[str]:
    """The argv to start (or the one shell string): `{python}` replaced, `use_sim_time` added where it
    applies (`use_sim_time:=true` to `ros2 launch`, `--ros-args -p use_sim_time:=true` to a node)."""
    argv = [part.replace('{python}', shlex.quote(python) if system.shell else python) for part in system.command]
    if not system.use_sim_time:
        return argv
    words = shlex.split(argv[0]) if system.shell else argv
    launch = len(words) > 1 and Path(words[0]).name == 'ros2' and words[1] == 'launch'
    extra = ['use_sim_time:=true'] if launch else ['--ros-args', '-p', 'use_sim_time:=true']
    if system.shell:
        return [f'{argv[0]} {" ".join(extra)}']
    return [*argv, *extra]
