"""Third-party bag directories that rosbag2 itself can read, and their expected counts."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import yaml

ROSBAG2_DIRS = [
    'rosbag2-dashing/rosbag2_tests/resources/cdr_test',
    'rosbag2-foxy/rosbag2_tests/resources/cdr_test',
    'rosbag2-foxy/ros2bag/test/resources/empty_bag',
    'rosbag2/ros2bag/test/resources/empty_bag',
    'rosbag2/rosbag2_py/test/resources/mcap/convert_a',
    'rosbag2/rosbag2_py/test/resources/mcap/convert_b',
    'rosbag2/rosbag2_py/test/resources/mcap/talker',
    'rosbag2/rosbag2_py/test/resources/mcap/wbag',
    'rosbag2/rosbag2_py/test/resources/sqlite3/convert_a',
    'rosbag2/rosbag2_py/test/resources/sqlite3/convert_b',
    'rosbag2/rosbag2_py/test/resources/sqlite3/talker',
    'rosbag2/rosbag2_py/test/resources/sqlite3/wbag',
    'rosbag2/rosbag2_tests/resources/mcap/bag_with_topics_and_service_events',
    'rosbag2/rosbag2_tests/resources/mcap/cdr_test',
    'rosbag2/rosbag2_tests/resources/sqlite3/bag_with_topics_and_service_events',
    'rosbag2/rosbag2_tests/resources/sqlite3/cdr_test',
    'rosbag2/rosbag2_transport/test/resources/mcap/rewriter_a',
    'rosbag2/rosbag2_transport/test/resources/mcap/rewriter_b',
    'rosbag2/rosbag2_transport/test/resources/mcap/test_bag_for_seek',
    'rosbag2/rosbag2_transport/test/resources/sqlite3/rewriter_a',
    'rosbag2/rosbag2_transport/test/resources/sqlite3/rewriter_b',
    'rosbag2/rosbag2_transport/test/resources/sqlite3/test_bag_for_seek',
    'rosbags-rs/tests/test_bags/test_bag_mcap',
    'rosbags-rs/tests/test_bags/test_bag_sqlite3',
    'evo/test/data/tf_example',
    'Turtlebot_Walker_Algorithm_ROS2/walker_bag_topics_list',
]


def metadata_counts(path: Path) -> Counter[str]:
    info = yaml.safe_load((path / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    return Counter({t['topic_metadata']['name']: t['message_count'] for t in info['topics_with_message_count']
                    if t['message_count']})
