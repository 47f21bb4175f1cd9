"""Every key of every section of a scenario and a campaign file, declared once.

A `Key` says a key's type, unit, range, default, whether it is required
and what it means. `bagfault schema` prints these tables, and
`bagfault schema --json-schema` turns them (with the injector and assertion
types' own `ConfigField`s) into a JSON Schema an editor's YAML language
server checks and completes files with. The parsers' own key sets are
tested against these declarations (tests/spec/test_sections.py), so a key
a parser reads is a key the schema documents.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

KeyType = Literal['string', 'number', 'integer', 'boolean', 'list', 'mapping', 'string_or_list', 'seconds', 'any']


@dataclass(frozen=True)
class Key:
    """One key of a section."""

    name: str
    type: KeyType
    description: str
    unit: str = ''
    default: object = None
    required: bool = False
    minimum: float | None = None
    maximum: float | None = None
    choices: tuple[str, ...] = ()
    section: str = ''  # the section its value is (a mapping, or a list of mappings)


@dataclass(frozen=True)
class Section:
    """A mapping in a file: its keys, where it sits."""

    name: str
    where: str
    description: str
    keys: tuple[Key, ...] = field(default_factory=tuple)

    def key(self, name: str) -> Key | None:
        """The declaration of one key."""
        return next((k for k in self.keys if k.name == name), None)


SECONDS = 'seconds of bag time'
SCENARIO = Section('scenario', '(top level)', 'A scenario file: injectors, faults, schedules, assertions.', (
    Key('name', 'string', "The scenario's name (default: the file name)."),
    Key('description', 'string', 'Free text.'),
    Key('seed', 'integer', 'Seed of every random draw; `--seed` overrides.', default=0, minimum=0,
        maximum=2**64 - 1),
    Key('bags', 'list', 'Bags the scenario is meant for, relative to the file (pytest and `test` play them).'),
    Key('msg_paths', 'list', 'Folders of .msg definitions for types the bags do not define, relative to the file.'),
    Key('injectors', 'list', "The injectors (the anchor's list layouts).", section='injector'),
    Key('injector', 'mapping', "One injector (the anchor's single layout); `injectors` wins when both are given.",
        section='injector'),
    Key('faults', 'list', 'The faults.', section='fault'),
    Key('assertions', 'list', "The verdicts; the keys of each type are in the assertion types' tables.",
        section='assertion'),
    Key('fault_manager', 'mapping', "ros2_medkit's fault manager on bag time.", section='fault_manager'),
    Key('system_under_test', 'mapping', 'What `bagfault test` starts and judges.', section='system_under_test'),
))
INJECTOR = Section('injector', 'injectors[]', "Which topic (or service), which type; plus its type's options.", (
    Key('id', 'string', 'Unique name; faults refer to it.', required=True),
    Key('type', 'string', 'An injector type (`bagfault schema` lists them) or one a plugin adds.', required=True),
    Key('input_topic', 'string', 'The topic read, as the bag spells it.'),
    Key('output_topic', 'string', 'Where the faulty stream goes (the input topic itself replaces it).'),
    Key('qos_depth', 'integer', 'Live mode: the history depth of the subscription and publisher.', default=10,
        minimum=1),
    Key('topic', 'mapping', "The anchor's nested layout of input_topic, output_topic and qos_depth.",
        section='topic'),
    Key('trigger_service', 'mapping', "The anchor's nested layout of a service injector."),
    Key('proxy_service', 'string', 'A service injector: the service bagfault offers.'),
    Key('target_service', 'string', 'A service injector: the service it forwards to.'),
    Key('seed', 'integer', 'Accepted and ignored, as the anchor does (the scenario seed is used).'),
))
TOPIC = Section('topic', 'injectors[].topic', "The anchor's nested topic block.", (
    Key('input_topic', 'string', 'The topic read.'),
    Key('output_topic', 'string', 'Where the faulty stream goes.'),
    Key('qos_depth', 'integer', 'History depth in live mode.', default=10, minimum=1),
))
FAULT = Section('fault', 'faults[]', "What happens to an injector's stream, and when.", (
    Key('id', 'string', 'Unique name.', required=True),
    Key('injector_id', 'string', 'The injector it acts on.', required=True),
    Key('active_on_startup', 'boolean', 'Active from time zero (until `duration`).', default=False),
    Key('active', 'boolean', "The anchor's older spelling of active_on_startup."),
    Key('start', 'seconds', 'Active from this time.', unit=SECONDS, minimum=0, maximum=1e7),
    Key('duration', 'seconds', 'Active this long (from `start`, or from zero when active on startup).',
        unit='seconds', minimum=0, maximum=1e7),
    Key('config', 'mapping', "The fault config keys of its injector's type."),
    Key('repeat', 'mapping', 'On for `on` seconds every `period` seconds.', section='repeat'),
    Key('probability_per_second', 'number', 'Random activations per second (each `hold` long).', unit='1/s',
        minimum=0, maximum=100),
    Key('hold', 'seconds', 'How long a random activation lasts.', unit='seconds', minimum=0.001),
    Key('after', 'mapping', 'Starts `delay` seconds after another fault does.', section='after'),
    Key('report', 'any', 'Accepted and ignored, as the anchor does.'),
))
REPEAT = Section('repeat', 'faults[].repeat', 'An intermittent fault.', (
    Key('period', 'seconds', 'Time from one activation to the next.', unit='seconds', required=True, minimum=0.01),
    Key('on', 'seconds', 'How long each activation lasts.', unit='seconds', required=True, minimum=0.001),
))
AFTER = Section('after', 'faults[].after', 'A fault that follows another.', (
    Key('fault', 'string', 'The fault whose activation starts this one.', required=True),
    Key('delay', 'seconds', 'Time after that activation.', unit='seconds', default=0.0, minimum=0, maximum=1e7),
))
ASSERTION = Section('assertion', 'assertions[]', 'A verdict; each type adds its own keys.', (
    Key('id', 'string', 'Unique name.', required=True),
    Key('type', 'string', "An assertion type (see the assertion types' tables).", required=True),
))
SYSTEM = Section('system_under_test', 'system_under_test', 'The system `bagfault test` starts, feeds and judges.', (
    Key('command', 'string_or_list', "Its command line (`{python}` is bagfault's interpreter); use_sim_time is "
        'added.', required=True),
    Key('shell', 'boolean', 'Run the command string in /bin/sh.', default=False),
    Key('env', 'mapping', "Environment variables added to bagfault's."),
    Key('cwd', 'string', 'Working folder, relative to the scenario file.'),
    Key('ready', 'list', 'Conditions met, in turn, before the first message is played.', section='ready'),
    Key('record', 'string_or_list', '`all`, or the topics of the system to record.', default='all'),
    Key('stop_timeout', 'seconds', 'SIGINT, then SIGTERM, then SIGKILL, this far apart.', unit='seconds',
        default=5.0, minimum=0, maximum=3600),
    Key('use_sim_time', 'boolean', 'Add `--ros-args -p use_sim_time:=true`.', default=True),
    Key('tail', 'seconds', 'Bag time recorded after the last message, while the system answers.', unit=SECONDS,
        default=1.0, minimum=0, maximum=3600),
))
READY = Section('ready', 'system_under_test.ready[]', 'One ready condition (one of topic, subscribes, service, '
                'delay).', (
    Key('topic', 'string', 'A topic the system publishes (with `publisher: true` or `message: true`).'),
    Key('publisher', 'boolean', 'Ready once the topic has a publisher.'),
    Key('message', 'boolean', 'Ready once a first message arrived on the topic.'),
    Key('subscribes', 'string_or_list', '`played` (every played topic), or the topics it must subscribe to.'),
    Key('service', 'string', 'A service the system must offer.'),
    Key('delay', 'seconds', 'Wait this long.', unit='seconds', minimum=0, maximum=3600),
    Key('timeout', 'seconds', 'Give up (exit 2) after this long.', unit='seconds', default=30.0, minimum=0,
        maximum=3600),
))
FAULT_MANAGER = Section('fault_manager', 'fault_manager', "ros2_medkit's fault manager semantics on bag time.", (
    Key('confirmation_threshold', 'integer', 'Debounce counter value at which a fault is CONFIRMED (negative, '
        "medkit's sign).", default=-1),
    Key('healing_enabled', 'boolean', 'Faults heal after enough PASSED reports.', default=False),
    Key('healing_threshold', 'integer', 'Counter value at which a fault HEALS.', default=3),
    Key('auto_confirm_after_sec', 'number', 'Confirm a PREFAILED fault after this long.', unit='seconds',
        default=0.0, minimum=0),
    Key('overrides', 'mapping', 'Per-source thresholds, by reporting-source prefix.'),
    Key('diagnostics', 'mapping', 'Fault codes from /diagnostics statuses (`codes: {NAME: CODE}`).'),
    Key('conditions', 'list', 'Fault codes from conditions on message fields.'),
    Key('correlation', 'mapping', "Hierarchical and auto-cluster correlation (medkit's correlation block)."),
    Key('snapshots', 'mapping', 'Freeze frames and black boxes of confirmed faults.'),
    Key('clear', 'list', 'ClearFault calls at given times.'),
))
CAMPAIGN = Section('campaign', '(top level of a campaign file)', 'Bags x fault parameters x seeds.', (
    Key('campaign', 'string', "The campaign's name.", required=True),
    Key('scenario', 'string', 'The scenario file, relative to this file.', required=True),
    Key('mode', 'string', '`run` (offline) or `test` (closed loop).', default='run', choices=('run', 'test')),
    Key('bags', 'list', 'Bags: files, rosbag2 folders or globs, relative to this file.', required=True),
    Key('sweep', 'mapping', 'Dotted scenario paths and their values (a list or {range: [start, stop, step]}).'),
    Key('seeds', 'any', "Seeds of each point: a list or {range: [start, stop]} (default: the scenario's)."),
    Key('design', 'any', '`grid`, or {random: {samples: N, seed: S}}.', default='grid'),
    Key('search', 'mapping', 'The breaking point of one parameter per bag, by bisection.', section='search'),
    Key('keep', 'string', 'Outputs kept.', default='failed', choices=('all', 'failed', 'none')),
    Key('timeout', 'seconds', 'Time a job may take.', unit='seconds', default=3600, minimum=0, maximum=86400),
))
SEARCH = Section('search', 'search', 'Bisection of one parameter.', (
    Key('parameter', 'string', 'A dotted scenario path.', required=True),
    Key('low', 'number', 'Lower end of the bracket.', required=True),
    Key('high', 'number', 'Upper end of the bracket.', required=True),
    Key('tolerance', 'number', 'Stop when the bracket is this narrow.', required=True),
    Key('until', 'mapping', '{assertion: ID, state: passed|failed}: what counts as holding.', required=True),
    Key('repeat', 'integer', 'Runs per value and seed (default 1 offline, 3 in closed loop).', minimum=1,
        maximum=100),
))

SCENARIO_SECTIONS = (SCENARIO, INJECTOR, TOPIC, FAULT, REPEAT, AFTER, ASSERTION, SYSTEM, READY, FAULT_MANAGER)
CAMPAIGN_SECTIONS = (CAMPAIGN, SEARCH)
