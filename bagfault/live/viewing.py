"""What a live command needs of a view of its run (the Foxglove view, one layer up): handed in, never imported.

The API opens the view (`OpenView`, given the scenario and what the
command offers: fault controls, playback, a reload); `live/` and the closed
loop receive it, so the rclpy runtime does not depend on the view.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Protocol

if TYPE_CHECKING:
    from collections.abc import Callable

    from bagfault.engine.run import Run, Sink
    from bagfault.spec.model import Scenario


class LiveView(Protocol):
    """A view that shows a run's records and events, and takes edits and playback controls."""

    controls: Any  # what edits of faults go to (a proxy sets itself once it runs)
    scenario: Scenario  # whose faults are shown (a proxy's reload replaces it)

    @property
    def url(self) -> str:
        """Where a client connects."""
        ...

    def add_channel(self, topic: str, msgtype: str, schema_encoding: str, schema_text: str,
                    message_encoding: str = 'cdr') -> int:
        """A channel; its id."""
        ...

    def write(self, channel_id: int, log_time: int, data: bytes | memoryview) -> None:
        """One record."""
        ...

    def attach(self, run: Run) -> None:
        """A pass begins: its events go to the view."""
        ...

    def played(self, bag_time: int) -> None:
        """The timeline reached `bag_time`."""
        ...

    def ended(self, bag_time: int) -> None:
        """The bag ended at `bag_time` (the view stays until a stop or a seek)."""
        ...

    def sink(self, inner: Sink) -> Sink:
        """A sink that writes to `inner` and shows every record."""
        ...

    def notes(self) -> list[str]:
        """What the report says about the view."""
        ...

    def close(self) -> None:
        """Stop serving."""
        ...


class OpenView(Protocol):
    """Opens the view of one command's run."""

    def __call__(self, scenario: Scenario, *, controls: Any = None, playback: Any = None,
                 time_range: tuple[int, int] | None = None, reload: Callable[[], tuple[bool, str]] | None = None,
                 editable: bool | None = None) -> LiveView:
        """The view, serving."""
        ...
