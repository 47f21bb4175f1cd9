"""JSON report: the report model as is (keys documented in docs/reference/report.md)."""

from __future__ import annotations

import json
from typing import Any


def render(report: dict[str, Any]) -> str:
    """Indented JSON with sorted keys."""
    return json.dumps(report, indent=2, sort_keys=True, allow_nan=False, default=str) + '\n'
