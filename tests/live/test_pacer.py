"""The pacer's timeline when bagfault itself stalls (a busy machine): with `hold_stalls` (the closed loop's sim
time) the timeline holds for the stall and goes on at its rate; without (play on wall time, as `ros2 bag play`
keeps its schedule) the records due meanwhile come at once. No ROS: a bare Pacer and a view that records when
each record was shown; the stall is a sleep inside the view's write of one record, as a stalled process would
take it."""

from __future__ import annotations

import time

import pytest

from bagfault.engine.stop import StopFlag
from bagfault.live.pacer import STALL, Pacer

NS = 1_000_000_000
PERIOD = 0.02  # seconds of bag time between records
STALLED_AT = 10  # the record whose handling stalls
STALL_SECONDS = 0.6


class StallingView:
    """Shows records; notes the wall time each is shown at; stalls once."""

    def __init__(self) -> None:
        self.shown: list[float] = []
        self.played_times: list[int] = []

    def add_channel(self, topic: str, msgtype: str, schema_encoding: str, schema_text: str,
                    message_encoding: str = 'cdr') -> int:
        return 0

    def write(self, channel_id: int, log_time: int, data: bytes | memoryview) -> None:
        self.shown.append(time.monotonic())
        if len(self.shown) == STALLED_AT:
            time.sleep(STALL_SECONDS)

    def attach(self, run: object) -> None:
        pass

    def played(self, bag_time: int) -> None:
        self.played_times.append(bag_time)


def play(*, hold_stalls: bool, count: int = 30) -> tuple[list[float], Pacer]:
    view = StallingView()
    pacer = Pacer(rate=1.0, stop=StopFlag(), view=view, hold_stalls=hold_stalls)
    channel = pacer.add_channel('/imu', 'sensor_msgs/msg/Imu', 'ros2msg', 'x')
    for k in range(count):
        bag_time = 1_000 * NS + round(k * PERIOD * NS)
        pacer.gate(bag_time)
        pacer.write(channel, bag_time, bag_time, b'\x00')
    return view.shown, pacer


def test_a_stall_of_bagfault_holds_the_timeline_and_the_rate_goes_on() -> None:
    shown, pacer = play(hold_stalls=True)
    after = shown[STALLED_AT]  # the record after the stalled one
    stall_ended = shown[STALLED_AT - 1] + STALL_SECONDS
    # by construction: the next record is due one period after the timeline resumed, not at once
    assert after - stall_ended == pytest.approx(PERIOD, abs=0.015)
    # and every later one a period apart on average: the rate is kept after the stall
    assert (shown[-1] - after) / (len(shown) - 1 - STALLED_AT) == pytest.approx(PERIOD, abs=0.005)
    assert pacer.held == pytest.approx(STALL_SECONDS, abs=0.1) and pacer.held > STALL


def test_without_holding_the_records_due_during_a_stall_come_at_once() -> None:
    shown, pacer = play(hold_stalls=False)
    burst = shown[STALLED_AT:STALLED_AT + 25]  # 0.5 s of records were due during the 0.6 s stall
    assert burst[-1] - burst[0] < 0.05 and pacer.held == 0.0


def test_a_pause_is_no_stall() -> None:
    view = StallingView()
    pacer = Pacer(rate=1.0, stop=StopFlag(), view=view, hold_stalls=True)
    channel = pacer.add_channel('/imu', 'sensor_msgs/msg/Imu', 'ros2msg', 'x')
    for k in range(5):
        bag_time = round(k * PERIOD * NS)
        if k == 3:
            pacer.pause()
            time.sleep(0.3)
            pacer.resume()
        pacer.gate(bag_time)
        pacer.write(channel, bag_time, bag_time, b'\x00')
    assert pacer.held == 0.0
