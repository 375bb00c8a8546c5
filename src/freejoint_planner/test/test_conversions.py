"""The planner's message conversions: setpoints, occupancy grid, path marker, stamps."""
from freejoint_common.contract import setpoint_samples
from freejoint_common.setpoint import SetpointSample
from freejoint_core.arm import table1
from freejoint_core.singularity import det_map, semi_singular
from freejoint_planner.conversions import occupancy_grid, path_marker, setpoints_msg
from freejoint_planner.planning import grid_extent
from freejoint_planner.stream import Setpoint, SpatialSetpoint
import numpy as np
import pytest

pytestmark = pytest.mark.ros


def test_a_batch_carries_every_field_flat_setpoint_after_setpoint_and_reads_back():
    first = Setpoint(2_000_000_003, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 7, 0.25, True)
    second = Setpoint(2_001_000_003, 1.1, 1.2, 1.3, 1.4, 1.5, 1.6, 8, -0.5, False)
    msg = setpoints_msg([first, second], 'base')
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (2, 3)
    assert msg.header.frame_id == 'base'
    assert msg.stamps.tolist() == [2_000_000_003, 2_001_000_003]
    assert msg.position.tolist() == [0.1, 0.2, 1.1, 1.2]
    assert msg.velocity.tolist() == [0.3, 0.4, 1.3, 1.4]
    assert msg.acceleration.tolist() == [0.5, 0.6, 1.5, 1.6]
    assert (msg.plan_id.tolist(), msg.plan_time.tolist(), list(msg.final)) == (
        [7, 8], [0.25, -0.5], [True, False])
    assert setpoint_samples(msg) == [
        SetpointSample(2_000_000_003, (0.1, 0.2), (0.3, 0.4), (0.5, 0.6), 7, 0.25, True),
        SetpointSample(2_001_000_003, (1.1, 1.2), (1.3, 1.4), (1.5, 1.6), 8, -0.5, False)]


def test_a_spatial_batch_has_three_values_per_vector_and_an_empty_one_none():
    sp = SpatialSetpoint(5, (0.1, 0.2, 0.3), (0.0, 0.0, 0.1), (1.0, 0.0, 0.0), 3, 0.0, False)
    (back,) = setpoint_samples(setpoints_msg([sp], 'base'))
    assert back == SetpointSample(*sp)
    empty = setpoints_msg([], 'base')
    assert (empty.header.stamp.sec, empty.header.stamp.nanosec, len(empty.stamps)) == (0, 0, 0)
    assert setpoint_samples(empty) == []


@pytest.mark.parametrize('field, values, error', [
    ('position', [0.1, 0.2, 0.3], 'position has 3 values for 2 stamps'),
    ('velocity', [0.0] * 3, 'velocity has 3 values, position 4'),
    ('acceleration', [], 'acceleration has 0 values, position 4'),
    ('plan_id', [1], 'plan_id has 1 values for 2 stamps (n or none)'),
    ('final', [True, False, True], 'final has 3 values for 2 stamps')])
def test_a_batch_whose_arrays_do_not_fit_its_stamps_is_refused_naming_the_array(
        field, values, error):
    msg = setpoints_msg([Setpoint(0, *[0.0] * 6, 1, 0.0, False),
                         Setpoint(1, *[0.0] * 6, 1, 0.0, False)], 'base')
    setattr(msg, field, values)
    with pytest.raises(ValueError, match=r'^setpoints: ' + error.replace('(', r'\(').replace(
            ')', r'\)')):
        setpoint_samples(msg)


def test_a_hand_made_batch_without_plan_fields_reads_as_no_plan():
    from freejoint_msgs.msg import CartesianSetpoints
    msg = CartesianSetpoints(stamps=[4], position=[0.2, 0.0], velocity=[0.0, 0.0],
                             acceleration=[0.0, 0.0])
    assert setpoint_samples(msg) == [
        SetpointSample(4, (0.2, 0.0), (0.0, 0.0), (0.0, 0.0), 0, 0.0, False)]


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
