"""Helpers the tests share: bags and readers (helpers), the third-party cases (io_cases), a live ROS graph of peer
processes (livegraph), HTML reports in Chromium (html_check), rosbag2's metadata rules (rosbag2_rules), an output
through independent readers (toolchain), `bagfault test` as a user runs it (loop), a campaign corpus (corpus)."""
