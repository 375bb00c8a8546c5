"""
Message conversions of the planner (ROS message types only, no node, no spinning).

``occupancy_grid`` turns ``SemiSingularRegion.to_grid`` into ``nav_msgs/OccupancyGrid``:
100 = semi-singular (the cell touches the region), 0 = nonsingular and within reach,
-1 (unknown) = out of the arm's reach; row 0 is the bottom row (``y_min``), as both
``to_grid`` and OccupancyGrid lay it out, so the data is ``grid.ravel()``.
"""

import array

from freejoint_common.contract import PLAN_OUTCOME, SEMI_SINGULAR_MAP, SETPOINTS
from freejoint_common.contract import stamp_from_ns
from geometry_msgs.msg import Point
import numpy as np
from visualization_msgs.msg import Marker

from .stream import SpatialSetpoint


def setpoints_msg(setpoints, frame_id):
    """
    Return the ``freejoint_msgs/CartesianSetpoints`` of stream setpoints (in stamp order).

    ``stream.Setpoint`` (planar, m = 2) or ``stream.SpatialSetpoint`` (m = 3), one kind per
    batch; its header: the first setpoint's stamp (0 when ``setpoints`` is empty),
    ``frame_id``. ``freejoint_common.contract.setpoint_samples`` reads it back.
    """
    msg = SETPOINTS.msg_type()
    msg.header.frame_id = frame_id
    if not setpoints:
        return msg
    stamp_from_ns(setpoints[0].stamp_ns, msg.header.stamp)
    msg.stamps = array.array('q', [sp.stamp_ns for sp in setpoints])
    if type(setpoints[0]) is SpatialSetpoint:
        msg.position = array.array('d', [v for sp in setpoints for v in sp.position])
        msg.velocity = array.array('d', [v for sp in setpoints for v in sp.velocity])
        msg.acceleration = array.array('d', [v for sp in setpoints for v in sp.acceleration])
    else:
        msg.position = array.array('d', [v for sp in setpoints for v in (sp.px, sp.py)])
        msg.velocity = array.array('d', [v for sp in setpoints for v in (sp.vx, sp.vy)])
        msg.acceleration = array.array('d', [v for sp in setpoints for v in (sp.ax, sp.ay)])
    msg.plan_id = array.array('I', [sp.plan_id for sp in setpoints])
    msg.plan_time = array.array('d', [sp.plan_time for sp in setpoints])
    msg.final = [bool(sp.final) for sp in setpoints]
    return msg


def occupancy_grid(grid, extent, cell, frame_id, stamp_ns):
    """
    Return a ``nav_msgs/OccupancyGrid`` of an int8 grid from ``SemiSingularRegion.to_grid``.

    Parameters
    ----------
    grid : numpy.ndarray of int8, shape (ny, nx)
        Row 0 at ``y_min``, column 0 at ``x_min``; values 100, 0, -1.
    extent : sequence of float, shape (4,)
        ``(x_min, x_max, y_min, y_max)`` (m) the grid was made for.
    cell : float
        Cell size (m).
    frame_id : str
        Frame of the grid (the arm's base frame).
    stamp_ns : int
        Header stamp and map load time (ns).

    Returns
    -------
    nav_msgs.msg.OccupancyGrid

    """
    grid = np.asarray(grid)
    if grid.ndim != 2 or grid.dtype != np.int8:
        raise ValueError(f'grid: expected a 2-D int8 array, got {grid.dtype} {grid.shape}')
    msg = SEMI_SINGULAR_MAP.msg_type()
    msg.header.stamp = stamp_from_ns(stamp_ns)
    msg.header.frame_id = frame_id
    msg.info.map_load_time = stamp_from_ns(stamp_ns)
    msg.info.resolution = float(cell)
    msg.info.height, msg.info.width = (int(n) for n in grid.shape)
    msg.info.origin.position.x = float(extent[0])
    msg.info.origin.position.y = float(extent[2])
    msg.info.origin.orientation.w = 1.0
    msg.data = array.array('b', np.ascontiguousarray(grid).tobytes())
    return msg


def path_marker(points, frame_id, stamp_ns, plan_id=0, width=0.005):
    """
    Return a ``visualization_msgs/Marker`` LINE_STRIP through ``points`` (m, (N, 2) or (N, 3)).

    Namespace ``planned_path``, id 0 (each new plan replaces the previous line), green,
    line width ``width`` (m), no lifetime (stays until replaced).
    """
    msg = Marker()
    msg.header.stamp = stamp_from_ns(stamp_ns)
    msg.header.frame_id = frame_id
    msg.ns = 'planned_path'
    msg.id = 0
    msg.type = Marker.LINE_STRIP
    msg.action = Marker.ADD
    msg.pose.orientation.w = 1.0
    msg.scale.x = float(width)
    msg.color.r, msg.color.g, msg.color.b, msg.color.a = 0.1, 0.8, 0.2, 1.0
    msg.text = f'plan {int(plan_id)}'
    pts = np.asarray(points, dtype=float)
    if pts.ndim == 2 and pts.shape[1] == 3:     # a spatial plan
        msg.points = [Point(x=float(x), y=float(y), z=float(z)) for x, y, z in pts]
    else:
        msg.points = [Point(x=float(x), y=float(y), z=0.0) for x, y in pts]
    return msg


def outcome_msg(outcome):
    """Return the ``freejoint_msgs/PlanOutcome`` of a ``plan_goal.Outcome``."""
    return PLAN_OUTCOME.msg_type(
        stamp=stamp_from_ns(max(outcome.stamp_ns, 0)), plan_id=outcome.plan_id,
        code=outcome.code, code_name=outcome.code_name, message=outcome.message,
        planned_duration=float(outcome.planned_duration), elapsed=float(outcome.elapsed),
        lateness=float(outcome.lateness), time_paused=float(outcome.time_paused),
        pauses=outcome.pauses, max_path_error=float(outcome.max_path_error))
