"""The registries of built-in injector and assertion types are tables of names, each type's module imported when
a scenario names it: every type is listed under its own name, and a run loads only the types it uses."""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest
from support.helpers import FIXTURES

from bagfault.assertions.registry import ASSERTION_TYPES
from bagfault.injectors.registry import BUILTIN
from bagfault.types_by_name import TypesByName

PACKAGE = Path(__file__).resolve().parents[1] / 'bagfault'


def _declared(folder: str) -> set[str]:
    """The `type_name = '...'` of every class in the folder's modules, read from the source."""
    names = set()
    for path in (PACKAGE / folder).glob('*.py'):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ClassDef):
                for item in node.body:
                    if isinstance(item, ast.Assign) and [getattr(t, 'id', None) for t in item.targets] == \
                            ['type_name'] and isinstance(item.value, ast.Constant) and item.value.value:
                        names.add(item.value.value)
    return names


@pytest.mark.parametrize(('table', 'folder'), [(BUILTIN, 'injectors'), (ASSERTION_TYPES, 'assertions')])
def test_every_type_the_source_declares_is_listed_under_its_own_name(table, folder):
    declared = _declared(folder)
    assert len(declared) >= 10
    assert set(table) == declared
    assert {name: table[name].type_name for name in table} == {name: name for name in table}


def test_a_name_not_listed_is_a_key_error_and_a_lookup_loads_once():
    table: TypesByName[object] = TypesByName({'decoder': 'json:JSONDecoder'})
    assert table['decoder'] is json.JSONDecoder and table.get('other') is None
    assert 'other' not in table and list(table) == ['decoder'] and len(table) == 1
    with pytest.raises(KeyError):
        table['other']


PROBE = """
import json, sys
from bagfault.cli import main
assert main(['run', *sys.argv[1:3], '-o', sys.argv[3]]) == 0
print(json.dumps(sorted(m for m in sys.modules if m.startswith(('bagfault.injectors.', 'bagfault.assertions.',
                                                              'bagfault.report.')))))
"""


def test_a_run_loads_the_types_its_scenario_names_only(tmp_path):
    """An IMU injector, no assertion, no report: no other injector's module, no assertion's, no renderer."""
    scenario = tmp_path / 'imu.yaml'
    scenario.write_text('injectors:\n  - {id: imu0, type: imu, input_topic: /imu, output_topic: /imu}\n'
                        'faults:\n  - {id: b, injector_id: imu0, start: 1.0, duration: 1.0,\n'
                        '     config: {angular_velocity_z_bias: 0.5}}\n')
    done = subprocess.run([sys.executable, '-c', PROBE, str(scenario), str(FIXTURES / 'rover_20s.mcap'),
                           str(tmp_path / 'out.mcap')], capture_output=True, text=True, check=True, timeout=300)
    loaded = json.loads(done.stdout.splitlines()[-1])
    assert 'bagfault.injectors.imu' in loaded  # the probe ran the injector
    injectors = {m for m in loaded if m.startswith('bagfault.injectors.')}
    assert injectors <= {'bagfault.injectors.imu', 'bagfault.injectors.base', 'bagfault.injectors.registry',
                         'bagfault.injectors.system'}, injectors
    assert not any(m.rpartition('.')[2] in _declared_modules('assertions') for m in loaded), loaded
    assert not {'bagfault.report.model', 'bagfault.report.markdown', 'bagfault.report.json_report',
                'bagfault.report.junit', 'bagfault.report.html'} & set(loaded), loaded


def _declared_modules(folder: str) -> set[str]:
    return {path.stem for path in (PACKAGE / folder).glob('*.py')} - {'__init__', 'base', 'registry', 'runner'}
