"""Behaviour of the singularity analysis (paper, Sec. 3.2)."""

import math

from freejoint_core import singularity as sing
from freejoint_core.arm import ArmModel, ArmParams, table1
from freejoint_core.errors import FreejointValueError
from freejoint_core.trajectory import CircleQuintic
import numpy as np
import pytest


NOMINAL = table1('horizontal').scaled(0.7)


@pytest.fixture(scope='module')
def region_1deg():
    return sing.semi_singular(sing.det_map(NOMINAL, 1.0), eps_d=1e-7)


def _model_det(model, q):
    da, _ = model.decoupling(q, np.zeros(3))
    return np.linalg.det(da @ da.T)


def test_det_is_invariant_to_base_rotation_q1():
    model = ArmModel(NOMINAL)
    rng = np.random.default_rng(11)
    for _ in range(50):
        q = rng.uniform(-math.pi, math.pi, 3)
        ref = _model_det(model, q)
        for shift in rng.uniform(-10.0, 10.0, 3):
            moved = q + np.array([shift, 0.0, 0.0])
            assert _model_det(model, moved) == pytest.approx(ref, rel=1e-9, abs=1e-15)


def test_det_ignores_gravity():
    flat = ArmModel(table1('horizontal').scaled(0.7))
    upright = ArmModel(table1('vertical').scaled(0.7))
    rng = np.random.default_rng(12)
    for q in rng.uniform(-math.pi, math.pi, (20, 3)):
        assert _model_det(upright, q) == _model_det(flat, q)


def test_det_is_invariant_to_mirroring_q2_q3():
    model = ArmModel(NOMINAL)
    rng = np.random.default_rng(13)
    for q in rng.uniform(-math.pi, math.pi, (30, 3)):
        mirrored = np.array([q[0], -q[1], -q[2]])
        assert _model_det(model, mirrored) == pytest.approx(_model_det(model, q), rel=1e-9)


def test_end_effector_radius_is_independent_of_q1():
    model = ArmModel(NOMINAL)
    rng = np.random.default_rng(14)
    for q in rng.uniform(-math.pi, math.pi, (30, 3)):
        r = np.linalg.norm(model.fk(q))
        assert sing.ee_radius(NOMINAL.lengths, q[1], q[2]) == pytest.approx(r, abs=1e-14)
        for shift in (0.3, -2.0, 5.0):
            moved = q + np.array([shift, 0.0, 0.0])
            assert np.linalg.norm(model.fk(moved)) == pytest.approx(r, abs=1e-14)


@pytest.mark.parametrize('params', [
    NOMINAL,
    table1('vertical'),
    ArmParams(lengths=(0.4, 0.7, 0.3), masses=(2.0, 1.5, 0.5), inertias=(0.2, 0.1, 0.01),
              com=(0.2, 0.3, 0.12), passive=(2,)),
])
def test_closed_form_det_equals_arm_model_det_at_random_points(params):
    model = ArmModel(params)
    rng = np.random.default_rng(15)
    q = rng.uniform(-math.pi, math.pi, (100, 3))
    fast = sing.det_da_closed_form(params, q[:, 1], q[:, 2]) ** 2
    general = sing.det_da_general(params, q[:, 1], q[:, 2]) ** 2
    ref = np.array([_model_det(model, x) for x in q])
    np.testing.assert_allclose(fast, ref, rtol=1e-9, atol=1e-18)
    np.testing.assert_allclose(general, ref, rtol=1e-9, atol=1e-18)


@pytest.mark.parametrize('passive', [(0,), (1,)])
def test_general_path_matches_arm_model_for_other_passive_joints(passive):
    params = ArmParams(lengths=(0.5, 0.5, 0.5), masses=(0.7,) * 3, inertias=(0.07,) * 3,
                       com=(0.175,) * 3, passive=passive)
    model = ArmModel(params)
    rng = np.random.default_rng(16)
    q = rng.uniform(-math.pi, math.pi, (40, 3))
    got = sing.det_da_general(params, q[:, 1], q[:, 2]) ** 2
    ref = np.array([_model_det(model, x) for x in q])
    np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-18)
    dmap = sing.det_map(params, 10.0)         # dispatches to the general path
    i, j = 7, 23
    qq = np.array([0.0, dmap.q[i], dmap.q[j]])
    assert dmap.det[i, j] == pytest.approx(_model_det(model, qq), rel=1e-9)


def test_det_map_grid_equals_pointwise_closed_form_including_mirrored_rows():
    dmap = sing.det_map(NOMINAL, 2.0)
    assert dmap.det.shape == (180, 180)
    np.testing.assert_allclose(dmap.q, np.radians(np.arange(180) * 2.0), atol=1e-15)
    ref = sing.det_da_closed_form(NOMINAL, dmap.q[:, None], dmap.q[None, :])
    np.testing.assert_allclose(dmap.det_da, ref, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(dmap.det, ref ** 2, rtol=1e-12, atol=1e-15)


def test_closed_form_and_general_maps_agree():
    fast = sing.det_map(NOMINAL, 5.0, method='closed_form')
    slow = sing.det_map(NOMINAL, 5.0, method='general')
    np.testing.assert_allclose(fast.det, slow.det, rtol=1e-10, atol=1e-15)


def test_det_vanishes_only_on_the_stretched_and_folded_elbow():
    # det Da = L1 L2 sin q2 (I3 + m3 lc3 (lc3 - L3)) / det M: zero at q2 = 0 and pi only.
    dmap = sing.det_map(NOMINAL, 1.0)
    assert np.all(dmap.det[0] == 0.0) and np.all(dmap.det[180] == 0.0)
    others = np.delete(dmap.det, [0, 180], axis=0)
    assert others.min() > 1e-7


def test_centre_of_percussion_arm_is_singular_everywhere():
    # I3 = m3 lc3 (L3 - lc3): the tip is the centre of percussion of link 3 about joint 3.
    params = ArmParams(lengths=(0.5, 0.5, 0.5), masses=(1.0, 1.0, 1.0),
                       inertias=(0.1, 0.1, 0.0625), com=(0.25, 0.25, 0.25))
    dmap = sing.det_map(params, 10.0)
    assert dmap.det.max() < 1e-25
    region = sing.semi_singular(dmap)
    np.testing.assert_allclose(region.intervals, [[0.0, 1.5]])


def test_paper_semi_singular_region_is_one_annulus_from_half_a_metre_out(region_1deg):
    # Hand analysis: singular band |q2 - {0, pi}| < 0.013 deg. q2 = pi (folded, L1 = L2)
    # puts joint 3 on the base, r = L3 = 0.5; q2 = 0 gives r in [L1 + L2 - L3, 1.5].
    assert region_1deg.reach == (0.0, 1.5)
    assert region_1deg.intervals.shape == (1, 2)
    lo, hi = region_1deg.intervals[0]
    assert hi == 1.5
    # sample at q2 = pi + 1 deg (sign change) minus the cell widening 1.5 m * 0.5 deg
    widen = 1.5 * math.radians(0.5)
    r_next = sing.ee_radius(NOMINAL.lengths, math.pi + math.radians(1.0), np.radians(
        np.arange(360.0))).min()
    assert lo == pytest.approx(r_next - widen, abs=1e-12)
    assert 0.47 < lo < 0.5
    np.testing.assert_allclose(region_1deg.nonsingular_intervals, [[0.0, lo]])


def test_finer_map_shrinks_towards_the_exact_boundary():
    fine = sing.semi_singular(sing.det_map(NOMINAL, 0.25))
    coarse = sing.semi_singular(sing.det_map(NOMINAL, 1.0))
    assert coarse.intervals[0, 0] < fine.intervals[0, 0] < 0.4999


def test_check_path_accepts_the_paper_circle_with_positive_margin(region_1deg):
    pts = CircleQuintic().points(361)
    res = sing.check_path(region_1deg, pts)
    assert res.ok and res.reason == ''
    assert res.margin == pytest.approx(region_1deg.intervals[0, 0] - 0.2, abs=1e-12)
    assert res.margin > 0.27


def test_check_path_refuses_a_circle_through_the_annulus_and_names_the_point(region_1deg):
    pts = CircleQuintic(centre=(0.4, 0.0), radius=0.2).points(9)   # r from 0.2 to 0.6
    times = np.linspace(0.0, 5.0, 9)
    res = sing.check_path(region_1deg, pts, times)
    assert not res.ok
    assert res.margin == pytest.approx(-min(0.6 - region_1deg.intervals[0, 0], 0.9), abs=1e-12)
    assert res.reason.startswith('point 0 (t = 0 s) at (0.6, 0) m')
    assert 'semi-singular annulus' in res.reason


def test_check_path_refuses_points_out_of_reach():
    region = sing.semi_singular(sing.det_map(NOMINAL, 1.0))
    empty = sing.SemiSingularRegion(np.zeros((0, 2)), np.zeros((0, 2)), (0.0, 1.5), 1e-7,
                                    1.0, region.singular_mask)
    res = sing.check_path(empty, [[0.1, 0.0], [1.6, 0.0]])
    assert not res.ok
    assert res.margin == pytest.approx(-0.1)
    assert 'point 1 at (1.6, 0) m' in res.reason and 'reach' in res.reason
    ok = sing.check_path(empty, [[0.1, 0.0], [0.0, 1.2]])
    assert ok.ok and ok.margin == pytest.approx(0.3)


@pytest.mark.parametrize('kwargs, match', [
    ({'points': np.zeros((3,))}, 'points'),
    ({'points': np.zeros((0, 2))}, 'points'),
    ({'points': [[0.1, float('nan')]]}, 'points'),
    ({'points': [[0.1, 0.0]], 'times': [0.0, 1.0]}, 'times'),
    ({'region': 'annulus', 'points': [[0.1, 0.0]]}, 'region'),
])
def test_check_path_bad_arguments(region_1deg, kwargs, match):
    args = {'region': region_1deg}
    args.update(kwargs)
    with pytest.raises(FreejointValueError, match=match):
        sing.check_path(**args)


def test_to_grid_marks_annulus_free_disc_and_unreachable_corners(region_1deg):
    lo = region_1deg.intervals[0, 0]
    grid = region_1deg.to_grid((-1.6, 1.6, -1.6, 1.6), 0.1)
    assert grid.shape == (32, 32) and grid.dtype == np.int8
    # cell (row 16, col 16) spans x, y in [0, 0.1]: free disc around the base
    assert grid[16, 16] == sing.GRID_FREE
    # the cell whose lower-left corner is (0.5, 0.0) spans r in [0.5, 0.61]: semi-singular
    assert grid[16, 21] == sing.GRID_SEMI_SINGULAR
    # the corner cell lies beyond r = 1.5 entirely
    assert grid[0, 0] == sing.GRID_UNREACHABLE and grid[31, 31] == sing.GRID_UNREACHABLE
    # row-major with y rows: an asymmetric extent keeps rows as y
    tall = region_1deg.to_grid((0.0, 0.2, -0.6, 0.6), 0.1)
    assert tall.shape == (12, 2)
    assert tall[0, 0] == sing.GRID_SEMI_SINGULAR          # y in [-0.6, -0.5]
    assert tall[6, 0] == sing.GRID_FREE                   # y in [0, 0.1]
    assert lo < 0.5


@pytest.mark.parametrize('extent, cell, match', [
    ((0.0, 1.0, 0.0), 0.1, 'extent'),
    ((1.0, 0.0, 0.0, 1.0), 0.1, 'extent'),
    ((0.0, 1.0, 0.0, 1.0), 0.0, 'cell'),
    ((0.0, 1.0, 0.0, 1.0), 'x', 'cell'),
])
def test_to_grid_bad_arguments(region_1deg, extent, cell, match):
    with pytest.raises(FreejointValueError, match=match):
        region_1deg.to_grid(extent, cell)


@pytest.mark.parametrize('res', [0.0, -1.0, 7.0, 120.0, 'fine', float('nan')])
def test_det_map_rejects_bad_resolution(res):
    with pytest.raises(FreejointValueError, match='^resolution_deg:'):
        sing.det_map(NOMINAL, res)


def test_det_map_rejects_unsupported_arms():
    four = ArmParams(lengths=(0.5,) * 4, masses=(1.0,) * 4, inertias=(0.1,) * 4,
                     com=(0.25,) * 4, passive=(3,))
    with pytest.raises(FreejointValueError, match='^nominal_params:.*n = 4'):
        sing.det_map(four, 10.0)
    with pytest.raises(FreejointValueError, match='^nominal_params:'):
        sing.det_map((0.5, 0.5, 0.5), 10.0)
    other = ArmParams(lengths=(0.5,) * 3, masses=(1.0,) * 3, inertias=(0.1,) * 3,
                      com=(0.25,) * 3, passive=(1,))
    with pytest.raises(FreejointValueError, match='^method:'):
        sing.det_map(other, 10.0, method='closed_form')
    with pytest.raises(FreejointValueError, match='^method:'):
        sing.det_map(NOMINAL, 10.0, method='fast')


def test_semi_singular_rejects_bad_eps():
    dmap = sing.det_map(NOMINAL, 10.0)
    for eps in (0.0, -1e-7, float('inf'), 'tiny'):
        with pytest.raises(FreejointValueError, match='^eps_d:'):
            sing.semi_singular(dmap, eps)


def test_larger_eps_widens_the_annulus():
    dmap = sing.det_map(NOMINAL, 1.0)
    strict = sing.semi_singular(dmap, 1e-7)
    loose = sing.semi_singular(dmap, 1e-2)
    # |det Da| <= 0.1 reaches 4 deg either side of q2 = pi: the annulus grows inwards
    rows = set(np.nonzero(loose.singular_mask)[0].tolist())
    assert {176, 177, 178, 179, 180, 181, 182, 183, 184} <= rows
    assert loose.intervals[0, 0] < strict.intervals[0, 0] - 0.02
