"""A live recording: an MCAP that grows while the graph runs, with bagfault's preamble, all or nothing.

Every live mode (play, proxy, record, test) records the same way: the
running rclpy's distro, a chunk completed at least every LIVE_FLUSH seconds
(so `bagfault recover` finds most of it after a kill), the provenance
metadata first and the scenario attached at the first message's time. The
sink is a context manager: a recording not finished by the end of its `with`
is dropped, so a failed run never leaves a half-written file under the
requested name.
"""

from __future__ import annotations

import contextlib
from typing import TYPE_CHECKING

from bagfault.io.mcap_sink import LIVE_FLUSH, McapSink
from bagfault.live.runtime import running_distro

if TYPE_CHECKING:
    from collections.abc import Mapping
    from pathlib import Path

    from bagfault.spec.model import Scenario


def start_recording(path: Path, metadata: Mapping[str, str], scenario: Scenario | None = None,
                    at: int = 0) -> McapSink:
    """The recording at `path` with its `bagfault` metadata record and (if given) the scenario attached at `at`."""
    sink = McapSink(path, ros_distro=running_distro(), flush_every=LIVE_FLUSH)
    with contextlib.ExitStack() as undo:
        undo.callback(sink.abort)
        sink.add_metadata('bagfault', dict(metadata))
        if scenario is not None:
            sink.add_attachment(scenario.name, 'application/yaml', scenario.text.encode(), at)
        undo.pop_all()
    return sink


def maybe_recording(path: Path | None, metadata: Mapping[str, str], scenario: Scenario | None = None,
                    at: int = 0) -> contextlib.AbstractContextManager[McapSink | None]:
    """start_recording, or None without a path: `with maybe_recording(...) as recording:` either way."""
    if path is None:
        return contextlib.nullcontext()
    return start_recording(path, metadata, scenario, at)
