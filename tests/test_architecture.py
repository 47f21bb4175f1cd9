"""The package's layering: the core imports none of the modes, reports or the API (ARCHITECTURE.md)."""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / 'bagfault'
CORE = ('scenario', 'spec', 'injectors', 'faults', 'engine', 'io', 'assertions', 'fault_manager', 'latency')
CORE_MODULES = ('events', 'schema', 'errors')
OUTSIDE = ('bagfault.live', 'bagfault.api', 'bagfault.cli', 'bagfault.report', 'bagfault.closedloop',
           'bagfault.campaign', 'bagfault.explore', 'bagfault.view', 'bagfault.pytest_plugin')


def _core_files() -> list[Path]:
    files = [PACKAGE / f'{name}.py' for name in CORE_MODULES]
    for name in CORE:
        files += sorted((PACKAGE / name).rglob('*.py'))
    return files


def _imports(path: Path) -> list[tuple[int, str]]:
    """Every module a file imports, at any depth (lazy imports inside functions included)."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.append((node.lineno, node.module))
            found += [(node.lineno, f'{node.module}.{alias.name}') for alias in node.names]
    return found


def test_core_modules_import_no_mode_report_or_api() -> None:
    files = _core_files()
    assert len(files) > 60  # the scan did find the package
    wrong = [f'{path.relative_to(PACKAGE)}:{line}: {module}'
             for path in files for line, module in _imports(path) if module.startswith(OUTSIDE)]
    assert wrong == []


def test_importing_engine_and_io_loads_nothing_of_live_or_api() -> None:
    modules = sorted('.'.join(p.relative_to(PACKAGE.parent).with_suffix('').parts).removesuffix('.__init__')
                     for name in ('engine', 'io') for p in (PACKAGE / name).rglob('*.py'))
    code = ('import importlib, json, sys\n'
            f'for name in {modules!r}: importlib.import_module(name)\n'
            'print(json.dumps(sorted(sys.modules)))')
    loaded = json.loads(subprocess.run([sys.executable, '-c', code], check=True, capture_output=True, text=True,
                                       cwd=PACKAGE.parent).stdout)
    assert 'bagfault.engine.run' in loaded and 'bagfault.io.sources' in loaded  # the probe did import them
    assert [m for m in loaded if m.startswith(OUTSIDE)] == []


def test_only_the_front_ends_import_the_api() -> None:
    """The command line and the pytest plugin use the API; nothing below them does (a campaign's job calls it
    through the function the API hands the engines)."""
    users = {str(p.relative_to(PACKAGE)) for p in PACKAGE.rglob('*.py')
             if any(module == 'bagfault.api' for _, module in _imports(p))}
    assert 'cli.py' in users
    assert users <= {'cli.py', 'pytest_plugin.py'}


def test_the_command_line_imports_the_api_and_the_bottom_layers_only() -> None:
    """cli.py parses arguments and calls the API: besides it, only the error tree, logging, the terminal's
    progress lines and the environment's settings."""
    modules = {m for _, m in _imports(PACKAGE / 'cli.py') if m.startswith('bagfault')}
    allowed = {'bagfault', 'bagfault.__version__', 'bagfault.api', 'bagfault.settings', 'bagfault.errors',
               'bagfault.log', 'bagfault.progress'}
    assert {'bagfault.api', 'bagfault.errors'} <= modules
    assert sorted(m for m in modules if m not in allowed and m.rpartition('.')[0] not in allowed - {'bagfault'}) \
        == []


def test_every_subpackage_names_its_public_api() -> None:
    """Each subpackage's __init__ has an `__all__`, and each name in it is one of its modules or defined there;
    one that lists modules lists every public one."""
    packages = sorted(p for p in PACKAGE.iterdir() if (p / '__init__.py').is_file())
    assert len(packages) >= 15
    wrong = []
    for package in packages:
        tree = ast.parse((package / '__init__.py').read_text())
        names = [ast.literal_eval(node.value) for node in tree.body if isinstance(node, ast.Assign)
                 and any(isinstance(t, ast.Name) and t.id == '__all__' for t in node.targets)]
        if not names:
            wrong.append(f'{package.name}: no __all__')
            continue
        defined = {n.name for n in tree.body if isinstance(n, (ast.FunctionDef, ast.ClassDef))}
        defined |= {t.id for n in tree.body if isinstance(n, ast.Assign) for t in n.targets if isinstance(t, ast.Name)}
        defined |= {a.asname or a.name for n in tree.body if isinstance(n, ast.ImportFrom) for a in n.names}
        modules = {p.stem for p in package.glob('*.py')} | {p.name for p in package.iterdir() if p.is_dir()}
        wrong += [f'{package.name}: {name}' for name in names[0] if name not in defined | modules]
        files = {p.stem for p in package.glob('*.py') if not p.stem.startswith('_')}
        if set(names[0]) & files:  # a list of its modules: all of them (a new module is not left out)
            wrong += [f'{package.name}: {name} not in __all__' for name in sorted(files - set(names[0]))]
    assert wrong == []


def test_the_library_prints_nothing_outside_the_command_line_and_the_reports() -> None:
    """Diagnostics are log records of the `bagfault` logger (bagfault/log.py); only the CLI and the report
    writers print."""
    printing = []
    for path in PACKAGE.rglob('*.py'):
        relative = path.relative_to(PACKAGE)
        if relative.parts[0] in ('cli.py', 'report'):
            continue
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == 'print':
                printing.append(f'{relative}:{node.lineno}')
            if isinstance(node, ast.Attribute) and node.attr in ('print_exc', 'print_exception'):
                printing.append(f'{relative}:{node.lineno}')
    assert printing == []


def test_a_library_user_sees_bagfaults_records_through_logging(caplog) -> None:
    import logging

    from bagfault.log import log

    with caplog.at_level(logging.INFO, logger='bagfault'):
        log.info('system under test started on ROS domain 42')
    assert [(r.name, r.levelname, r.getMessage()) for r in caplog.records] == [
        ('bagfault', 'INFO', 'system under test started on ROS domain 42')]


def test_third_party_data_is_found_through_bagfault_shared_only() -> None:
    """Every test reaches ../shared through support/helpers.py (BAGFAULT_SHARED, default ../shared): a path built
    to 'shared' anywhere else ignores the variable (test_fuzz.py did: its third-party cases skipped with it set)."""
    tests = Path(__file__).resolve().parent
    found = [f'{path.relative_to(tests)}:{number}' for path in sorted(tests.rglob('*.py'))
             if path not in (tests / 'support' / 'helpers.py', Path(__file__).resolve())
             for number, line in enumerate(path.read_text().splitlines(), 1)
             if "'shared'" in line or '"shared"' in line]
    assert found == []


# files read whole by name that are never a user's: package resources, /proc, a log bagfault wrote itself
READ_BY_NAME_ALLOWED = {'report/page.py', 'demo/__init__.py', 'closedloop/process.py', 'closedloop/actions.py',
                        'campaign/engines.py', 'io/regular.py'}


def test_every_file_read_by_name_is_checked_to_be_a_regular_file() -> None:
    """A FIFO, a device or a socket given as a scenario, a campaign file or a message definition blocked
    `read_text` for ever: bagfault reads named files through io/regular.py, which opens without blocking and
    refuses what is not a regular file. No `Path.read_text`/`read_bytes` elsewhere (bags are opened by their
    readers after `sources.require_regular`)."""
    found = []
    for path in PACKAGE.rglob('*.py'):
        relative = str(path.relative_to(PACKAGE))
        if relative in READ_BY_NAME_ALLOWED:
            continue
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Attribute) and node.attr in ('read_text', 'read_bytes') and \
                    isinstance(node.ctx, ast.Load) and not (isinstance(node.value, ast.Name) and
                                                             node.value.id in ('regular',)):
                found.append(f'{relative}:{node.lineno}')
    assert found == []


def test_every_environment_variable_of_bagfault_is_read_in_settings():
    """One owner: settings.py parses and checks each BAGFAULT_* variable; nothing else reads one."""
    import re

    package = PACKAGE
    reads = re.compile(r"""(environ\.get|getenv|environ\[)\(?\s*['"](BAGFAULT_|XDG_CACHE_HOME)""")
    found = [f'{path.relative_to(package)}:{number}' for path in sorted(package.rglob('*.py'))
             if path.name != 'settings.py'
             for number, line in enumerate(path.read_text().splitlines(), 1) if reads.search(line)]
    assert found == []
