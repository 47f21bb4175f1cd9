"""A test's hand on a run: an injector type (installed as a plugin package, by entry point) that, at its first
faulted message, says so with a file and waits until the test creates the gate file. A test that needs a run
in progress holds it there, whatever the machine's speed.

The `reached` file is named after `BAGFAULT_CACHE_NODE` when set (`reached-node1`), so a test can tell which
Ray node holds a job.
"""

from __future__ import annotations

from pathlib import Path

HOLD_INJECTOR = '''
import os
import time
from pathlib import Path

from bagfault.injectors.base import Injector
from bagfault.schema import double


class HoldInjector(Injector):
    """holds the run at its first faulted message until $HOLD_GATE exists"""

    type_name = 'hold'
    description = 'holds the run at its first faulted message until $HOLD_GATE exists'
    message_types = ('sensor_msgs/msg/Imu',)
    fields = (double('level', 'unused'),)

    def mutate(self, message, stamp, active):
        gate = Path(os.environ['HOLD_GATE'])
        node = os.environ.get('BAGFAULT_CACHE_NODE')
        gate.with_name(f'reached-{node}' if node else 'reached').touch()
        while not gate.exists():
            time.sleep(0.01)
'''


def hold_plugin(folder: Path) -> Path:
    """A folder that, on PYTHONPATH, installs the `hold` injector type (an entry point, as a plugin package has)."""
    folder.mkdir()
    (folder / 'hold_injector.py').write_text(HOLD_INJECTOR)
    info = folder / 'hold_injector-0.dist-info'
    info.mkdir()
    (info / 'METADATA').write_text('Metadata-Version: 2.1\nName: hold-injector\nVersion: 0\n')
    (info / 'entry_points.txt').write_text('[bagfault.injectors]\nhold = hold_injector:HoldInjector\n')
    return folder
