"""A run pays for what acts: numpy and a type's compiled codec are loaded when a fault changes a message.

Seen from inside a `bagfault run` in a process of its own (numpy is loaded in
this one): which modules it imported by its end and which types rosbags
compiled. A fault outside the bag's time leaves the bag's chunks as they are,
so nothing needs decoding; the same fault inside it does.
"""

from __future__ import annotations

import struct
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from bagfault.demo.workloads import write_bag
from bagfault.io.channel import Channel
from bagfault.io.mcap_index_check import bounds_in_python, bounds_with_numpy
from bagfault.io.types import TypeCatalog

IMU = """
injectors:
  - {{id: imu, type: imu, input_topic: /imu, output_topic: /imu}}
faults:
  - {{id: bias, injector_id: imu, start: {start}, duration: 0.4, config: {{angular_velocity_z_bias: 0.05}}}}
"""


@pytest.fixture(scope='module')
def bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp('loads') / 'sensor.mcap'
    write_bag(path, 'sensor-heavy', 3.0)
    return path


def loaded_by_run(bag: Path, folder: Path, start: float, numpy_after: int | None = None) -> tuple[str, ...]:
    """(exit code, numpy imported, types compiled) of `bagfault run` in a fresh process."""
    (folder / 'imu.yaml').write_text(IMU.format(start=start))
    code = f"""
import sys
from bagfault.io import types
from bagfault.io.mcap_index_check import DataSection
if {numpy_after!r} is not None:
    DataSection.NUMPY_AFTER = {numpy_after!r}
stores = []
built = types.TypeCatalog._build
def kept(self, wanted):
    stores.append(built(self, wanted))
    return stores[-1]
types.TypeCatalog._build = kept
from bagfault.cli import main
code = main(['run', 'imu.yaml', {str(bag)!r}, '-o', 'out.mcap'])
print(code, 'numpy' in sys.modules, sorted(name for store in stores for name in store.cache))
"""
    done = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, check=True, cwd=folder)
    return tuple(done.stdout.splitlines()[-1].split(' ', 2))


def test_a_fault_that_never_acts_loads_no_numpy_and_compiles_no_codec(bag: Path, tmp_path: Path) -> None:
    assert loaded_by_run(bag, tmp_path, start=100.0) == ('0', 'False', '[]')


def test_a_fault_that_acts_loads_both(bag: Path, tmp_path: Path) -> None:
    """numpy for the bias (patched in the CDR bytes: the IMU type needs no codec), the event type's codec for the
    fault's start and end events."""
    code, numpy, compiled = loaded_by_run(bag, tmp_path, start=1.5)
    assert (code, numpy) == ('0', 'True')
    assert 'ros2_fault_injection/msg/FaultEvent' in compiled


def test_the_index_check_imports_numpy_once_its_python_would_cost_more(bag: Path, tmp_path: Path) -> None:
    """With the switch at no entries, the check's first chunk imports numpy (the bag has a few hundred)."""
    assert loaded_by_run(bag, tmp_path, start=100.0, numpy_after=0)[:2] == ('0', 'True')


U64 = st.integers(0, 2**64 - 1)


@given(st.lists(st.tuples(U64, U64), min_size=1, max_size=300))
def test_index_entry_bounds_in_python_and_with_numpy_agree(pairs: list[tuple[int, int]]) -> None:
    entries = b''.join(struct.pack('<QQ', time, offset) for time, offset in pairs)
    expected = (min(t for t, _ in pairs), max(t for t, _ in pairs), max(o for _, o in pairs))
    assert bounds_in_python(entries) == expected
    assert bounds_with_numpy(entries) == expected


def test_a_type_referring_to_an_unknown_one_has_no_codec_and_the_reason_names_it() -> None:
    channel = Channel('/t', 'my_pkg/msg/Thing', 'ros2msg', 'my_pkg/Inner inner\nfloat64 x\n', 'cdr')
    catalog = TypeCatalog([channel], None)
    assert catalog.codec('my_pkg/msg/Thing') is None
    assert catalog.why_not('my_pkg/msg/Thing') == "no usable definition ('my_pkg/msg/Inner')"
    known = Channel('/t', 'my_pkg/msg/Thing', 'ros2msg', 'geometry_msgs/Vector3 inner\nfloat64 x\n', 'cdr')
    codec = TypeCatalog([known], None).codec('my_pkg/msg/Thing')
    assert codec is not None
    assert codec.decode(bytes([0, 1, 0, 0]) + bytes(range(32))).x == struct.unpack('<d', bytes(range(24, 32)))[0]


@st.composite
def packages(draw: st.DrawFn) -> tuple[str, dict[str, str], set[str]]:
    """A type `gen_pkg/msg/T0` and the definitions a bag stores with it: types T1.. (each referring only to later
    ones, base types, arrays and sequences), some of them left out. Returns (schema text, bodies, left out)."""
    count = draw(st.integers(1, 5))
    bodies = {}
    for number in range(count):
        fields = []
        for field in range(draw(st.integers(1, 4))):
            target = draw(st.one_of(st.sampled_from(['float64', 'uint8', 'string', 'int32']),
                                    st.integers(number + 1, count).map(lambda n: f'gen_pkg/T{n}')))
            suffix = draw(st.sampled_from(['', '[]', '[3]']))
            fields.append(f'{target}{suffix} f{field}')
        bodies[f'gen_pkg/msg/T{number}'] = '\n'.join(fields) + '\n'
    bodies[f'gen_pkg/msg/T{count}'] = 'float32 leaf\n'
    left_out = set(draw(st.lists(st.sampled_from(sorted(bodies)[1:]), unique=True))) if count else set()
    separator = '=' * 80 + '\n'
    text = bodies['gen_pkg/msg/T0'] + ''.join(f'{separator}MSG: {name.replace("/msg/", "/")}\n{body}'
                                             for name, body in sorted(bodies.items())[1:] if name not in left_out)
    return text, bodies, left_out


@given(packages())
def test_a_codec_is_given_exactly_when_every_type_it_refers_to_is_known_and_then_compiles(
        package: tuple[str, dict[str, str], set[str]]) -> None:
    """Whether the codec is given is decided without compiling; a codec given compiles at its first use, and
    None comes with the first unknown type named (the reachable types worked out here from the bodies)."""
    text, bodies, left_out = package
    reachable, todo = set(), ['gen_pkg/msg/T0']
    while todo:
        name = todo.pop()
        if name not in reachable:
            reachable.add(name)
            if name not in left_out:
                todo += [f'gen_pkg/msg/{word.split("/")[1].split("[")[0]}'
                         for word in bodies[name].split() if word.startswith('gen_pkg/')]
    catalog = TypeCatalog([Channel('/t', 'gen_pkg/msg/T0', 'ros2msg', text, 'cdr')], None)
    codec = catalog.codec('gen_pkg/msg/T0')
    missing = reachable & left_out
    assert (codec is None) == bool(missing)
    if codec is None:
        assert any(catalog.why_not('gen_pkg/msg/T0') == f"no usable definition ('{name}')" for name in missing)
    else:
        assert codec.store.get_msgdef('gen_pkg/msg/T0').name == 'gen_pkg/msg/T0'
