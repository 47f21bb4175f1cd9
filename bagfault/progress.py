"""Progress on a terminal: a run's messages and bag seconds, a campaign's jobs, an exploration's runs.

Display only: each reads the wall clock to pace itself and estimate time
left; the engine never sees it. Silent when stderr is not a terminal.
"""

from __future__ import annotations

import sys
import time
from typing import TextIO

from bagfault.units import NS


def _clock(seconds: float) -> str:
    seconds = max(0, int(seconds))
    hours, rest = divmod(seconds, 3600)
    minutes, secs = divmod(rest, 60)
    return f'{hours}:{minutes:02d}:{secs:02d}' if hours else f'{minutes:02d}:{secs:02d}'


class _CountLine:
    """A one-line bar of counted items on a terminal (stderr unless `stream`; drawn only on a terminal)."""

    WIDTH = 24
    END = '\n'  # what `close` writes after the last drawing

    def __init__(self, stream: TextIO | None = None, enabled: bool | None = None) -> None:
        self.stream = stream or sys.stderr
        self.enabled = self.stream.isatty() if enabled is None else enabled
        self.began = time.monotonic()
        self.shown = False

    def bar(self, fraction: float) -> str:
        """`[####....]` filled to `fraction`."""
        filled = int(fraction * self.WIDTH)
        return f'[{"#" * filled}{"." * (self.WIDTH - filled)}]'

    def show(self, text: str) -> None:
        """Redraw the line with `text`."""
        if self.enabled:
            self.stream.write('\r' + text + '\x1b[K')
            self.stream.flush()
            self.shown = True

    def close(self) -> None:
        """End the line: kept (a new line after it), or cleared where END says so."""
        if self.enabled and self.shown:
            self.stream.write(self.END)
            self.stream.flush()


class ProgressBar(_CountLine):
    """Callable given to the pipeline: progress(messages_done, bag_time_ns); the line is cleared at the end."""

    END = '\r\x1b[2K'

    def __init__(self, *, stream: TextIO | None = None, enabled: bool | None = None) -> None:
        super().__init__(stream, enabled)
        self.start_time: int | None = None
        self.end_time: int | None = None
        self.total: int | None = None
        self.last_draw = 0.0

    def begin(self, start_time: int | None, end_time: int | None, total_messages: int | None) -> None:
        """What the whole job is: bag time span and message count, when known."""
        self.start_time, self.end_time, self.total = start_time, end_time, total_messages
        self.began = time.monotonic()

    def fraction(self, messages: int, bag_time: int) -> float | None:
        """Share of the work done, from bag time if known, else from message count."""
        if self.start_time is not None and self.end_time is not None and self.end_time > self.start_time:
            return min(1.0, max(0.0, (bag_time - self.start_time) / (self.end_time - self.start_time)))
        if self.total:
            return min(1.0, messages / self.total)
        return None

    def line(self, messages: int, bag_time: int, elapsed: float) -> str:
        """The text of one update."""
        done_s = (bag_time - self.start_time) / NS if self.start_time is not None else 0.0
        total_s = (self.end_time - self.start_time) / NS if self.end_time and self.start_time is not None else None
        fraction = self.fraction(messages, bag_time)
        if fraction is None:
            bar, eta = '', ''
        else:
            bar = f'{self.bar(fraction)} {fraction * 100:5.1f}% '
            eta = f' ETA {_clock(elapsed * (1 - fraction) / fraction)}' if fraction > 0 else ''
        bag = f'{done_s:.1f}/{total_s:.1f} s bag' if total_s is not None else f'{done_s:.1f} s bag'
        rate = messages / elapsed if elapsed > 0 else 0.0
        return f'{bar}{messages} msgs, {bag}, {rate:,.0f} msg/s, {_clock(elapsed)} elapsed{eta}'

    def __call__(self, messages: int, bag_time: int) -> None:
        if not self.enabled:
            return
        now = time.monotonic()
        if now - self.last_draw < 0.2:
            return
        self.last_draw = now
        self.show(self.line(messages, bag_time, now - self.began))


class JobProgress(_CountLine):
    """Jobs done, passed/failed/error so far, ETA."""

    def __init__(self, stream: TextIO | None = None, enabled: bool | None = None) -> None:
        super().__init__(stream, enabled)
        self.total = 0
        self.done = 0
        self.cached = 0
        self.counts = {'passed': 0, 'failed': 0, 'error': 0}

    def add(self, total: int, cached: int) -> None:
        """More jobs to do (a search round), `cached` of them already done."""
        self.total += total
        self.done += cached
        self.cached += cached

    def finished(self, status: str) -> None:
        """A job ended."""
        self.done += 1
        self.counts[status] = self.counts.get(status, 0) + 1
        self.show(self.line())

    def line(self) -> str:
        """The text of the bar."""
        ran = self.done - self.cached
        elapsed = time.monotonic() - self.began
        left = self.total - self.done
        eta = f' ETA {_clock(elapsed / ran * left)}' if ran and left else ''
        c = self.counts
        return (f'{self.bar(self.done / self.total if self.total else 1.0)} {self.done}/{self.total} jobs  '
                f'{c["passed"]} passed  {c["failed"]} failed  {c["error"]} error{eta}')


class ExploreProgress(_CountLine):
    """Runs of the budget, failures, the closest margin so far."""

    def update(self, used: int, budget: int, failures: int, best: float | None) -> None:
        """Redraw."""
        elapsed = time.monotonic() - self.began
        eta = f'  ETA {_clock(elapsed / used * (budget - used))}' if used and used < budget else ''
        margin = f'  closest {best:.2f} of the baseline margin' if best is not None else ''
        self.show(f'{self.bar(used / budget if budget else 1.0)} {used}/{budget} runs  {failures} '
                  f'failure{"s" if failures != 1 else ""}{margin}{eta}')
