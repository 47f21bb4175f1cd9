"""Job functions for the campaign engines' own tests: known CPU, known wall time (importable by a fork server)."""

from __future__ import annotations

import subprocess
import sys
import time
from typing import Any

BURN = 'import time\nend = time.process_time() + {seconds}\nwhile time.process_time() < end: pass'


def measured(spec: dict[str, Any]) -> dict[str, Any]:
    """Burns `spec['cpu']` CPU seconds in this process and `spec['child_cpu']` in a child it waits for, then
    sleeps `spec['sleep']` seconds."""
    began = time.monotonic()
    end = time.process_time() + spec.get('cpu', 0.0)
    while time.process_time() < end:
        pass
    if spec.get('child_cpu'):
        subprocess.run([sys.executable, '-c', BURN.format(seconds=spec['child_cpu'])], check=True)
    time.sleep(spec.get('sleep', 0.0))
    return {'status': 'passed', 'message': '', 'assertions': {}, 'detections': {}, 'warnings': [],
            'seconds': round(time.monotonic() - began, 3), 'output': None}


def loaded_modules(spec: dict[str, Any]) -> dict[str, Any]:
    """The bagfault modules already loaded when the job starts (what its fork server had imported), as the message."""
    loaded = sorted(m for m in sys.modules if m.startswith(spec['prefix']))
    return {'status': 'passed', 'message': ' '.join(loaded), 'assertions': {}, 'detections': {}, 'warnings': [],
            'seconds': 0.0, 'output': None}
