"""The `bagfault` metadata record: enough to reproduce a run from its output alone."""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict
from typing import TYPE_CHECKING

from bagfault import __version__
from bagfault.io.sources import fingerprint

if TYPE_CHECKING:
    import threading
    from collections.abc import Sequence
    from pathlib import Path

    from bagfault.engine.activation import Activation
    from bagfault.io.mcap_sink import McapSink
    from bagfault.io.sources import ReadMark
    from bagfault.spec.model import Scenario


def provenance(scenario: Scenario, inputs: Sequence[Path], seed: int, activations: Sequence[Activation],
               start_offset: float, stop: threading.Event | None = None,
               mark: ReadMark | None = None) -> dict[str, str]:
    """Tool version, seed, scenario hash, inputs with sizes and BLAKE3 digests, `--activate` and `--start` options
    (`mark`: the run reads its one input file in order, and the hash keeps pace with it)."""
    return {
        'tool': 'bagfault',
        'version': __version__,
        'seed': str(seed),
        'scenario': scenario.name,
        'scenario_sha256': hashlib.sha256(scenario.text.encode()).hexdigest(),
        'inputs': json.dumps(
            [{'name': p.name, 'files': [asdict(f) for f in fingerprint(p, stop, mark)]} for p in inputs], sort_keys=True
        ),
        'activate': json.dumps([asdict(a) for a in activations], sort_keys=True),
        'start_offset': repr(float(start_offset)),
    }


ORIGIN_RECORD = 'bagfault.origin'


def record_origin(recording: McapSink, origin: int | None) -> None:
    """Add the `bagfault.origin` metadata to a live recording: where its bag time zero was, so `check` judges
    the recording with the zero the live run used (not its first message)."""
    if origin is not None:
        recording.add_metadata(ORIGIN_RECORD, {'origin_ns': str(origin)})
