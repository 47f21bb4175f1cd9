"""Does the system under test follow the bag's sim time? Two looks from outside, for runs at `--rate` other than 1.

At rate 1 sim time and wall time advance alike, so a system that reads the
wall clock still gives the right verdicts; at any other rate it does not.
Two things betray it without touching the system:

- stamps: a header stamp near the wall clock and far from the bag time at
  which the message arrived (`now()` of a node without use_sim_time, or
  `time.time()`), which misleads any verdict on stamps at every rate;
- publication: messages heard while the sim clock stands still. Before the
  first record no /clock has been published, so sim time is zero and no
  sim-time timer fires; at rates other than 1 the link holds the clock
  still for HOLD seconds there, and a topic heard at least twice in that
  time is published on a wall-clock timer.

Logic that reads the wall clock inside (diagnostic_updater's Python
FrequencyStatus and TimeStampStatus use `time.time()`) is invisible from
outside; the README says when `--rate 1` is required.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field

from bagfault.units import NS

HOLD = 1.0  # seconds the sim clock stands still before the first record when rate != 1
GRACE = 0.2  # seconds at the start of the hold not counted (what was in flight, a latched topic's history)
STAMP_SLACK = NS  # ns a stamp may differ from the clock it follows
SAME_CLOCKS = 10_000_000_000  # ns: bag time this close to wall time cannot tell the two apart


@dataclass
class ClockCheck:
    """Per topic of the system: messages heard while the clock stood still, stamps near wall time."""

    rate: float
    held: dict[str, int] = field(default_factory=dict)
    wall_stamps: dict[str, int] = field(default_factory=dict)
    stamps: dict[str, int] = field(default_factory=dict)

    def during_hold(self, topic: str) -> None:
        """A message of `topic` arrived while the sim clock stood still."""
        self.held[topic] = self.held.get(topic, 0) + 1

    def stamp(self, topic: str, data: bytes | memoryview, bag_time: int, wall_time: int) -> None:
        """Look at the header stamp of a message that arrived at `bag_time` (the sim time) and `wall_time`."""
        if len(data) < 12 or abs(bag_time - wall_time) < SAME_CLOCKS:
            return
        sec, nanosec = struct.unpack_from('<iI' if data[1] else '>iI', data, 4)
        stamp = sec * NS + nanosec
        self.stamps[topic] = self.stamps.get(topic, 0) + 1
        if abs(stamp - wall_time) < STAMP_SLACK and abs(stamp - bag_time) > STAMP_SLACK:
            self.wall_stamps[topic] = self.wall_stamps.get(topic, 0) + 1

    def warnings(self) -> list[str]:
        """One line per topic that follows wall time."""
        lines = [f'{topic}: published {count} times while the sim clock stood still ({HOLD:g} s before the first '
                 f'/clock): the system under test publishes it on a wall-clock timer, so at --rate {self.rate:g} '
                 "its rate and deadlines are not the bag's; run with --rate 1"
                 for topic, count in sorted(self.held.items()) if count >= 2 and self.rate != 1]
        lines += [f"{topic}: {count} of {self.stamps[topic]} header stamps follow the wall clock, not the bag's "
                  'sim time (the node does not read /clock): verdicts on these stamps compare two clocks'
                  for topic, count in sorted(self.wall_stamps.items()) if count * 2 > self.stamps[topic]]
        return lines
