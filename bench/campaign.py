"""Campaign throughput: the same offline campaign on a local pool of 1 and 2 workers and on Ray (2 CPUs).

    python bench/campaign.py [--bags 4] [--seconds 60] [--json bench/results/campaign.json]

Each bag is a synthetic rover log (/imu 200 Hz, /odom 50 Hz, /scan 10 Hz
with 720 beams); the sweep is 3 IMU biases x 2 seeds per bag, each job a
full `run` with the fault manager and one assertion. Reported: wall time,
jobs per second, a job's CPU seconds (median), the cores the jobs kept busy
(their CPU seconds over the jobs phase), the 2-worker speed-up and
Ray's time against the local pool's. Not a test: numbers depend on the
machine.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import time
from datetime import date
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
STREAMS = [('/imu', 'sensor_msgs/msg/Imu', 200.0), ('/odom', 'nav_msgs/msg/Odometry', 50.0),
           ('/scan', 'sensor_msgs/msg/LaserScan', 10.0)]
SCENARIO = """
name: drift_bench
injectors:
  - {id: imu, type: imu, input_topic: /imu, output_topic: /imu}
faults:
  - {id: bias, injector_id: imu, start: 5.0, duration: 20.0, config: {angular_velocity_z_bias: 0.0,
     angular_velocity_z_noise_stddev: 0.01}}
fault_manager:
  confirmation_threshold: -3
  conditions: [{topic: /imu, when: {field: angular_velocity.z, above: 0.6}, code: IMU_DRIFT}]
assertions:
  - {id: drift_detected, type: fault_status, code: IMU_DRIFT, status: CONFIRMED, after: bias, within: 2.0}
"""
CAMPAIGN = """
campaign: bench
scenario: drift.yaml
bags: [bags/*.mcap]
sweep:
  faults.bias.config.angular_velocity_z_bias: [0.05, 0.2, 0.5]
seeds: [0, 1]
keep: none
"""


def clock_progress() -> Any:
    """A JobProgress that notes when the jobs began (the engine is up) and when the last one ended."""
    from bagfault.progress import JobProgress

    class Clock(JobProgress):
        first: float | None = None
        last = 0.0

        def add(self, total: int, cached: int) -> None:
            self.first = self.first or time.monotonic()
            super().add(total, cached)

        def finished(self, status: str) -> None:
            self.last = time.monotonic()
            super().finished(status)

    return Clock(enabled=False)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--bags', type=int, default=4)
    parser.add_argument('--seconds', type=float, default=60.0)
    parser.add_argument('--json', type=Path, default=None)
    args = parser.parse_args()
    os.environ.setdefault('RAY_USAGE_STATS_ENABLED', '0')
    from bagfault import api
    from bagfault.demo import synthetic

    with tempfile.TemporaryDirectory(prefix='bagfault-campaign-bench-') as tmp:
        folder = Path(tmp)
        (folder / 'bags').mkdir()
        specs = [synthetic.Stream(t, m, r) for t, m, r in STREAMS]
        for k in range(args.bags):
            synthetic.write_mcap(folder / 'bags' / f'route{k}.mcap', synthetic.messages(
                specs, args.seconds, start=synthetic.DEFAULT_START + k * 10**12))
        (folder / 'drift.yaml').write_text(SCENARIO)
        (folder / 'campaign.yaml').write_text(CAMPAIGN)
        size = sum(p.stat().st_size for p in (folder / 'bags').iterdir())
        runs = {}
        for name, options in [('local, 1 worker', {'workers': 1}), ('local, 2 workers', {'workers': 2}),
                              ('Ray, 2 CPUs', {'ray': '', 'workers': 2})]:
            clock = clock_progress()
            started = time.monotonic()
            result = api.campaign(folder / 'campaign.yaml', folder / name.replace(' ', '').replace(',', '_'),
                                  progress=clock, **options)  # type: ignore[arg-type]
            seconds = time.monotonic() - started
            jobs_phase = clock.last - (clock.first or started)
            jobs = len(result.table.rows)
            runs[name] = {'seconds': round(seconds, 2), 'jobs_seconds': round(jobs_phase, 2), 'jobs': jobs,
                          'jobs_per_s': round(jobs / jobs_phase, 3),
                          'job_seconds_mean': round(sum(r['seconds'] for r in result.table.rows) / jobs, 3),
                          'job_cpu_seconds_median': statistics.median(r['cpu_s'] for r in result.table.rows),
                          # the jobs' own CPU over the jobs phase: how many cores the jobs kept busy (the driver's
                          # and the engine's own work not counted)
                          'cores_busy': round(sum(r['cpu_s'] for r in result.table.rows) / jobs_phase, 2)}
            print(f'{name:18} {jobs} jobs in {seconds:6.1f} s, of which jobs {jobs_phase:6.1f} s: '
                  f'{jobs / jobs_phase:5.2f} jobs/s  (a job {runs[name]["job_seconds_mean"]:.2f} s, '
                  f'{runs[name]["job_cpu_seconds_median"]:.2f} s of CPU; {runs[name]["cores_busy"]:.2f} cores busy)',
                  flush=True)
    one, two, ray = (runs[k]['jobs_seconds'] for k in runs)
    summary = {'speedup_2_workers': round(one / two, 2), 'ray_vs_local_2': round(ray / two, 3),
               'ray_vs_local_2_with_start': round(runs['Ray, 2 CPUs']['seconds'] / runs['local, 2 workers']['seconds'],
                                                  3)}
    print(f'2 workers: {one / two:.2f}x the speed of 1 (target >= 1.7); Ray: {ray / two:.3f}x the time of the '
          f'local pool for the jobs (target <= 1.15), {summary["ray_vs_local_2_with_start"]:.3f}x with starting '
          'and stopping its instance')
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({'date': date.today().isoformat(), 'bags': args.bags,
                                         'bag_seconds': args.seconds, 'bag_bytes': size, 'runs': runs,
                                         **summary}, indent=1) + '\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())
