"""Campaign fixtures (see corpus.py for the data and why its answers are known)."""

from __future__ import annotations

from pathlib import Path

import pytest
from support.corpus import SCENARIO, write_imu_bag


@pytest.fixture
def corpus(tmp_path: Path) -> Path:
    """bags/a.mcap (z = 0.02) and bags/b.mcap (z = 0.0), the scenario with bias 0, no campaign file yet."""
    (tmp_path / 'bags').mkdir()
    write_imu_bag(tmp_path / 'bags' / 'a.mcap', 0.02)
    write_imu_bag(tmp_path / 'bags' / 'b.mcap', 0.0)
    (tmp_path / 'drift.yaml').write_text(SCENARIO % {'bias': '0.0'})
    return tmp_path
