"""The planner's message conversions: setpoint, occupancy grid, path marker, stamps."""
from freejoint_core.arm import table1
from freejoint_core.singularity import det_map, semi_singular
from freejoint_planner.conversions import occupancy_grid, path_marker, setpoint_msg
from freejoint_planner.planning import grid_extent
from freejoint_planner.stream import Setpoint
import numpy as np
import pytest

pytestmark = pytest.mark.ros


def test_setpoint_message_carries_every_field():
    sp = Setpoint(2_000_000_003, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 7, 0.25, True)
    msg = setpoint_msg(sp, 'base')
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (2, 3)
    assert msg.header.frame_id == 'base'
    assert msg.position.tolist() == [0.1, 0.2]
    assert msg.velocity.tolist() == [0.3, 0.4]
    assert msg.acceleration.tolist() == [0.5, 0.6]
    assert (msg.plan_id, msg.plan_time, msg.final) == (7, 0.25, True)


def test_occupancy_grid_is_row_major_from_the_bottom_left_corner():
    grid = np.array([[0, 100, -1], [0, 0, 100]], dtype=np.int8)   # row 0 = bottom
    msg = occupancy_grid(grid, (-0.75, 0.75, -0.5, 0.5), 0.5, 'base_link', 3_000_000_000)
    assert (msg.info.width, msg.info.height, msg.info.resolution) == (3, 2, 0.5)
    assert (msg.info.origin.position.x, msg.info.origin.position.y) == (-0.75, -0.5)
    assert msg.info.origin.orientation.w == 1.0
    assert list(msg.data) == [0, 100, -1, 0, 0, 100]
    assert msg.header.frame_id == 'base_link'
    assert (msg.header.stamp.sec, msg.info.map_load_time.sec) == (3, 3)


def test_occupancy_grid_refuses_a_grid_that_is_not_2d_int8():
    with pytest.raises(ValueError, match='grid: expected a 2-D int8 array'):
        occupancy_grid(np.zeros((2, 2)), (0, 1, 0, 1), 0.5, 'base', 0)


def test_the_paper_region_grid_is_free_at_the_base_semi_singular_at_1_m_unknown_beyond():
    region = semi_singular(det_map(table1('horizontal').scaled(0.7), 1.0), 1e-7)
    extent = grid_extent(region.reach, 0.01)
    msg = occupancy_grid(region.to_grid(extent, 0.01), extent, 0.01, 'base_link', 0)
    assert (msg.info.width, msg.info.height) == (300, 300)

    def cell(x, y):      # the cell holding (x, y): column (x + 1.5) / 0.01, row (y + 1.5) / 0.01
        return msg.data[int((y + 1.5) / 0.01) * 300 + int((x + 1.5) / 0.01)]

    assert cell(0.005, 0.005) == 0            # base: nonsingular
    assert cell(0.305, -0.205) == 0           # r = 0.37 m < 0.478 m: nonsingular
    assert cell(1.005, 0.005) == 100          # r = 1 m: stretched-elbow annulus
    assert cell(-0.005, 0.705) == 100
    assert cell(-1.495, -1.495) == -1         # corner, r = 2.1 m: out of reach


def test_path_marker_is_a_line_strip_through_the_points():
    pts = np.array([[0.2, 0.0], [0.0, 0.2], [-0.2, 0.0]])
    msg = path_marker(pts, 'base_link', 1_000_000_000, plan_id=4)
    assert msg.type == msg.LINE_STRIP and msg.action == msg.ADD
    assert (msg.ns, msg.id, msg.header.frame_id) == ('planned_path', 0, 'base_link')
    assert [(p.x, p.y, p.z) for p in msg.points] == [
        (0.2, 0.0, 0.0), (0.0, 0.2, 0.0), (-0.2, 0.0, 0.0)]
    assert msg.scale.x == 0.005 and msg.color.a == 1.0
    assert msg.text == 'plan 4'
