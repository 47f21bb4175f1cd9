"""Every key of every section of a scenario and a campaign file, declared once.

A `Key` (bagfault/schema.py, the one declaration of a key, which the injector
and assertion types' config keys are too) says a key's type, unit, range,
default, whether it is required and what it means; spec/reader.py reads
every section by these declarations. `bagfault schema` prints these tables,
and `bagfault schema --json-schema` turns them (with the types' own keys)
into a JSON Schema an editor's YAML language server checks and completes
files with. The parsers' own key sets are
tested against these declarations (tests/spec/test_sections.py), so a key
a parser reads is a key the schema documents.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from bagfault.schema import Key, KeyType
from bagfault.units import MAX_SECONDS

Reads = Literal['anchor', 'caret', 'medkit', 'yaml']
Unknown = Literal['warn', 'error', 'ignore']
__all__ = ['Key', 'KeyType', 'Section']  # Key and KeyType: bagfault.schema's, where every key is declared


@dataclass(frozen=True)
class Section:
    """A mapping in a file: its keys, where it sits."""

    name: str
    where: str
    description: str
    keys: tuple[Key, ...] = field(default_factory=tuple)
    reads: Reads = 'yaml'  # how scalars are read (spec/reader.py)
    unknown: Unknown = 'error'  # what an undeclared key is
    noun: str = ''  # 'unknown fault key ...'

    def key(self, name: str) -> Key | None:
        """The declaration of one key."""
        return next((k for k in self.keys if k.name == name), None)


SECONDS = 'seconds of bag time'
SCENARIO = Section('scenario', '(top level)', 'A scenario file: injectors, faults, schedules, assertions.', (
    Key('name', 'string', "The scenario's name (default: the file name)."),
    Key('description', 'string', 'Free text.'),
    Key('seed', 'integer', 'Seed of every random draw; `--seed` overrides.', default=0, minimum=0,
        maximum=2**64 - 1),
    Key('bags', 'list', 'Bags the scenario is meant for, relative to the file (pytest and `test` play them).',
        what='a list of bags (files or rosbag2 folders, relative to this file)'),
    Key('msg_paths', 'list', 'Folders of .msg definitions for types the bags do not define, relative to the file.',
        what='a list of folders holding <package>/msg/<Name>.msg or .idl files'),
    Key('injectors', 'list', "The injectors (the anchor's list layouts).", section='injector',
        what='a list of injectors'),
    Key('injector', 'mapping', "One injector (the anchor's single layout); `injectors` wins when both are given.",
        section='injector'),
    Key('faults', 'list', 'The faults.', section='fault', what='a list of faults'),
    Key('assertions', 'list', "The verdicts; the keys of each type are in the assertion types' tables.",
        section='assertion', what='a list of assertions'),
    Key('fault_manager', 'mapping', "ros2_medkit's fault manager on bag time.", section='fault_manager'),
    Key('system_under_test', 'mapping', 'What `bagfault test` starts and judges.', section='system_under_test',
        what='a mapping with at least a command'),
    Key('explore', 'mapping', 'A fault space `bagfault explore` searches for failures (`run` and `test` refuse a '
        'file with one).', section='explore'),
), reads='anchor', unknown='warn', noun='top-level')
INJECTOR = Section('injector', 'injectors[]', "Which topic (or service), which type; plus its type's options.", (
    Key('id', 'string', 'Unique name; faults refer to it.', required=True),
    Key('type', 'string', 'An injector type (`bagfault schema` lists them) or one a plugin adds.', required=True),
    Key('input_topic', 'string', 'The topic read, as the bag spells it.'),
    Key('output_topic', 'string', 'Where the faulty stream goes (the input topic itself replaces it).'),
    Key('qos_depth', 'integer', 'Live mode: the history depth of the subscription and publisher.', default=10,
        minimum=1),
    Key('topic', 'mapping', "The anchor's nested layout of input_topic, output_topic and qos_depth.",
        section='topic'),
    Key('trigger_service', 'mapping', "The anchor's nested layout of a service injector.",
        section='trigger_service'),
    Key('proxy_service', 'string', 'A service injector: the service bagfault offers.'),
    Key('target_service', 'string', 'A service injector: the service it forwards to.'),
    Key('seed', 'integer', 'Accepted and ignored, as the anchor does (the scenario seed is used).', minimum=0,
        maximum=2**64 - 1),
), reads='anchor', unknown='warn', noun='injector')
TRIGGER_SERVICE = Section('trigger_service', 'injectors[].trigger_service', "The anchor's nested service block.", (
    Key('proxy_service', 'string', 'The service bagfault offers.', required=True),
    Key('target_service', 'string', 'The service it forwards to.', required=True),
), reads='anchor', unknown='warn', noun='trigger_service')
TOPIC = Section('topic', 'injectors[].topic', "The anchor's nested topic block.", (
    Key('input_topic', 'string', 'The topic read.'),
    Key('output_topic', 'string', 'Where the faulty stream goes.'),
    Key('qos_depth', 'integer', 'History depth in live mode.', default=10, minimum=1),
), reads='anchor', unknown='warn', noun='topic')
FAULT = Section('fault', 'faults[]', "What happens to an injector's stream, and when.", (
    Key('id', 'string', 'Unique name.', required=True),
    Key('injector_id', 'string', 'The injector it acts on.', required=True),
    Key('active_on_startup', 'boolean', 'Active from time zero (until `duration`).', default=False),
    Key('active', 'boolean', "The anchor's older spelling of active_on_startup."),
    Key('start', 'seconds', 'Active from this time.', unit=SECONDS, minimum=0, maximum=MAX_SECONDS),
    Key('duration', 'seconds', 'Active this long (from `start`, or from zero when active on startup).',
        unit='seconds', minimum=0, maximum=MAX_SECONDS),
    Key('config', 'mapping', "The fault config keys of its injector's type.", what='a mapping of config keys'),
    Key('repeat', 'mapping', 'On for `on` seconds every `period` seconds.', section='repeat'),
    Key('probability_per_second', 'number', 'Random activations per second (each `hold` long).', unit='1/s',
        minimum=0, exclusive=True, maximum=100),
    Key('hold', 'seconds', 'How long a random activation lasts.', unit='seconds', minimum=0.001, maximum=MAX_SECONDS),
    Key('after', 'mapping', 'Starts `delay` seconds after another fault does.', section='after'),
    Key('report', 'mapping', 'A fault manager report while it is active (the anchor ignores it).', section='report'),
), reads='anchor', unknown='warn', noun='fault')
REPEAT = Section('repeat', 'faults[].repeat', 'An intermittent fault.', (
    Key('period', 'seconds', 'Time from one activation to the next.', unit='seconds', required=True, minimum=0.01,
        maximum=MAX_SECONDS),
    Key('on', 'seconds', 'How long each activation lasts.', unit='seconds', required=True, minimum=0.001,
        maximum=MAX_SECONDS),
), reads='anchor')
AFTER = Section('after', 'faults[].after', 'A fault that follows another.', (
    Key('fault', 'string', 'The fault whose activation starts this one.', required=True),
    Key('delay', 'seconds', 'Time after that activation.', unit='seconds', default=0.0, minimum=0, maximum=MAX_SECONDS),
), reads='anchor')
ASSERTION = Section('assertion', 'assertions[]', 'A verdict; each type adds its own keys.', (
    Key('id', 'string', 'Unique name.', required=True),
    Key('type', 'string', "An assertion type (see the assertion types' tables).", required=True),
    Key('within', 'seconds', 'Deadline, seconds from time zero (the types that take one).', unit=SECONDS, minimum=0,
        maximum=MAX_SECONDS),
    Key('duration', 'seconds', 'Accepted and ignored, as the anchor does.', unit='seconds', minimum=0,
        maximum=MAX_SECONDS),
), reads='anchor', unknown='ignore')
SYSTEM = Section('system_under_test', 'system_under_test', 'The system `bagfault test` starts, feeds and judges.', (
    Key('command', 'string_or_list', "Its command line (`{python}` is bagfault's interpreter); use_sim_time is "
        'added.', required=True),
    Key('shell', 'boolean', 'Run the command string in /bin/sh.', default=False),
    Key('env', 'mapping', "Environment variables added to bagfault's.", what='a mapping of variable names to values'),
    Key('cwd', 'string', 'Working folder, relative to the scenario file.', what='a folder'),
    Key('ready', 'list', 'Conditions met, in turn, before the first message is played.', section='ready',
        what='a list of conditions'),
    Key('record', 'string_or_list', '`all`, or the topics of the system to record.', default='all'),
    Key('publishes', 'string_or_list', 'Topics of the bag the system publishes itself: bagfault does not play '
        "them, and what is judged on them is the system's (a system publishing a played topic undeclared makes "
        'the run invalid).', what='a list of topics'),
    Key('stop_timeout', 'seconds', 'SIGINT, then SIGTERM, then SIGKILL, this far apart.', unit='seconds',
        default=5.0, minimum=0, exclusive=True, maximum=3600),
    Key('use_sim_time', 'boolean', 'Add `--ros-args -p use_sim_time:=true`.', default=True),
    Key('tail', 'seconds', 'Bag time recorded after the last message, while the system answers.', unit=SECONDS,
        default=1.0, minimum=0, maximum=3600),
))
READY = Section('ready', 'system_under_test.ready[]', 'One ready condition (one of topic, subscribes, service, '
                'delay).', (
    Key('topic', 'string', 'A topic the system publishes (with `publisher: true` or `message: true`).',
        what='a topic name'),
    Key('publisher', 'boolean', 'Ready once the topic has a publisher.'),
    Key('message', 'boolean', 'Ready once a first message arrived on the topic.'),
    Key('subscribes', 'string_or_list', '`played` (every played topic), or the topics it must subscribe to.'),
    Key('service', 'string', 'A service the system must offer.', what='a service name'),
    Key('delay', 'seconds', 'Wait this long.', unit='seconds', minimum=0, maximum=3600),
    Key('timeout', 'seconds', 'Give up (exit 2) after this long.', unit='seconds', default=30.0, minimum=0,
        exclusive=True, maximum=3600),
))
THRESHOLDS = (
    Key('confirmation_threshold', 'integer', 'Debounce counter value at which a fault is CONFIRMED (negative, '
        "medkit's sign; 0 reads as -1, a positive value as its negative).", default=-1),
    Key('healing_enabled', 'boolean', 'Faults heal after enough PASSED reports.', default=False),
    Key('healing_threshold', 'integer', 'Counter value at which a fault HEALS (its absolute value).', default=3),
    Key('auto_confirm_after_sec', 'seconds', 'Confirm a PREFAILED fault after this long.', unit='seconds',
        default=0.0, minimum=0, maximum=MAX_SECONDS),
)
FAULT_MANAGER = Section('fault_manager', 'fault_manager', "ros2_medkit's fault manager semantics on bag time.", (
    *THRESHOLDS,
    Key('overrides', 'list', 'Per-source thresholds, by reporting-source prefix.', section='override',
        default=[]),
    Key('diagnostics', 'any', 'Fault codes from /diagnostics statuses: true, or {topic, codes: {NAME: CODE}}.'),
    Key('conditions', 'list', 'Fault codes from conditions on message fields.', section='condition', default=[]),
    Key('correlation', 'mapping', "Hierarchical and auto-cluster correlation (medkit's correlation block).",
        section='correlation'),
    Key('snapshots', 'mapping', 'Freeze frames and black boxes of confirmed faults.', section='snapshots'),
    Key('clear', 'list', 'ClearFault calls at given times.', section='clear', default=[]),
), noun='fault_manager')
OVERRIDE = Section('override', 'fault_manager.overrides[]', 'Thresholds of the sources under one prefix.', (
    Key('source', 'string', 'A reporting-source prefix (`/powertrain` matches `/powertrain/motor`).', required=True),
    *(Key(k.name, k.type, k.description, unit=k.unit, minimum=k.minimum, maximum=k.maximum) for k in THRESHOLDS
      if k.name != 'auto_confirm_after_sec'),
    Key('auto_confirm_after_sec', 'seconds', 'Accepted and ignored with a warning, as medkit ignores it here (timed '
        'confirmation uses the global value).', unit='seconds', minimum=0, maximum=MAX_SECONDS),
), noun='override')
DIAGNOSTICS = Section('diagnostics', 'fault_manager.diagnostics', 'Fault codes from diagnostic statuses.', (
    Key('topic', 'string', 'The DiagnosticArray topic.', default='/diagnostics'),
    Key('codes', 'mapping', 'Status names to fault codes.', default={},
        what='a mapping of status names to fault codes'),
), noun='diagnostics')
CONDITION = Section('condition', 'fault_manager.conditions[]', 'FAILED while a condition on a field holds.', (
    Key('topic', 'string', 'The topic.', required=True),
    Key('when', 'mapping', 'The condition.', required=True, section='when'),
    Key('code', 'string', 'The fault code reported.', required=True),
    Key('severity', 'any', 'INFO, WARN, ERROR, CRITICAL or 0-3.', default='ERROR'),
    Key('source', 'string', 'The reporting source (default: /bagfault/conditions<topic>).'),
), noun='condition')
WHEN = Section('when', 'fault_manager.conditions[].when', 'One of above, below, outside, not_finite on a field.', (
    Key('field', 'string', 'A field path of the message (`linear_acceleration.z`).', required=True),
    Key('above', 'number', 'Holds while the field is above this.'),
    Key('below', 'number', 'Holds while the field is below this.'),
    Key('outside', 'list', 'Holds while the field is outside [low, high].', what='[low, high]'),
    Key('not_finite', 'boolean', 'Holds while the field is NaN or infinite.'),
), noun='when')
SNAPSHOTS = Section('snapshots', 'fault_manager.snapshots', 'Freeze frames and black boxes of confirmed faults.', (
    Key('enabled', 'boolean', 'Capture snapshots.', default=True,
        what='medkit declares snapshots.enabled as a bool parameter; a quoted value is a string there'),
    Key('default_topics', 'list', 'Topics captured for any code.', what='a list of topic names'),
    Key('fault_specific', 'mapping', 'Fault codes to topic lists.', what='a mapping of fault codes to topic lists'),
    Key('patterns', 'any', 'Regular expressions of codes to topic lists ({REGEX: [topics]} or [{match, topics}]).'),
    Key('duration_sec', 'seconds', 'Black box length before confirmation.', unit='seconds', default=5.0, minimum=0,
        maximum=MAX_SECONDS),
    Key('duration_after_sec', 'seconds', 'Black box length after confirmation.', unit='seconds', default=1.0,
        minimum=0, maximum=MAX_SECONDS),
    Key('recapture_cooldown_sec', 'seconds', 'Time before one code is captured again.', unit='seconds',
        default=60.0, minimum=0, maximum=MAX_SECONDS),
), noun='snapshots')
CLEAR = Section('clear', 'fault_manager.clear[]', 'A ClearFault call.', (
    Key('code', 'string', 'The fault code cleared.', required=True),
    Key('at', 'seconds', 'When.', unit=SECONDS, required=True, minimum=0, maximum=MAX_SECONDS),
    Key('skip_correlation_auto_clear', 'boolean', "medkit's flag of the same name.", default=False),
), noun='clear')
REPORT = Section('report', 'faults[].report', 'A fault manager report made while the fault is active.', (
    Key('code', 'string', 'The fault code.', required=True),
    Key('severity', 'any', 'INFO, WARN, ERROR, CRITICAL or 0-3.', default='ERROR'),
    Key('report_period', 'seconds', 'Report again this often while active.', unit='seconds', minimum=0,
        exclusive=True, maximum=MAX_SECONDS),
    Key('source', 'string', 'The reporting source (default: /bagfault/<injector id>).', what='a non-empty source id'),
), noun='report')
UINT32 = 2**32 - 1
CORRELATION = Section('correlation', 'fault_manager.correlation', "ros2_medkit's correlation block, read as medkit "
                      'reads it (unknown keys ignored).', (
    Key('enabled', 'boolean', 'Apply the rules (a disabled block is checked with warnings only).', default=False),
    Key('default_window_ms', 'integer', 'Window of a rule that sets none.', unit='ms', default=500, minimum=1,
        maximum=UINT32),
    Key('patterns', 'mapping', 'Named code lists rules refer to: {ID: {codes: [...]}}.',
        what='a mapping of pattern ids to {codes: [...]}'),
    Key('rules', 'list', 'The rules.', section='rule', default=[]),
), reads='medkit', unknown='ignore')
RULE = Section('rule', 'fault_manager.correlation.rules[]', 'A hierarchical or auto-cluster rule.', (
    Key('id', 'string', 'Unique name.', required=True),
    Key('name', 'string', 'Display name (default: the id).'),
    Key('mode', 'string', '`hierarchical` or `auto_cluster` (and the aliases medkit takes, in any case).',
        default='hierarchical'),
    Key('window_ms', 'integer', 'Time after a root cause (or the first fault of a cluster) that counts.', unit='ms',
        minimum=1, maximum=UINT32),
    Key('root_cause', 'mapping', 'Hierarchical: {codes: [...]} of the root cause.', what='{codes: [...]}'),
    Key('symptoms', 'list', 'Hierarchical: [{pattern: ID} or {codes: [...]}].'),
    Key('mute_symptoms', 'boolean', 'Hierarchical: symptoms are muted.', default=True),
    Key('auto_clear_with_root', 'boolean', 'Hierarchical: symptoms clear with the root.', default=True),
    Key('match', 'list', 'Auto-cluster: [{pattern: ID}].'),
    Key('min_count', 'integer', 'Auto-cluster: faults that make a cluster.', default=3, minimum=1, maximum=UINT32),
    Key('show_as_single', 'boolean', 'Auto-cluster: one fault stands for the cluster.', default=True),
    Key('representative', 'string', '`first`, `most_recent` or `highest_severity` (and their aliases).',
        default='highest_severity'),
), reads='medkit', unknown='ignore')
CAMPAIGN = Section('campaign', '(top level of a campaign file)', 'Bags x fault parameters x seeds.', (
    Key('campaign', 'string', "The campaign's name (default: the file's name)."),
    Key('scenario', 'string', 'The scenario file, relative to this file.', required=True,
        what='a scenario file (relative to this file)'),
    Key('mode', 'string', '`run` (offline) or `test` (closed loop).', default='run', choices=('run', 'test')),
    Key('bags', 'list', 'Bags: files, rosbag2 folders or globs, relative to this file.', required=True,
        what='a list of bag files, rosbag2 folders or globs (relative to this file)'),
    Key('sweep', 'mapping', 'Dotted scenario paths and their values (a list or {range: [start, stop, step]}).',
        default={}, what='a mapping of dotted scenario paths to values'),
    Key('seeds', 'any', "Seeds of each point: a list or {range: [start, stop]} (default: the scenario's)."),
    Key('design', 'any', '`grid`, or {random: {samples: N, seed: S}}.', default='grid'),
    Key('search', 'mapping', 'The breaking point of one parameter per bag, by bisection.', section='search'),
    Key('keep', 'string', 'Outputs kept.', default='failed', choices=('all', 'failed', 'none')),
    Key('timeout', 'seconds', 'Time a job may take.', unit='seconds', default=3600.0, minimum=0, exclusive=True,
        maximum=86400),
))
SEARCH = Section('search', 'search', 'Bisection of one parameter.', (
    Key('parameter', 'string', 'A dotted scenario path.', required=True, what='a dotted scenario path'),
    Key('low', 'number', 'Lower end of the bracket.', required=True),
    Key('high', 'number', 'Upper end of the bracket.', required=True),
    Key('tolerance', 'number', 'Stop when the bracket is this narrow.', required=True, minimum=0, exclusive=True),
    Key('until', 'mapping', '{assertion: ID, state: passed|failed}: what counts as holding.', required=True,
        section='until'),
    Key('repeat', 'integer', 'Runs per value and seed (default 1 offline, 3 in closed loop).', minimum=1,
        maximum=100),
))

EXPLORE = Section('explore', 'explore', 'The fault space of `bagfault explore`: candidate faults whose numbers may '
                  'be dimensions, and how the search spends its runs.', (
    Key('faults', 'list', 'Candidate faults; each run draws 1 to max_faults of them.', required=True,
        section='explore_fault', what='a list of candidate faults'),
    Key('max_faults', 'integer', 'Most candidates drawn into one run (default: 3, or fewer when there are fewer).',
        minimum=1, maximum=16),
    Key('budget', 'integer', 'Runs in all, confirmations, shrinking and replays included, runs ahead of a shrink '
        'that it did not take left out (`--budget` overrides).',
        default=300, minimum=1, maximum=100_000),
    Key('confirm', 'integer', 'A run counts as failing when it fails this many runs in a row (default: 1 offline, '
        'where runs are byte-identical; 2 in closed loop).', minimum=1, maximum=20),
    Key('resolution', 'number', "Shrinking stops this close to a threshold, as a fraction of the dimension's range.",
        default=0.01, minimum=0, exclusive=True, maximum=0.5),
    Key('batch', 'integer', 'Runs the search proposes at a time: results depend on it, never on `--workers`.',
        default=4, minimum=1, maximum=256),
), noun='explore')
EXPLORE_FAULT = Section('explore_fault', 'explore.faults[]', 'A candidate fault: a fault whose numbers may be '
                        'dimensions, `[low, high]` with low the weakest value.', (
    Key('id', 'string', "Unique name (among the scenario's faults too); assertions may name it.", required=True),
    Key('injector_id', 'string', 'The injector it acts on.', required=True),
    Key('config', 'mapping', "Its injector type's config keys: a value, or `[low, high]` for a numeric key.",
        default={}, what='a mapping of config keys to values or [low, high]'),
    Key('start', 'dimension', 'Active from this time, or `[low, high]`.', unit=SECONDS, default=0.0, minimum=0,
        maximum=MAX_SECONDS),
    Key('duration', 'dimension', 'Active this long, or `[low, high]` (default: to the end of the bag).',
        unit='seconds', minimum=0, exclusive=True, maximum=MAX_SECONDS),
    Key('report', 'mapping', 'A fault manager report while it is active.', section='report'),
), noun='candidate fault')

SCENARIO_SECTIONS = (SCENARIO, INJECTOR, TOPIC, TRIGGER_SERVICE, FAULT, REPEAT, AFTER, REPORT, ASSERTION, SYSTEM,
                     READY, FAULT_MANAGER, OVERRIDE, DIAGNOSTICS, CONDITION, WHEN, SNAPSHOTS, CLEAR, CORRELATION,
                     RULE, EXPLORE, EXPLORE_FAULT)
UNTIL = Section('until', 'search.until', 'What counts as holding.', (
    Key('assertion', 'string', 'An assertion id of the scenario.', required=True),
    Key('state', 'string', 'The verdict that counts as holding.', default='passed', choices=('passed', 'failed')),
))
CAMPAIGN_SECTIONS = (CAMPAIGN, SEARCH, UNTIL)

# caret_analyze's architecture file (`--architecture`): the keys bagfault reads, as caret_analyze requires them
ARCHITECTURE = Section('architecture', '(top level of a CARET architecture file)', 'Named paths, executors, nodes.', (
    Key('named_paths', 'list', 'Paths: path_name and node_chain.', required=True, section='named_path'),
    Key('executors', 'list', 'Executors (kept, not used).', required=True),
    Key('nodes', 'list', 'Nodes: callbacks, publishes, subscribes, message contexts.', required=True,
        section='node'),
), reads='caret', unknown='ignore')
NAMED_PATH = Section('named_path', 'named_paths[]', 'A path through nodes.', (
    Key('path_name', 'any', 'Its name.', required=True),
    Key('node_chain', 'list', 'The nodes in turn: node_name, subscribe_topic_name, publish_topic_name.',
        required=True, section='chain_node'),
), reads='caret', unknown='ignore')
CHAIN_NODE = Section('chain_node', 'named_paths[].node_chain[]', 'One node of a path.', (
    Key('node_name', 'any', 'The node.', required=True),
    Key('subscribe_topic_name', 'any', 'The topic it takes (UNDEFINED: none).'),
    Key('publish_topic_name', 'any', 'The topic it gives (UNDEFINED: none).'),
), reads='caret', unknown='ignore')
NODE = Section('node', 'nodes[]', 'A node.', (
    Key('node_name', 'any', 'Its name.', required=True),
    Key('callbacks', 'list', 'Timer and subscription callbacks (others ignored).', default=[]),
    Key('callback_groups', 'list', 'Callback groups (checked, not used).', default=[]),
    Key('variable_passings', 'list', 'Callback to callback links.', default=[]),
    Key('publishes', 'list', 'Publishers: topic_name, callback_names.', default=[]),
    Key('subscribes', 'list', 'Subscriptions: topic_name, callback_name.', default=[]),
    Key('message_contexts', 'list', 'How a node passes a message on (use_latest_message, callback_chain).',
        default=[]),
), reads='caret', unknown='ignore')
CALLBACK = Section('callback', 'nodes[].callbacks[]', 'A callback (a timer one needs period_ns, a subscription one '
                   'topic_name).', (
    Key('callback_type', 'any', 'timer_callback, subscription_callback or another caret ignores.', required=True),
    Key('callback_name', 'any', 'Its name.'),
    Key('symbol', 'any', 'Its symbol.'),
    Key('period_ns', 'any', 'A timer callback: its period.'),
    Key('topic_name', 'any', 'A subscription callback: its topic.'),
), reads='caret', unknown='ignore')
CALLBACK_GROUP = Section('callback_group', 'nodes[].callback_groups[]', 'A callback group.', (
    Key('callback_group_type', 'any', 'Its type.', required=True),
    Key('callback_group_name', 'any', 'Its name.', required=True),
    Key('callback_names', 'any', 'Its callbacks.', required=True),
), reads='caret', unknown='ignore')
VARIABLE_PASSING = Section('variable_passing', 'nodes[].variable_passings[]', 'A callback writes, another reads.', (
    Key('callback_name_write', 'any', 'The writer (UNDEFINED: none).', required=True),
    Key('callback_name_read', 'any', 'The reader (UNDEFINED: none).', required=True),
), reads='caret', unknown='ignore')
PUBLISH = Section('publish', 'nodes[].publishes[]', 'A publisher.', (
    Key('topic_name', 'any', 'Its topic.', required=True),
    Key('callback_names', 'any', 'The callbacks that publish.', required=True),
), reads='caret', unknown='ignore')
SUBSCRIBE = Section('subscribe', 'nodes[].subscribes[]', 'A subscription.', (
    Key('topic_name', 'any', 'Its topic.', required=True),
    Key('callback_name', 'any', 'Its callback.', required=True),
), reads='caret', unknown='ignore')
MESSAGE_CONTEXT = Section('message_context', 'nodes[].message_contexts[]', 'How a node passes a message on.', (
    Key('context_type', 'any', 'use_latest_message, callback_chain, or UNDEFINED.', required=True),
    Key('subscription_topic_name', 'any', 'The topic taken (required unless the type is UNDEFINED).'),
    Key('publisher_topic_name', 'any', 'The topic given (required unless the type is UNDEFINED).'),
), reads='caret', unknown='ignore')
ARCHITECTURE_SECTIONS = (ARCHITECTURE, NAMED_PATH, CHAIN_NODE, NODE, CALLBACK, CALLBACK_GROUP, VARIABLE_PASSING,
                         PUBLISH, SUBSCRIBE, MESSAGE_CONTEXT)
