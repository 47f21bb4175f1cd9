"""File sources and sinks: MCAP, rosbag2 (sqlite3/mcap), ROS 1; the MCAP writer; message types."""
