"""bagfault benchmark: bagfault against the MCAP copy limit and a hand-written rosbags loop.

    python bench/run.py [--seconds 60] [--repeat 3] [--long 600] [--json bench/results/out.json]

Generates the deterministic bags (bench/bags.py) into bench/data, then runs
in one go, alternating the contestants each repetition, every job in its
own process (peak RSS per job):
- limit: read every message with the `mcap` library and write it unchanged
  (same zstd compression);
- hand-written: what a user writes today with rosbags + mcap (decode every
  message, bias and noise on the IMU, re-encode, write);
- bagfault (a) faults defined, none active; (b) IMU bias + noise all along;
  (c) PointCloud2 noise + point dropout all along; (d) drop 20 % + delay
  50 ms on every topic;
- chunk copy (--copy, a 300 s sensor-heavy bag): `cp` of the file against
  (a) and (w) an IMU bias active for 10 s, with and without chunk copy, and
  the time a bagfault process takes to start and import before it reads
  anything (the part of every run that `cp` does not have).
Prints median times, throughput, peak RSS and the ratios, and writes JSON.
Jobs run with bytecode caching on (bagfault is byte-compiled first).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import random
import resource
import statistics
import subprocess
import sys
import textwrap
import time
from datetime import date
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
from bagfault.demo.workloads import CASES, KINDS, scenario, write_bag  # noqa: E402

DATA = HERE / 'data'
RESULTS = HERE / 'results'

LIMIT = """
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer
with open(SRC, 'rb') as src, open(DST, 'wb') as dst:
    reader = make_reader(src)
    writer = Writer(dst, compression=CompressionType.ZSTD)
    writer.start(profile='ros2', library='limit')
    ids = {}
    for schema, channel, message in reader.iter_messages(log_time_order=False):
        if channel.id not in ids:
            schema_id = writer.register_schema(schema.name, schema.encoding, schema.data)
            ids[channel.id] = writer.register_channel(channel.topic, channel.message_encoding, schema_id,
                                                      channel.metadata)
        writer.add_message(ids[channel.id], message.log_time, message.data, message.publish_time, message.sequence)
    writer.finish()
"""

HAND = """
import numpy as np
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
store = get_typestore(Stores.EMPTY)
rng = np.random.default_rng(0)
with open(SRC, 'rb') as src, open(DST, 'wb') as dst:
    reader = make_reader(src)
    summary = reader.get_summary()
    types = {}
    for schema in summary.schemas.values():
        types.update(get_types_from_msg(schema.data.decode(), schema.name))
    store.register(types)
    writer = Writer(dst, compression=CompressionType.ZSTD)
    writer.start(profile='ros2', library='hand-written')
    ids = {}
    for schema, channel, message in reader.iter_messages(log_time_order=False):
        if channel.id not in ids:
            schema_id = writer.register_schema(schema.name, schema.encoding, schema.data)
            ids[channel.id] = writer.register_channel(channel.topic, channel.message_encoding, schema_id,
                                                      channel.metadata)
        decoded = store.deserialize_cdr(message.data, schema.name)
        if schema.name == 'sensor_msgs/msg/Imu':
            decoded.angular_velocity.z += 0.05 + rng.normal(0.0, 0.02)
            decoded.linear_acceleration.z += 0.2 + rng.normal(0.0, 0.05)
        data = store.serialize_cdr(decoded, schema.name)
        writer.add_message(ids[channel.id], message.log_time, data, message.publish_time, message.sequence)
    writer.finish()
"""

IMPORT_ONLY = """
from bagfault import api
from bagfault.scenario import parse_scenario
"""

BAGFAULT = IMPORT_ONLY + """
api.run(parse_scenario(SCENARIO), [SRC], DST, seed=1, chunk_copy=CHUNK_COPY == 'yes')
"""

CP = """
import subprocess
subprocess.run(['cp', SRC, DST], check=True)
"""

# `bagfault run` as a user types it: its leading copy starts before the heavy imports (bagfault/engine/lead.py)
CLI = """
import sys
from bagfault.cli import main
sys.argv = ['bagfault', 'run', SCENARIO_FILE, SRC, '-o', DST]
main()  # as the console script calls it
"""

# The kernel copying the input's chunks moved by SHIFT bytes (64 MB copy_file_range calls, as bagfault does): on
# this machine a copy that moves the bytes by an amount that is not a multiple of 64 KiB runs a third slower than
# `cp`'s copy onto the same offsets; bagfault places long copied spans 64 KiB-aligned (mcap_writer.ALIGN)
SHIFTED = """
import os
src, dst = os.open(SRC, os.O_RDONLY), os.open(DST, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
size, at = os.fstat(src).st_size, 43
while at < size:
    part = min(64 << 20, size - at)
    done = 0
    while done < part:
        done += os.copy_file_range(src, dst, part - done, at + done, at + done + int(SHIFT))
    at += part
"""


PEAK_RSS = """
import resource
try:  # the job's own high-water mark (ru_maxrss would include the forking parent's memory)
    with open('/proc/self/status') as status:
        PEAK = int(next(line for line in status if line.startswith('VmHWM')).split()[1]) * 1024
except (OSError, StopIteration):
    PEAK = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
print('peak-rss', PEAK)
"""


# Jobs import from compiled bytecode, as an installed bagfault does (pip compiles it at install time);
# a PYTHONDONTWRITEBYTECODE environment would make every job compile its imports (0.15 s more).
JOB_ENV = {k: v for k, v in os.environ.items() if k != 'PYTHONDONTWRITEBYTECODE'}


class Conditions:
    """Where jobs run: a cold page cache (dropped before each job) and a memory cgroup that bounds the page
    cache (input + output larger than it, as for a bag bigger than the machine's memory). Both need root."""

    cold = False
    cgroup: Path | None = None
    page_cache_gb: float | None = None

    @classmethod
    def limit_page_cache(cls, gigabytes: float) -> None:
        """A memory cgroup (v2, else v1) of that size for every job."""
        unified = Path('/sys/fs/cgroup/cgroup.controllers').exists()
        root, limit = (Path('/sys/fs/cgroup'), 'memory.max') if unified else \
            (Path('/sys/fs/cgroup/memory'), 'memory.limit_in_bytes')
        group = root / 'bagfault-bench'
        group.mkdir(exist_ok=True)
        (group / limit).write_text(str(int(gigabytes * 2**30)))
        cls.cgroup, cls.page_cache_gb = group, gigabytes

    @classmethod
    def enter(cls) -> None:
        """In the job's process before it starts."""
        if cls.cgroup is not None:
            (cls.cgroup / 'cgroup.procs').write_text(str(os.getpid()))


READS: list[int] = []  # bytes each job read from the storage device (not from the page cache), in order


def run_job(code: str, env: dict[str, str] | None = None, **values: str) -> tuple[float, int, float]:
    """Run one job in a fresh process (`env`: added to its environment); return (wall seconds, its peak RSS in
    bytes, its CPU seconds); the bytes it read from the device go to READS."""
    prelude = ''.join(f'{k} = {v!r}\n' for k, v in values.items())
    os.sync()  # the previous job's output is written back before this one is timed, not during it
    if Conditions.cold:
        Path('/proc/sys/vm/drop_caches').write_text('3')
    before, blocks = os.times(), resource.getrusage(resource.RUSAGE_CHILDREN).ru_inblock
    started = time.perf_counter()
    done = subprocess.run([sys.executable, '-c', prelude + textwrap.dedent(code) + PEAK_RSS],
                          stdout=subprocess.PIPE, text=True, check=False, env={**JOB_ENV, **(env or {})},
                          preexec_fn=Conditions.enter)
    elapsed = time.perf_counter() - started
    after = os.times()
    READS.append((resource.getrusage(resource.RUSAGE_CHILDREN).ru_inblock - blocks) * 512)
    if done.returncode != 0:
        raise SystemExit(f'benchmark job failed ({done.returncode}):\n{code}')
    cpu = (after.children_user - before.children_user) + (after.children_system - before.children_system)
    return elapsed, int(done.stdout.split()[-1]), cpu


def ensure_bag(kind: str, seconds: float) -> Path:
    """Generate the bag once per kind and length."""
    DATA.mkdir(parents=True, exist_ok=True)
    path = DATA / f'{kind}-{int(seconds)}s.mcap'
    if not path.exists():
        started = time.perf_counter()
        count = write_bag(path, kind, seconds)
        print(f'generated {path.name}: {count} messages, {path.stat().st_size / 1e6:.0f} MB '
              f'in {time.perf_counter() - started:.1f} s', flush=True)
    return path


def plain_copy(bag: Path) -> Path:
    """The bag as the plain `mcap` writer writes it (as Foxglove and converters do): the same messages and schemas,
    channels without rosbag2's metadata (no offered_qos_profiles), no rosbag2 metadata record."""
    from mcap.reader import make_reader
    from mcap.writer import CompressionType, Writer

    path = bag.with_name(bag.stem + '-plain.mcap')
    if path.exists():
        return path
    with bag.open('rb') as src, path.open('wb') as dst:
        reader = make_reader(src)
        writer = Writer(dst, compression=CompressionType.ZSTD)
        writer.start(profile='ros2', library='plain')
        ids: dict[int, int] = {}
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            if channel.id not in ids:
                schema_id = writer.register_schema(schema.name, schema.encoding, schema.data)
                ids[channel.id] = writer.register_channel(channel.topic, channel.message_encoding, schema_id, {})
            writer.add_message(ids[channel.id], message.log_time, message.data, message.publish_time,
                               message.sequence)
        writer.finish()
    return path


def count_messages(path: Path) -> int:
    """Message count from the MCAP summary."""
    from mcap.reader import make_reader

    with path.open('rb') as stream:
        return make_reader(stream).get_summary().statistics.message_count


def measure(kind: str, seconds: float, repeat: int, include_baselines: bool = True) -> dict[str, dict]:
    """Alternate the contestants `repeat` times on one bag; medians."""
    bag = ensure_bag(kind, seconds)
    out = DATA / 'out.mcap'
    jobs: dict[str, tuple[str, dict[str, str]]] = {}
    if include_baselines:
        jobs['limit'] = (LIMIT, {})
        jobs['hand-written'] = (HAND, {})
    for case in CASES[kind]:
        jobs[f'bagfault ({case})'] = (BAGFAULT, {'SCENARIO': scenario(kind, case), 'CHUNK_COPY': 'yes'})
    samples: dict[str, list[tuple[float, int, float]]] = {name: [] for name in jobs}
    for _ in range(repeat):
        for name, (code, values) in jobs.items():
            samples[name].append(run_job(code, SRC=str(bag), DST=str(out), **values))
            out.unlink(missing_ok=True)
    size, messages = bag.stat().st_size, count_messages(bag)
    results = {}
    for name, runs in samples.items():
        seconds_taken = statistics.median(t for t, _, _ in runs)
        results[name] = {'seconds': seconds_taken, 'runs': [t for t, _, _ in runs],
                         'mb_per_s': size / 1e6 / seconds_taken, 'messages_per_s': messages / seconds_taken,
                         'cpu_seconds': statistics.median(c for _, _, c in runs),
                         'peak_rss_mb': max(r for _, r, _ in runs) / 1e6}
    for entry in results.values():
        if 'limit' in results:
            entry['vs_limit'] = results['limit']['seconds'] / entry['seconds']
        if 'hand-written' in results:
            entry['vs_hand_written'] = results['hand-written']['seconds'] / entry['seconds']
    return {'bag': bag.name, 'bytes': size, 'messages': messages, 'results': results}


def measure_copy(seconds: float, repeat: int, reference: bool = True) -> dict[str, dict]:
    """Chunk copy against `cp` of the same file: no fault active, and an IMU bias active 10 s (from 100 s)."""
    bag = ensure_bag('sensor-heavy', seconds)
    out = DATA / 'out.mcap'
    jobs: dict[str, tuple[str, dict[str, str], dict[str, str]]] = {
        'cp': (CP, {}, {}), 'kernel copy moved 8120 bytes': (SHIFTED, {'SHIFT': '8120'}, {}),
        'kernel copy moved 64 KiB': (SHIFTED, {'SHIFT': '65536'}, {}),
        'start and import only': (IMPORT_ONLY, {}, {})}
    plain = plain_copy(bag)  # the same content from the plain mcap writer: no rosbag2 QoS metadata
    jobs['cp (plain writer)'] = (CP, {'SRC': str(plain)}, {})
    for case, what in (('a', 'none active'), ('w', 'IMU bias 10 s')):
        scenario_file = DATA / f'copy-{case}.yaml'
        scenario_file.write_text(scenario('sensor-heavy', case))
        jobs[f'{what}, bagfault run'] = (CLI, {'SCENARIO_FILE': str(scenario_file)}, {})
        if case == 'a':  # as a user runs it on the plain writer's bag: beside the rosbag2 bag's job of the line above
            jobs[f'{what}, bagfault run (plain writer)'] = (CLI, {'SCENARIO_FILE': str(scenario_file),
                                                                  'SRC': str(plain)}, {})
        for copy in ('yes', 'no') if reference else ('yes',):
            name = f'{what}{"" if copy == "yes" else ", --no-chunk-copy"}'
            jobs[name] = (BAGFAULT, {'SCENARIO': scenario('sensor-heavy', case), 'CHUNK_COPY': copy}, {})
        # the first run on a bag hashes it; later ones recall its digest (bagfault/io/digests.py): a cache
        # folder that cannot be made is a miss every time
        jobs[f'{what}, first run (input hashed)'] = (BAGFAULT, {'SCENARIO': scenario('sensor-heavy', case),
                                                               'CHUNK_COPY': 'yes'},
                                                     {'BAGFAULT_CACHE': '/proc/bagfault-bench-no-cache'})
    samples: dict[str, list[tuple[float, int, float]]] = {name: [] for name in jobs}
    reads: dict[str, list[int]] = {name: [] for name in jobs}
    for each in (bag, plain):  # digests kept, as after a first run: the jobs that are not "first run" recall them
        subprocess.run([sys.executable, '-c', 'import sys; from pathlib import Path; from bagfault.io.sources import '
                        'digests_of; digests_of(Path(sys.argv[1]))', str(each)], check=True, env=JOB_ENV)
    order = random.Random(29)  # each round in its own order: no job always follows the same one
    for _ in range(repeat):
        for name in order.sample(list(jobs), len(jobs)):
            code, values, env = jobs[name]
            samples[name].append(run_job(code, env, **{'SRC': str(bag), 'DST': str(out), **values}))
            reads[name].append(READS[-1])
            out.unlink(missing_ok=True)
    cp = statistics.median(t for t, _, _ in samples['cp'])
    cp_cpu = statistics.median(c for _, _, c in samples['cp'])
    cp_best = min(t for t, _, _ in samples['cp'])  # this machine's copies are bimodal: the fast runs compared too
    results = {name: {'seconds': statistics.median(t for t, _, _ in runs), 'runs': [t for t, _, _ in runs],
                      'vs_cp': statistics.median(t for t, _, _ in runs) / cp,
                      'best_vs_cp': min(t for t, _, _ in runs) / cp_best,
                      'cpu_seconds': statistics.median(c for _, _, c in runs),
                      'cpu_vs_cp': statistics.median(c for _, _, c in runs) / cp_cpu,
                      'read_from_device_gb': statistics.median(reads[name]) / 1e9,
                      'peak_rss_mb': max(r for _, r, _ in runs) / 1e6} for name, runs in samples.items()}
    return {'bag': bag.name, 'bytes': bag.stat().st_size, 'load_before': os.getloadavg()[0],
            'cold': Conditions.cold, 'page_cache_gb': Conditions.page_cache_gb, 'results': results}


def copy_table(block: dict) -> str:
    """Printable table of the chunk copy block."""
    lines = [f'chunk copy: {block["bag"]} ({block["bytes"] / 1e6:.0f} MB)',
             f'  load {block["load_before"]:.1f}, cold cache {block["cold"]}, page cache {block["page_cache_gb"]} GB',
             f'  {"job":<40}{"median s":>10}{"x cp":>8}{"best x cp":>10}{"CPU s":>8}{"CPU x cp":>9}{"RSS MB":>8}'
             f'{"read GB":>9}']
    for name, entry in block['results'].items():
        lines.append(f'  {name:<40}{entry["seconds"]:>10.2f}{entry["vs_cp"]:>8.2f}{entry["best_vs_cp"]:>10.2f}'
                     f'{entry["cpu_seconds"]:>8.2f}{entry["cpu_vs_cp"]:>9.2f}{entry["peak_rss_mb"]:>8.0f}'
                     f'{entry["read_from_device_gb"]:>9.2f}')
    return '\n'.join(lines)


def table(title: str, block: dict) -> str:
    """Printable table of one bag's results."""
    lines = [f'{title}: {block["bag"]} ({block["bytes"] / 1e6:.0f} MB, {block["messages"]} messages)',
             f'  {"job":<16}{"median s":>10}{"MB/s":>9}{"msg/s":>11}{"RSS MB":>8}{"x limit":>9}{"x hand":>8}']
    for name, entry in block['results'].items():
        limit = f'{entry["vs_limit"]:.2f}' if 'vs_limit' in entry else '-'
        hand = f'{entry["vs_hand_written"]:.2f}' if 'vs_hand_written' in entry else '-'
        lines.append(f'  {name:<16}{entry["seconds"]:>10.2f}{entry["mb_per_s"]:>9.1f}{entry["messages_per_s"]:>11.0f}'
                     f'{entry["peak_rss_mb"]:>8.0f}{limit:>9}{hand:>8}')
    return '\n'.join(lines)


def main() -> int:
    """Run everything, print the tables, write JSON."""
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--seconds', type=float, default=60.0, help='bag length for the speed comparison')
    parser.add_argument('--repeat', type=int, default=3, help='alternating repetitions (medians)')
    parser.add_argument('--long', type=float, default=600.0, help='bag length for the memory check (0: skip)')
    parser.add_argument('--copy', type=float, default=300.0,
                        help='sensor-heavy bag length for chunk copy against cp (0: skip)')
    parser.add_argument('--only-copy', action='store_true', help='run the chunk copy block only')
    parser.add_argument('--no-reference', action='store_true',
                        help='chunk copy block without the --no-chunk-copy jobs (minutes each on long bags)')
    parser.add_argument('--cold', action='store_true', help='drop the page cache before every job (root)')
    parser.add_argument('--page-cache-gb', type=float, default=None,
                        help='run every job in a memory cgroup of this size, bounding its page cache (root)')
    parser.add_argument('--json', type=Path, default=None)
    args = parser.parse_args()
    Conditions.cold = args.cold
    if args.page_cache_gb:
        Conditions.limit_page_cache(args.page_cache_gb)
    subprocess.run([sys.executable, '-m', 'compileall', '-q', str(Path(__file__).resolve().parents[1] / 'bagfault')],
                   check=True, env=JOB_ENV)
    report: dict = {'date': date.today().isoformat(), 'machine': platform.platform(), 'cpus': os.cpu_count(),
                    'python': platform.python_version(), 'seconds': args.seconds, 'repeat': args.repeat,
                    'speed': {}, 'memory': {}}
    if args.copy:
        report['chunk_copy'] = measure_copy(args.copy, args.repeat, not args.no_reference)
        print(copy_table(report['chunk_copy']), flush=True)
    if args.only_copy:
        save(report, args.json or RESULTS / f'bench-copy-{report["date"]}.json')
        return 0
    for kind in KINDS:
        block = measure(kind, args.seconds, args.repeat)
        report['speed'][kind] = block
        print(table(f'{kind}, {args.seconds:g} s', block), flush=True)
    if args.long:
        for kind in KINDS:
            block = measure(kind, args.long, 1, include_baselines=False)
            report['memory'][kind] = block
            print(table(f'{kind}, {args.long:g} s (memory)', block), flush=True)
            (DATA / f'{kind}-{int(args.long)}s.mcap').unlink(missing_ok=True)
    save(report, args.json or RESULTS / f'bench-{report["date"]}.json')
    return 0


def save(report: dict, path: Path) -> None:
    """Write a results JSON (stable key order) and say where."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(report, indent=1, sort_keys=True) + '\n')
    print(f'results written to {path}')


if __name__ == '__main__':
    sys.exit(main())
