"""Full rewrites: bagfault against rosbags-convert on one bag as rosbag2 sqlite3 and as ROS 1; compression levels.

    python bench/rewrite.py [--seconds 300] [--repeat 3] [--json bench/results/rewrite.json]

The sensor-heavy bag of bench/run.py is written once more as a rosbag2
sqlite3 folder (rosbags' writer, uncompressed, as `ros2 bag record` does by
default). Then, alternating, each in its own process:
- `rosbags-convert --src BAG --dst OUT --dst-storage mcap` (its default:
  uncompressed chunks), and with `--compress zstd --compress-mode storage`
  (zstd chunks, as bagfault writes);
- the same two on the bag as a ROS 1 bag (made once with rosbags-convert),
  and `bagfault run` on it (every message converted from ROS 1 to CDR);
- `bagfault run` with a scenario that has faults defined and none active, on
  the sqlite3 folder (every message read and written: no chunk to copy), at
  zstd levels 1 (the default, the MCAP C++ writer's) and 3 (bagfault's before);
- the same on the MCAP bag with `--no-chunk-copy`.
Prints medians of wall and CPU seconds and output sizes; ratios against
rosbags-convert's default on the same input format.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import time
from datetime import date
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
from bagfault.demo.workloads import scenario  # noqa: E402
from bench.run import JOB_ENV, ensure_bag  # noqa: E402

DATA = HERE / 'data'
BIN = Path(sys.executable).parent


def sqlite_copy(bag: Path) -> Path:
    """The MCAP bag as a rosbag2 sqlite3 folder (once)."""
    from mcap.reader import make_reader
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    folder = bag.with_suffix('.sqlite3')
    if folder.exists():
        return folder
    started = time.perf_counter()
    store = get_typestore(Stores.ROS2_JAZZY)  # the bench bag's types are all standard ones
    with bag.open('rb') as stream, Writer(folder, version=9, storage_plugin=StoragePlugin.SQLITE3) as writer:
        reader = make_reader(stream)
        connections = {}
        for schema, channel, message in reader.iter_messages(log_time_order=True):
            if channel.id not in connections:
                connections[channel.id] = writer.add_connection(channel.topic, schema.name, typestore=store)
            writer.write(connections[channel.id], message.log_time, message.data)
    print(f'wrote {folder.name} in {time.perf_counter() - started:.0f} s', flush=True)
    return folder


def ros1_copy(bag: Path) -> Path:
    """The MCAP bag as a ROS 1 bag (once), converted by rosbags-convert."""
    ros1 = bag.with_suffix('.bag')
    if not ros1.exists():
        subprocess.run([str(BIN / 'rosbags-convert'), '--src', str(bag), '--dst', str(ros1)], check=True)
    return ros1


def timed(command: list[str]) -> tuple[float, float]:
    """Wall and CPU seconds of one command (its whole process tree)."""
    os.sync()
    before = os.times()
    started = time.perf_counter()
    subprocess.run(command, check=True, stdout=subprocess.DEVNULL, env=JOB_ENV)
    elapsed = time.perf_counter() - started
    after = os.times()
    return elapsed, (after.children_user - before.children_user) + (after.children_system - before.children_system)


def main() -> int:
    """Alternate the jobs, print the table, write JSON."""
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--seconds', type=float, default=300.0)
    parser.add_argument('--repeat', type=int, default=3)
    parser.add_argument('--json', type=Path, default=None)
    args = parser.parse_args()
    bag = ensure_bag('sensor-heavy', args.seconds)
    folder = sqlite_copy(bag)
    ros1 = ros1_copy(bag)
    scenario_file = DATA / 'rewrite-scenario.yaml'
    scenario_file.write_text(scenario('sensor-heavy', 'a'))
    out_dir, out_file = DATA / 'rewrite-out', DATA / 'rewrite-out.mcap'
    bagfault = [str(BIN / 'bagfault'), 'run', str(scenario_file)]
    jobs = {
        'rosbags-convert (sqlite3 -> mcap)': ['rosbags-convert', '--src', str(folder), '--dst', str(out_dir),
                                              '--dst-storage', 'mcap'],
        'rosbags-convert, zstd storage': ['rosbags-convert', '--src', str(folder), '--dst', str(out_dir),
                                          '--dst-storage', 'mcap', '--compress', 'zstd', '--compress-mode', 'storage'],
        'bagfault, sqlite3, zstd 1 (default)': [*bagfault, str(folder), '-o', str(out_file), '--force'],
        'bagfault, sqlite3, zstd 3': [*bagfault, str(folder), '-o', str(out_file), '--force',
                                      '--compression-level', '3'],
        'bagfault, sqlite3, lz4': [*bagfault, str(folder), '-o', str(out_file), '--force', '--compression', 'lz4'],
        'rosbags-convert (ros1 -> mcap)': ['rosbags-convert', '--src', str(ros1), '--dst', str(out_dir),
                                           '--dst-storage', 'mcap'],
        'rosbags-convert, ros1, zstd storage': ['rosbags-convert', '--src', str(ros1), '--dst', str(out_dir),
                                                '--dst-storage', 'mcap', '--compress', 'zstd',
                                                '--compress-mode', 'storage'],
        'bagfault, ros1, zstd 1 (default)': [*bagfault, str(ros1), '-o', str(out_file), '--force'],
        'bagfault, mcap, --no-chunk-copy, zstd 1': [*bagfault, str(bag), '-o', str(out_file), '--force',
                                                    '--no-chunk-copy'],
    }
    for command in jobs.values():
        if command[0] == 'rosbags-convert':
            command[0] = str(BIN / 'rosbags-convert')
    samples: dict[str, list[tuple[float, float]]] = {name: [] for name in jobs}
    sizes: dict[str, int] = {}
    for _ in range(args.repeat):
        for name, command in jobs.items():
            samples[name].append(timed(command))
            made = out_file if out_file.exists() else next(out_dir.glob('*.mcap'))
            sizes[name] = made.stat().st_size
            shutil.rmtree(out_dir, ignore_errors=True)
            out_file.unlink(missing_ok=True)
    def base(name: str) -> float:
        """rosbags-convert's median on the job's input format."""
        reference = 'rosbags-convert (ros1 -> mcap)' if 'ros1' in name else 'rosbags-convert (sqlite3 -> mcap)'
        return statistics.median(t for t, _ in samples[reference])

    results = {name: {'seconds': statistics.median(t for t, _ in runs),
                      'cpu_seconds': statistics.median(c for _, c in runs),
                      'runs': [t for t, _ in runs], 'output_mb': sizes[name] / 1e6,
                      'faster_than_rosbags_convert': base(name) / statistics.median(t for t, _ in runs)}
               for name, runs in samples.items()}
    print(f'full rewrite: {bag.name} ({bag.stat().st_size / 1e6:.0f} MB as MCAP, {ros1.stat().st_size / 1e6:.0f} MB'
          f' as ROS 1), load {os.getloadavg()[0]:.1f}')
    print(f'  {"job":<42}{"median s":>10}{"CPU s":>8}{"out MB":>8}{"x faster":>10}')
    for name, entry in results.items():
        print(f'  {name:<42}{entry["seconds"]:>10.2f}{entry["cpu_seconds"]:>8.2f}{entry["output_mb"]:>8.0f}'
              f'{entry["faster_than_rosbags_convert"]:>10.2f}')
    report = {'date': date.today().isoformat(), 'machine': platform.platform(), 'cpus': os.cpu_count(),
              'load': os.getloadavg()[0],
              'bag': bag.name, 'repeat': args.repeat, 'results': results}
    path = args.json or HERE / 'results' / f'rewrite-{report["date"]}.json'
    path.write_text(json.dumps(report, indent=1, sort_keys=True) + '\n')
    print(f'results written to {path}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
