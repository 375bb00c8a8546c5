"""freejoint core: the math of the paper, plain Python/numpy, no ROS imports."""
