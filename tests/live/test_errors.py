"""Live commands refuse bad input with one line and exit code 2, before touching the graph."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def bagfault(env: dict[str, str] | None, *args: str, block_rclpy: bool = False) -> subprocess.CompletedProcess[str]:
    prelude = "import sys; sys.modules['rclpy'] = None; " if block_rclpy else 'import sys; '
    code = prelude + 'from bagfault.cli import main; sys.exit(main(sys.argv[1:]))'
    return subprocess.run([sys.executable, '-c', code, *args], capture_output=True, text=True, env=env, cwd=ROOT,
                          timeout=120, check=False)


def one_error_line(done: subprocess.CompletedProcess[str]) -> str:
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith('bagfault: error: '), done.stderr
    assert 'Traceback' not in done.stderr
    return lines[0]


def test_without_rclpy_live_commands_say_how_to_get_it(scenarios: Path, tmp_path: Path) -> None:
    for args in (['proxy', str(scenarios / 'imu.yaml')], ['record', '--all', '-o', str(tmp_path / 'r.mcap')],
                 ['play', str(ROOT / 'tests/fixtures/rover_20s.mcap')]):
        line = one_error_line(bagfault(None, *args, block_rclpy=True))
        assert "pip install 'bagfault[live]'" in line


@pytest.mark.parametrize(('scenario', 'expected'), [
    ('injector: {id: imu, type: imu, input_topic: /imu, output_topic: /imu}\nfaults: []\n',
     "injector 'imu' reads and writes /imu; a live proxy needs distinct input_topic and output_topic"),
    ('injector: {id: tf, type: tf, input_topic: /tf_raw, output_topic: /tf}\nfaults: []\n',
     'tf2_msgs/msg/TFMessage: type not installed for rclpy (pip install ros-jazzy-tf2-msgs'),
])
def test_proxy_refuses_what_cannot_work_live(graph, tmp_path: Path, scenario: str, expected: str) -> None:
    from bagfault.live.ros import has_interface

    if 'tf2_msgs' in expected and has_interface('tf2_msgs/msg/TFMessage'):
        pytest.skip('tf2_msgs is installed here')
    path = tmp_path / 'scenario.yaml'
    path.write_text(scenario)
    record = tmp_path / 'out.mcap'
    line = one_error_line(bagfault(graph.env, 'proxy', str(path), '--record', str(record)))
    assert expected in line
    assert list(tmp_path.iterdir()) == [path]  # no recording, no partial file


def test_record_and_play_argument_errors(graph, tmp_path: Path) -> None:
    assert 'give topics to record or --all' in one_error_line(bagfault(graph.env, 'record', '-o', str(tmp_path / 'r.mcap')))
    line = one_error_line(bagfault(graph.env, 'record', '/x', '-o', str(tmp_path / 'missing' / 'r.mcap')))
    assert 'does not exist' in line
    line = one_error_line(bagfault(graph.env, 'play', str(tmp_path / 'nothing.mcap')))
    assert 'nothing.mcap' in line
    line = one_error_line(bagfault(graph.env, 'play', str(ROOT / 'tests/fixtures/rover_20s.mcap'), '--rate', '0'))
    assert '--rate 0: must be above 0' in line
