"""pytest plugin (entry point `pytest11`): a `bagfault` fixture, and scenario files collected as tests.

    def test_monitor_detects_drift(bagfault):
        result = bagfault.test('test_imu_drift.bagfault.yaml')  # failed assertions fail the test
        assert result.system.heard['/diagnostics'] > 10

Files named `test_*.bagfault.yaml` are collected: the scenario runs once
(`bagfault test` when it has a `system_under_test`, else `bagfault run`,
on the bags it names under `bags:`) and each assertion is one test item,
located at its line, so `pytest --junitxml` gives CI one testcase per
assertion. A scenario that cannot run is an error of every item (pytest's
word for broken setup), with the reason, never a failure. Items carry the
markers `bagfault` and `closed_loop` (a `system_under_test`) or `offline`,
registered so `--strict-markers` passes: `pytest -m offline` runs the
scenarios that need no ROS graph. The scenario runs in the setup of the
file's first item (`--durations` shows it there; each item's call only
reads its verdict). Under pytest-xdist (`-n 2`) a file's items go to one
worker, so its scenario runs once. `--bagfault-out DIR` keeps the
recordings and logs of collected scenarios.
"""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest

if TYPE_CHECKING:
    from collections.abc import Iterator, Sequence

    from _pytest._code.code import ExceptionInfo, TerminalRepr

    from bagfault.engine.result import RunResult
    from bagfault.spec.model import Scenario

SUFFIXES = ('.bagfault.yaml', '.bagfault.yml')
ALIVE = 'system_alive'


def pytest_addoption(parser: pytest.Parser) -> None:
    """--bagfault-out."""
    group = parser.getgroup('bagfault')
    group.addoption('--bagfault-out', metavar='DIR', default=None,
                    help='keep the recordings and system logs of collected scenario files here')


MARKERS = {
    'bagfault': 'a bagfault scenario or a test using the bagfault fixture',
    'closed_loop': 'a bagfault scenario with a system_under_test (needs rclpy and a ROS graph)',
    'offline': 'a bagfault scenario run on its bags alone (no ROS needed)',
}


def pytest_configure(config: pytest.Config) -> None:
    """Register the markers (so `--strict-markers` accepts them); under xdist, keep each scenario file together."""
    for name, text in MARKERS.items():
        config.addinivalue_line('markers', f'{name}: {text}')
    if hasattr(config.hook, 'pytest_xdist_make_scheduler'):
        config.pluginmanager.register(ScenarioFilesTogether(), 'bagfault-xdist')


class ScenarioFilesTogether:
    """pytest-xdist: under its default `--dist load`, the items of one scenario file go to one worker, so the
    file's scenario runs once; every other test is scheduled alone, as `load` would."""

    @pytest.hookimpl(tryfirst=True)
    def pytest_xdist_make_scheduler(self, config: pytest.Config, log: Any) -> Any:
        """A LoadScopeScheduling whose scopes are scenario files and single items."""
        if config.getvalue('dist') != 'load':
            return None  # loadfile, loadscope and loadgroup keep a file together already; each/worksteal: asked for
        from xdist.scheduler import LoadScopeScheduling  # type: ignore[import-untyped]  # noqa: PLC0415

        class ByScenarioFile(LoadScopeScheduling):  # type: ignore[misc]
            def _split_scope(self, nodeid: str) -> str:
                path = nodeid.split('::', 1)[0]
                return path if path.endswith(SUFFIXES) else nodeid

        return ByScenarioFile(config, log)


class ScenarioAssertionError(AssertionError):
    """An assertion of a scenario did not pass: the test fails with its message, no traceback."""


def failure_text(result: RunResult) -> str:
    """One line per failed (or undecided) assertion."""
    return '\n'.join(f'{a.id} {a.state}: {a.message}' for a in result.assertions if a.state != 'passed')


class BagfaultFixture:
    """The `bagfault` fixture: the Python API with outputs in the test's tmp_path; failed assertions fail."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder

    def _done(self, result: RunResult, check: bool) -> RunResult:
        if check and result.failed:
            pytest.fail(failure_text(result), pytrace=False)
        return result

    def run(self, scenario: Scenario | str | Path, inputs: Sequence[str | Path] = (),
            output: str | Path | None = None, *, check: bool = True, **options: Any) -> RunResult:
        """`bagfault run` (inputs default to the scenario's `bags`, output to tmp_path/run.mcap)."""
        from bagfault import api  # noqa: PLC0415

        loaded = api.scenario_of(scenario)
        paths = list(inputs) or list(loaded.bags)
        result = api.run(loaded, paths, output or self.folder / 'run.mcap', **options)
        return self._done(result, check)

    def test(self, scenario: Scenario | str | Path, inputs: Sequence[str | Path] = (),
             output: str | Path | None = None, *, check: bool = True, **options: Any) -> RunResult:
        """`bagfault test` (output default tmp_path/test.mcap, the system's logs in tmp_path/logs)."""
        from bagfault import api  # noqa: PLC0415

        options.setdefault('keep_logs', self.folder / 'logs')
        result = api.test(scenario, inputs, output or self.folder / 'test.mcap', **options)
        return self._done(result, check)

    def check(self, scenario: Scenario | str | Path, recording: str | Path, *, check: bool = True,
              **options: Any) -> RunResult:
        """`bagfault check` of a recording."""
        from bagfault import api  # noqa: PLC0415

        return self._done(api.check(scenario, recording, **options), check)


@pytest.fixture
def bagfault(tmp_path: Path) -> BagfaultFixture:
    """run/test/check returning results; a failed assertion fails the test with its message."""
    return BagfaultFixture(tmp_path)


def pytest_collect_file(file_path: Path, parent: pytest.Collector) -> pytest.Collector | None:
    """test_*.bagfault.yaml files are scenario tests."""
    if file_path.name.startswith('test_') and file_path.name.endswith(SUFFIXES):
        return ScenarioFile.from_parent(parent, path=file_path)
    return None


class ScenarioFile(pytest.File):
    """A scenario file: run once, one item per assertion."""

    def collect(self) -> Iterator[pytest.Item]:
        """Items at the lines of the assertions (one `scenario` item if the file does not load)."""
        from bagfault.errors import BagfaultError  # noqa: PLC0415
        from bagfault.scenario import load_scenario  # noqa: PLC0415

        self._outcome: RunResult | BaseException | None = None
        try:
            self.scenario = load_scenario(self.path)
        except BagfaultError as exc:
            self._outcome = exc
            yield ScenarioItem.from_parent(self, name='scenario', assertion_id='', line=1)
            return
        if self.scenario.system is not None:
            yield ScenarioItem.from_parent(self, name=ALIVE, assertion_id=ALIVE,
                                           line=self._line(('system_under_test',)))
        for index, spec in enumerate(self.scenario.assertions):
            yield ScenarioItem.from_parent(self, name=spec.id, assertion_id=spec.id,
                                           line=self._line(('assertions', index)))
        if not self.scenario.assertions and self.scenario.system is None:
            yield ScenarioItem.from_parent(self, name='scenario', assertion_id='', line=1)

    def _line(self, path: tuple[Any, ...]) -> int:
        return int(self.scenario.located.where(path).split(':')[0])

    def outcome(self) -> RunResult:
        """The scenario's result, computed by the first item that asks; the error of a run that failed."""
        from bagfault import api  # noqa: PLC0415

        if self._outcome is None:
            kept = self.config.getoption('bagfault_out')
            if kept:
                folder = Path(kept) / self.path.name.removesuffix('.yaml').removesuffix('.yml')
                folder.mkdir(parents=True, exist_ok=True)
            else:
                folder = Path(tempfile.mkdtemp(prefix='bagfault-'))
                self.config.add_cleanup(lambda: shutil.rmtree(folder, ignore_errors=True))
            output = folder / 'output.mcap'
            try:
                if self.scenario.system is not None:
                    self._outcome = api.test(self.scenario, (), output, keep_logs=folder / 'logs')
                else:
                    self._outcome = api.run(self.scenario, list(self.scenario.bags), output)
            except Exception as exc:  # noqa: BLE001 - every item reports why the scenario could not run
                self._outcome = exc
        if isinstance(self._outcome, BaseException):
            raise self._outcome
        return self._outcome


class ScenarioItem(pytest.Item):
    """One assertion of a scenario file."""

    def __init__(self, *, assertion_id: str, line: int, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.assertion_id = assertion_id
        self.line = line  # (no user_properties: pytest writes them inside the testcase, which junit-10 refuses)
        self.add_marker('bagfault')
        scenario = getattr(self.parent, 'scenario', None)
        if scenario is not None:
            self.add_marker('closed_loop' if scenario.system is not None else 'offline')

    def setup(self) -> None:
        """The scenario runs here (once per file): a scenario that cannot run is a setup error, not a failure."""
        from bagfault.errors import BagfaultError  # noqa: PLC0415

        assert isinstance(self.parent, ScenarioFile)
        try:
            self.parent.outcome()
        except BagfaultError as exc:
            tail = getattr(exc, 'tail', None) or []
            pytest.fail('\n'.join([f'{self.path.name}: could not run: {exc}', *(f'  | {line}' for line in tail)]),
                        pytrace=False)

    def runtest(self) -> None:
        """Pass when the assertion passed."""
        assert isinstance(self.parent, ScenarioFile)
        result = self.parent.outcome()
        if not self.assertion_id:
            if result.failed:
                raise ScenarioAssertionError(failure_text(result))
            return
        found = next((a for a in result.assertions if a.id == self.assertion_id), None)
        where = f'{self.path.name}:{self.line}'  # the failure's text in the terminal and in --junitxml
        if found is None:
            raise ScenarioAssertionError(f'{where}: {self.assertion_id}: no verdict')
        if found.state != 'passed':
            raise ScenarioAssertionError(f'{where}: {found.id} {found.state}: {found.message}')

    def repr_failure(self, excinfo: ExceptionInfo[BaseException],
                     style: Any = None) -> str | TerminalRepr:
        """The assertion's message (or why the scenario could not run) instead of a traceback."""
        from bagfault.errors import BagfaultError  # noqa: PLC0415

        value = excinfo.value
        if isinstance(value, ScenarioAssertionError):
            return str(value)
        if isinstance(value, BagfaultError):  # (setup reports these as errors; a rerun of runtest alone lands here)
            return f'{self.path.name}: could not run: {value}'
        return super().repr_failure(excinfo)

    def reportinfo(self) -> tuple[Path, int, str]:
        """File and line of the assertion (pytest counts lines from 0)."""
        return self.path, self.line - 1, self.name
