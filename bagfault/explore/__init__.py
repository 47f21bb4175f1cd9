"""`bagfault explore`: fault-space search with margins, shrinking to the minimal cause, replay."""

from __future__ import annotations

from bagfault.explore.explorer import ExploreOptions, ExploreProgress, ExploreResult, explore
from bagfault.explore.records import Failure, Outcome, RunRecord

__all__ = ['ExploreOptions', 'ExploreProgress', 'ExploreResult', 'Failure', 'Outcome', 'RunRecord', 'explore']
