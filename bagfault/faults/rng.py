"""Random generators owned by one fault, seeded from (scenario seed, fault id).

Each fault gets one independent stream per purpose (`drop_probability`,
`x_noise_stddev`, ...). Streams never share state, so adding a fault or a
draw for one purpose never changes the numbers another one sees, and a
batch of n draws equals n single draws: the batch and per-message paths
produce the same bytes.
"""

from __future__ import annotations

import hashlib
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import numpy as np


def _words(text: str) -> list[int]:
    digest = hashlib.sha256(text.encode()).digest()
    return [int.from_bytes(digest[i : i + 4], 'little') for i in range(0, 16, 4)]


class FaultRandom:
    """Named random streams of one fault."""

    def __init__(self, seed: int, fault_id: str) -> None:
        self.seed = seed
        self.fault_id = fault_id
        self._streams: dict[str, np.random.Generator] = {}

    def stream(self, purpose: str) -> np.random.Generator:
        """The generator for one purpose, created on first use."""
        gen = self._streams.get(purpose)
        if gen is None:
            import numpy as np  # noqa: PLC0415 (a run whose faults never act does not pay numpy's import)

            entropy = [self.seed & 0xFFFFFFFF, self.seed >> 32, *_words(self.fault_id), *_words(purpose)]
            gen = np.random.Generator(np.random.PCG64(np.random.SeedSequence(entropy)))
            self._streams[purpose] = gen
        return gen
