"""The singularity map of any planar arm (freejoint_core.singularity_nlink) against brute force."""

import math

from freejoint_core import singularity as sing
from freejoint_core import singularity_nlink as sn
from freejoint_core.arm import ArmModel, ArmParams, table1
from freejoint_core.errors import FreejointValueError
from freejoint_core.trajectory import CircleQuintic
from freejoint_core.urdf import four_link_arm, FOUR_LINK_CIRCLE
import numpy as np
import pytest

PAPER = table1('horizontal').scaled(0.7)
FOUR = four_link_arm('horizontal').nominal(0.7)


def _brute(params, q):
    """``Da`` of the reference model at full joint angles ``q`` (n,)."""
    da, _ = ArmModel(params).decoupling(q, np.zeros(params.n))
    return da


def _brute_det(params, q):
    da = _brute(params, q)
    return np.linalg.det(da @ da.T)


def _arm(n, passive, seed):
    rng = np.random.default_rng(seed)
    lengths = rng.uniform(0.2, 0.6, n)
    return ArmParams(lengths=lengths, masses=rng.uniform(0.3, 2.0, n),
                     inertias=rng.uniform(0.005, 0.1, n),
                     com=lengths * rng.uniform(0.2, 0.9, n), passive=passive)


ARMS = [
    PAPER,
    _arm(2, (), 1),
    _arm(3, (0,), 2),
    _arm(3, (), 3),
    FOUR,
    _arm(4, (3,), 4),
    _arm(4, (1, 2), 5),
    _arm(5, (0, 3), 6),
]
IDS = ['paper', '2-link', '3-link-passive-0', '3-link-all-active', 'four-link-example',
       '4-link-passive-3', '4-link-passive-1-2', '5-link-passive-0-3']


@pytest.mark.parametrize('params', ARMS, ids=IDS)
def test_batched_det_equals_the_reference_model_det_at_random_points(params):
    rng = np.random.default_rng(21)
    q = rng.uniform(-4.0, 4.0, (60, params.n))
    got = sn.decoupling_det(params, q[:, 1:])
    ref = np.array([_brute_det(params, np.r_[0.0, x[1:]]) for x in q])
    np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-12 * ref.max())
    # Cauchy-Binet: the minors are those of the brute-force Da, in the documented order
    minors = sn.decoupling_minors(params, q[:5, 1:])
    act = range(params.r)
    for row, x in zip(minors, q[:5]):
        da = _brute(params, np.r_[0.0, x[1:]])
        ref_m = [da[0, a] * da[1, b] - da[0, b] * da[1, a] for a in act for b in act if a < b]
        np.testing.assert_allclose(row, ref_m, rtol=1e-9, atol=1e-9 * np.abs(ref_m).max())


@pytest.mark.parametrize('params', ARMS, ids=IDS)
def test_det_depends_on_the_relative_joint_angles_only_not_the_base_joint_or_gravity(params):
    rng = np.random.default_rng(22)
    upright = ArmParams(params.lengths, params.masses, params.inertias, params.com,
                        passive=params.passive, gravity=9.81)
    for q in rng.uniform(-math.pi, math.pi, (15, params.n)):
        ref = _brute_det(params, q)
        for shift in (0.7, -2.9, 11.0):
            moved = q + np.r_[shift, np.zeros(params.n - 1)]
            assert _brute_det(params, moved) == pytest.approx(ref, rel=1e-9, abs=1e-15)
            assert np.linalg.norm(ArmModel(params).fk(moved)) == pytest.approx(
                np.linalg.norm(ArmModel(params).fk(q)), abs=1e-14)
        assert _brute_det(upright, q) == pytest.approx(ref, rel=1e-12, abs=1e-15)
    assert sn.map_joints(params) == tuple(range(1, params.n))


@pytest.mark.parametrize('params', ARMS[1:], ids=IDS[1:])
def test_mirroring_all_joints_keeps_the_det_and_flips_every_minor(params):
    rng = np.random.default_rng(23)
    q = rng.uniform(-math.pi, math.pi, (20, params.n - 1))
    np.testing.assert_allclose(sn.decoupling_det(params, -q), sn.decoupling_det(params, q),
                               rtol=1e-12)
    np.testing.assert_allclose(sn.decoupling_minors(params, -q),
                               -sn.decoupling_minors(params, q), rtol=1e-12, atol=1e-300)


def test_two_link_arm_det_is_the_hand_derived_l1_l2_sin_q2_over_det_m():
    params = ARMS[1]
    (l1, l2), (m1, m2) = params.lengths, params.masses
    (i1, i2), (c1, c2) = params.inertias, params.com
    a1 = i1 + m1 * c1 ** 2 + m2 * l1 ** 2
    a2 = i2 + m2 * c2 ** 2
    h12 = m2 * c2 * l1
    q2 = np.linspace(-math.pi, math.pi, 73)
    det_m = a1 * a2 - (h12 * np.cos(q2)) ** 2       # absolute -> relative: unit determinant
    np.testing.assert_allclose(sn.decoupling_minors(params, q2[:, None])[:, 0],
                               l1 * l2 * np.sin(q2) / det_m, rtol=1e-12, atol=1e-15)
    # singular only stretched and folded: the region is the two reach boundaries
    region = sn.arm_region(params, 1.0)
    assert region.intervals.shape == (2, 2)
    assert region.intervals[0, 0] == region.reach[0] == abs(l1 - l2)
    assert region.intervals[1, 1] == region.reach[1] == l1 + l2


def test_three_link_general_path_reproduces_the_paper_map_to_round_off():
    fast = sing.det_map(PAPER, 1.0)
    general = sn.det_map_nlink(PAPER, 1.0)
    np.testing.assert_array_equal(general.q, fast.q)
    np.testing.assert_allclose(general.det, fast.det, rtol=1e-12, atol=1e-14 * fast.det.max())
    clear = np.abs(fast.det_da) > 1e-12                  # off the exact zeros at q2 = 0, pi
    np.testing.assert_array_equal(general.minor_negative[0][clear],
                                  np.signbit(fast.det_da)[clear])
    np.testing.assert_allclose(sn.semi_singular_nlink(general).intervals,
                               sing.semi_singular(fast).intervals, rtol=0, atol=1e-12)


def test_arm_region_keeps_the_paper_arm_on_its_closed_form_map_exactly():
    assert sn.uses_closed_map(PAPER) and not sn.uses_closed_map(FOUR)
    ref = sing.semi_singular(sing.det_map(PAPER, 0.5), 1e-7)
    got = sn.arm_region(PAPER, 0.5, 1e-7)
    np.testing.assert_array_equal(got.intervals, ref.intervals)
    np.testing.assert_array_equal(got.singular_mask, ref.singular_mask)
    assert got.reach == ref.reach


def test_four_link_map_points_equal_the_direct_det_including_the_mirrored_half():
    dmap = sn.det_map_nlink(FOUR, 10.0)
    assert dmap.det.shape == (36, 36, 36)
    assert dmap.minor_negative.shape == (3, 36, 36, 36)
    rng = np.random.default_rng(24)
    idx = np.vstack([rng.integers(0, 36, (30, 3)), [[0, 0, 0], [18, 5, 31], [35, 35, 1]]])
    for i, j, k in idx:
        q = np.array([0.0, dmap.q[i], dmap.q[j], dmap.q[k]])
        ref = _brute_det(FOUR, q)
        assert dmap.det[i, j, k] == pytest.approx(ref, rel=1e-9, abs=1e-12)
        minors = sn.decoupling_minors(FOUR, q[None, 1:])[0]
        clear = np.abs(minors) > 1e-9
        np.testing.assert_array_equal(dmap.minor_negative[:, i, j, k][clear],
                                      np.signbit(minors)[clear])


def _singular_configuration_in_band():
    """Newton on two minors of the reference model's Da over (q3, q4), q2 fixed."""
    def minors(x):
        da = _brute(FOUR, np.r_[0.0, -2.22, x])
        return np.array([da[0, 0] * da[1, 1] - da[0, 1] * da[1, 0],
                         da[0, 0] * da[1, 2] - da[0, 2] * da[1, 0]])
    x = np.array([-0.1, -3.3])
    for _ in range(30):
        f = minors(x)
        jac = np.stack([(minors(x + 1e-7 * e) - f) / 1e-7 for e in np.eye(2)], axis=1)
        x = x - np.linalg.solve(jac, f)
    return np.r_[0.0, -2.22, x]


def test_four_link_nominal_arm_is_singular_at_a_radius_inside_the_example_circle_band():
    q = _singular_configuration_in_band()
    sv = np.linalg.svd(_brute(FOUR, q), compute_uv=False)
    assert sv[1] < 1e-12 * sv[0]                               # rank 1: singular
    radius = float(np.linalg.norm(ArmModel(FOUR).fk(q)))
    centre = math.hypot(*FOUR_LINK_CIRCLE['centre'])
    assert centre - FOUR_LINK_CIRCLE['radius'] < radius < centre + FOUR_LINK_CIRCLE['radius']
    # the conservative map flags it; the paper's sampled criterion alone misses it
    conservative = sn.arm_region(FOUR, 3.0)
    sampled = sn.arm_region(FOUR, 3.0, cells=False)
    assert conservative.radial_distance(radius) <= 0.0
    assert sampled.radial_distance(radius) > 0.0


def _circle_points(circle):
    pts = circle.points(2001)
    u = np.asarray(circle.centre) / np.hypot(*circle.centre)
    return np.vstack((pts, circle.centre - circle.radius * u, circle.centre + circle.radius * u))


def test_path_check_on_the_four_link_example_circle_conservative_refuses_sampled_accepts():
    circle = CircleQuintic(centre=FOUR_LINK_CIRCLE['centre'], radius=FOUR_LINK_CIRCLE['radius'])
    pts = _circle_points(circle)
    check = sing.check_path(sn.arm_region(FOUR, 3.0), pts)
    assert not check.ok and 'semi-singular annulus [0, 1.3] m' in check.reason
    sampled = sing.check_path(sn.arm_region(FOUR, 2.0, cells=False), pts)
    assert sampled.ok and sampled.margin > 0.01, sampled


@pytest.mark.parametrize('cells', [True, False])
def test_path_check_refuses_a_circle_crossing_the_folded_radius_of_the_four_link_arm(cells):
    # links 2-4 folded back onto link 1: |0.40 - 0.35 - 0.30 - 0.25| = 0.5 m, J of rank 1
    folded = np.radians([0.0, 180.0, 0.0, 0.0])
    assert np.linalg.norm(ArmModel(FOUR).fk(folded)) == pytest.approx(0.5, abs=1e-15)
    assert _brute_det(FOUR, folded) < 1e-20
    circle = CircleQuintic(centre=(0.0, 0.5), radius=0.02)
    check = sing.check_path(sn.arm_region(FOUR, 4.0, cells=cells), _circle_points(circle))
    assert not check.ok and 'semi-singular annulus' in check.reason


def test_bad_arguments_are_refused_naming_them():
    with pytest.raises(FreejointValueError, match='resolution_deg: 0.5 deg gives 720'):
        sn.det_map_nlink(FOUR, 0.5)
    with pytest.raises(FreejointValueError, match='resolution_deg'):
        sn.det_map_nlink(FOUR, 7.0)
    with pytest.raises(FreejointValueError, match='max_samples'):
        sn.det_map_nlink(FOUR, 10.0, max_samples=0)
    with pytest.raises(FreejointValueError, match=r'q_rel: expected shape \(N, 3\)'):
        sn.decoupling_det(FOUR, np.zeros((4, 2)))
    with pytest.raises(FreejointValueError, match='q_rel: values must be finite'):
        sn.decoupling_det(FOUR, [[0.0, math.nan, 0.0]])
    with pytest.raises(FreejointValueError, match='nominal_params: expected ArmParams'):
        sn.arm_region(object(), 1.0)
    with pytest.raises(FreejointValueError, match='det_map: expected NLinkDetMap'):
        sn.semi_singular_nlink(sing.det_map(PAPER, 10.0))
    with pytest.raises(FreejointValueError, match='eps_d'):
        sn.semi_singular_nlink(sn.det_map_nlink(FOUR, 30.0), eps_d=0.0)


def test_no_singular_configuration_found_by_newton_lies_in_a_free_annulus_of_the_map():
    # a 4-link arm, last joint passive, whose conservative map leaves a nonsingular annulus
    params = ArmParams(lengths=(0.357, 0.397, 0.471, 0.224), masses=(1.245, 0.761, 1.795, 0.409),
                       inertias=(0.069, 0.087, 0.024, 0.09), com=(0.289, 0.085, 0.327, 0.045),
                       passive=(3,))
    free = sn.arm_region(params, 4.0).nonsingular_intervals
    assert free.shape == (1, 2) and free[0, 1] - free[0, 0] > 0.1      # about [0.81, 0.93] m
    # Levenberg-Marquardt on the three minors from random starts: points of the singular set
    rng = np.random.default_rng(25)
    x = rng.uniform(-math.pi, math.pi, (600, 3))
    for _ in range(50):
        f = sn.decoupling_minors(params, x)
        jac = np.stack([(sn.decoupling_minors(params, x + 1e-7 * e) - f) / 1e-7
                        for e in np.eye(3)], axis=2)
        jtj = jac.transpose(0, 2, 1) @ jac
        jtj += 1e-9 * np.trace(jtj, axis1=1, axis2=2)[:, None, None] * np.eye(3)
        step = np.linalg.solve(jtj, jac.transpose(0, 2, 1) @ f[:, :, None])[:, :, 0]
        x -= np.clip(step, -0.3, 0.3)
    found = x[sn.decoupling_det(params, x) < 1e-12]
    assert len(found) > 100
    for q in found[:5]:                                   # singular by the reference model too
        sv = np.linalg.svd(_brute(params, np.r_[0.0, q]), compute_uv=False)
        assert sv[1] < 1e-6 * sv[0]
    radii = sn.ee_radius_nlink(params.lengths, found)
    assert not np.any((radii >= free[0, 0]) & (radii <= free[0, 1]))
