"""The report files a command writes: checked before the run, written whole after it."""

from __future__ import annotations

import fnmatch
import glob
from dataclasses import dataclass
from typing import TYPE_CHECKING

from bagfault.errors import OutputError
from bagfault.io.outputs import check_output, write_atomic

if TYPE_CHECKING:
    from collections.abc import Sequence
    from pathlib import Path

    from bagfault.engine.result import RunResult
    from bagfault.engine.run import Observer
    from bagfault.report.rates import RateTracker


@dataclass(frozen=True)
class ReportPaths:
    """Where each report goes (None: not asked for)."""

    markdown: Path | None = None
    json: Path | None = None
    junit: Path | None = None
    html: Path | None = None
    force: bool = False  # replace existing files bagfault did not write
    junit_file_line: bool = False  # file and line attributes on each testcase (beyond Jenkins' junit-10 schema)

    def named(self) -> list[tuple[str, Path]]:
        """(option, path) of every report asked for."""
        pairs = (('--report', self.markdown), ('--json', self.json), ('--junit', self.junit), ('--html', self.html))
        return [(name, path) for name, path in pairs if path is not None]

    def check(self, protected: Sequence[tuple[str, Path]]) -> None:
        """Before the run: every report path is writable and replaces nothing the run reads or writes, its
        black boxes included (named after the output: OUT.blackbox.CODE.N.mcap, written during the run)."""
        named = self.named()
        outputs = [path for name, path in protected if name in ('the output', 'the recording')]
        for number, (option, path) in enumerate(named):
            others = [(f'the {name} report', other) for name, other in named[:number]]
            check_output(path, f'{option} report', [*protected, *others], force=self.force)
            for output in outputs:
                same_folder = path.resolve().parent == output.resolve().parent
                if same_folder and fnmatch.fnmatchcase(path.name, f'{glob.escape(output.stem)}.blackbox.*.mcap'):
                    raise OutputError(f'{path}: {option} report has the name of a black box of {output} (the run '
                                      'writes those); choose another name')

    def collectors(self) -> list[Observer]:
        """Observers the reports need during the run (topic rates for the HTML report)."""
        if self.html is None:
            return []  # (nothing imported: `bagfault run` starts its leading copy after this)
        from bagfault.report.rates import RateTracker  # noqa: PLC0415 - numpy

        return [RateTracker()]

    def write(self, result: RunResult, collectors: Sequence[Observer] = ()) -> None:
        """Render and write every report asked for (a renderer's module imported only when its report is)."""
        if not self.named():
            return
        from bagfault.report import model  # noqa: PLC0415

        report = model.build(result)
        if self.markdown is not None:
            from bagfault.report import markdown  # noqa: PLC0415

            write_atomic(self.markdown, markdown.render(report), 'markdown')
        if self.json is not None:
            from bagfault.report import json_report  # noqa: PLC0415

            write_atomic(self.json, json_report.render(report), 'json')
        if self.junit is not None:
            from bagfault.report import junit  # noqa: PLC0415

            write_atomic(self.junit, junit.render(report, extended=self.junit_file_line), 'xml')
        if self.html is not None:
            from bagfault.report import html  # noqa: PLC0415
            from bagfault.report.fields import collect  # noqa: PLC0415
            from bagfault.report.rates import RateTracker  # noqa: PLC0415

            rates: RateTracker | None = next((c for c in collectors if isinstance(c, RateTracker)), None)
            plots, media = collect(result)
            write_atomic(self.html, html.render(report, rates, plots, media=media), 'html')
