"""
One end-effector setpoint with m values per vector, as plain Python (no ROS).

The record the planner's spatial stream produces (``freejoint_planner.stream``, where it
is ``SpatialSetpoint``) and ``freejoint_common.contract.setpoint_samples`` reads out of a
``setpoints`` batch.
"""

from typing import NamedTuple


class SetpointSample(NamedTuple):
    """One setpoint: its stamp [ns], m-value vectors [m, m/s, m/s^2], its plan's fields."""

    stamp_ns: int
    position: tuple
    velocity: tuple
    acceleration: tuple
    plan_id: int
    plan_time: float
    final: bool
