"""freejoint run tools: recorder, player and offline analysis of rosbag2 (MCAP) bags."""
