#!/usr/bin/env python3
"""Write rover_bench.mcap beside this file: the bag the planted-bug benchmark plays (12 s of a rover).

/imu at 50 Hz, /odom at 25 Hz, /scan at 5 Hz: bagfault's synthetic values (a
rover turning at 0.1 rad/s, yaw = 0.1 t, x = 0.1 t), from bag time
1 700 000 000 s, written with the `mcap` library. The same bytes every time.

    python bench/explore/make_bag.py [PATH]
"""

from __future__ import annotations

import sys
from pathlib import Path

from bagfault.demo import synthetic

DURATION = 12.0
STREAMS = (synthetic.Stream('/imu', 'sensor_msgs/msg/Imu', 50.0),
           synthetic.Stream('/odom', 'nav_msgs/msg/Odometry', 25.0),
           synthetic.Stream('/scan', 'sensor_msgs/msg/LaserScan', 5.0))


def write(path: Path) -> Path:
    """The benchmark bag at `path`."""
    synthetic.write_mcap(path, synthetic.messages(STREAMS, DURATION))
    return path


if __name__ == '__main__':
    print(write(Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).with_name('rover_bench.mcap')))
