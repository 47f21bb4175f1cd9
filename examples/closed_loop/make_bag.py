#!/usr/bin/env python3
"""Write rover.mcap beside this file: 12 s of a rover turning at 0.1 rad/s, /imu at 100 Hz and /odom at 50 Hz.

The values are bagfault's synthetic ones (IMU and odometry agree on the yaw
rate), written with the `mcap` library; the bag is the same every time.
"""

from __future__ import annotations

import sys
from pathlib import Path

from bagfault.demo import synthetic


def write(path: Path, duration: float = 12.0) -> Path:
    """The example bag at `path`."""
    streams = [synthetic.Stream('/imu', 'sensor_msgs/msg/Imu', 100.0),
               synthetic.Stream('/odom', 'nav_msgs/msg/Odometry', 50.0)]
    synthetic.write_mcap(path, synthetic.messages(streams, duration))
    return path


if __name__ == '__main__':
    target = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).with_name('rover.mcap')
    print(write(target))
