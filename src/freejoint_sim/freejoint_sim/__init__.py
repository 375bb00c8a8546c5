"""freejoint_sim: the simulated arm with a free joint as a ROS 2 node."""
