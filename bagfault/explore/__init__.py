"""`bagfault explore`: fault-space search with margins, shrinking to the minimal cause, replay."""

from __future__ import annotations

from bagfault.explore.explorer import ExploreOptions, ExploreResult, explore
from bagfault.explore.records import Failure, Outcome, RunRecord

__all__ = ['ExploreOptions', 'ExploreResult', 'Failure', 'Outcome', 'RunRecord', 'explore']
