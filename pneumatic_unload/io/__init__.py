"""ROS-free input/output of tank-discharge data: rosbag2 bags (MCAP) and data-logger CSV files."""
