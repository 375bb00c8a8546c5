"""freejoint_control: the robust controller node and the run-record conversion."""
