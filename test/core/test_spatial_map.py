"""Sampled singularity map of a spatial arm: kappa, voxels, chunks, merging."""

import math
import re

from freejoint_core import spatial_map as sm
from freejoint_core.errors import FreejointValueError
from freejoint_core.spatial_law import task_conditioning
import numpy as np
import pytest

UR5 = ('ur5', ['wrist_2_joint'])
PANDA = ('panda', ['panda_joint7'])
# UR5 elbow straight (q3 = 0), wrist_1 at -pi/2, wrist_2 at 0: upper arm, forearm and wrist
# in one line (src/freejoint_planner/test/test_spatial_planning.py)
UR5_STRETCHED = np.array([0.0, -1.2, 0.0, -math.pi / 2, 0.0, 0.0])


def _spec(arm=UR5, samples=4000, **kw):
    kw.setdefault('chunk', 1000)
    return sm.known_spec(arm[0], arm[1], samples=samples, **kw)


def _law_kappa(spec, q):
    """Return kappa of each posture through the law's path (terms, decoupling, kappa)."""
    arm = spec.arm
    out = []
    for x in q:
        da, _, maa = arm.decoupling(arm.terms(x, np.zeros(arm.n)))
        out.append(task_conditioning(da, maa, spec.reach)[0])
    return np.array(out)


def _same_maps(a, b):
    assert (a.samples, a.near, a.kappa_max) == (b.samples, b.near, b.kappa_max)
    for name in ('hist', 'voxels', 'count', 'near_count', 'kappa_low', 'worst'):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name


def _heavier(urdf, factor):
    """Return the URDF with every mass and inertia entry times ``factor`` (same levers)."""
    def scaled(match):
        return re.sub(r'="([-+0-9.eE]+)"', lambda v: f'="{float(v.group(1)) * factor!r}"',
                      match.group(0))
    return re.sub(r'<(mass|inertia) [^>]*>', scaled, urdf)


def test_the_stretched_ur5_lands_in_a_voxel_whose_smallest_kappa_is_below_1e_3():
    spec = _spec(samples=3000)
    arm = spec.arm
    # elbow straight: across the three parallel axes (y of the shoulder-lift joint) the
    # shoulder-lift axis is upper arm + forearm from the wrist-1 axis (URDF: 0.425 +
    # 0.39225 m; 0.1197 m apart along them)
    p0 = sm.evaluate(spec, UR5_STRETCHED[None])[0][0]
    d = arm.data.oMi[4].translation - arm.data.oMi[2].translation
    axis = arm.data.oMi[2].rotation[:, 1]
    assert np.linalg.norm(d - axis * (axis @ d)) == pytest.approx(0.425 + 0.39225, abs=1e-12)
    assert axis @ d == pytest.approx(-0.1197, abs=1e-12)
    sampled = sm.compute_map(spec)
    plan = sm.map_of(spec, UR5_STRETCHED[None], first=spec.samples)
    full = sm.merge([sampled, plan])
    entry = full.at(p0)
    assert np.array_equal(entry['voxel'], np.floor(p0 / 0.05).astype(int))
    assert entry['kappa_low'] < 1e-6 and entry['worst'] == spec.samples
    assert entry['near_count'] >= 1
    assert full.samples == spec.samples + 1 and full.near == sampled.near + 1
    before = sampled.at(p0)                 # the voxel without the stretched posture
    assert before is None or (entry['count'] == before['count'] + 1
                              and before['kappa_low'] > entry['kappa_low'])
    assert full.minimum() == (entry['kappa_low'], spec.samples)


@pytest.mark.parametrize('arm,m', [(UR5, 3), (PANDA, 3), (('ur5', []), 6)])
def test_kappa_of_each_sample_is_the_laws_criterion_and_the_tip_its_forward_kinematics(arm, m):
    spec = _spec(arm, samples=300, chunk=300, m=m)
    q = sm.postures(spec, 0)
    p, kappa = sm.evaluate(spec, q)
    law = _law_kappa(spec, q)
    sure = law >= 1e-3                       # where the law's own round-off is below 1e-9
    assert sure.mean() > 0.9
    np.testing.assert_allclose(kappa[sure], law[sure], rtol=1e-9)
    assert np.all((kappa >= 0.0) & (kappa <= 1.0))
    assert np.array_equal(p, np.array([spec.arm.fk(x) for x in q]))


@pytest.mark.parametrize('arm', [UR5, PANDA])
def test_the_arm_ten_times_heavier_gives_the_same_kappa_per_sample_and_the_same_map(arm):
    light = _spec(arm, samples=20000, chunk=5000)
    text = _heavier(light.urdf, 10.0)
    heavy = sm.MapSpec(text, light.base_link, light.tip_link, light.passive, light.samples,
                       chunk=light.chunk, name='heavy')
    q = np.array([1.0, 0.3, -0.4, 0.2, 0.5, -0.1, 0.3])[:light.arm.n]
    assert heavy.arm.terms(q, 0 * q).M[0, 0] == pytest.approx(
        10.0 * light.arm.terms(q, 0 * q).M[0, 0], rel=1e-12)
    q = sm.postures(light, 0)
    assert np.array_equal(q, sm.postures(heavy, 0))
    k1 = sm.evaluate(light, q)[1]
    k2 = sm.evaluate(heavy, q)[1]
    np.testing.assert_allclose(k2, k1, rtol=1e-9)
    a, b = sm.compute_map(light), sm.compute_map(heavy)
    assert a.near == b.near and np.array_equal(a.near_count, b.near_count)   # same verdicts
    assert np.array_equal(a.hist, b.hist)
    assert np.array_equal(a.voxels, b.voxels) and np.array_equal(a.count, b.count)
    assert np.array_equal(a.worst, b.worst)
    np.testing.assert_allclose(b.kappa_low, a.kappa_low, rtol=1e-9)
    if arm == UR5:
        assert a.near > 0                    # near-singular samples in the comparison


def test_one_worker_and_two_workers_give_the_same_map_and_chunks_merge_in_any_order():
    spec = _spec(samples=2500, chunk=600)    # 5 chunks, the last one short (100)
    one = sm.compute_map(spec, workers=1)
    two = sm.compute_map(spec, workers=2)
    _same_maps(one, two)
    parts = [sm.map_chunk(spec, i) for i in range(spec.chunks)]
    _same_maps(one, sm.merge(parts[::-1]))
    _same_maps(one, sm.merge([sm.merge(parts[3:]), sm.merge(parts[:3])]))
    assert one.samples == 2500 and one.count.sum() == 2500 and one.hist.sum() == 2500


def test_the_map_counts_voxels_and_quantiles_as_a_brute_force_pass_over_the_samples():
    spec = _spec(samples=3000, chunk=1000, voxel=0.1, kappa_min=0.05)
    smap = sm.compute_map(spec)
    q = np.vstack([sm.postures(spec, i) for i in range(spec.chunks)])
    p, kappa = sm.evaluate(spec, q)
    assert smap.near == np.count_nonzero(kappa < 0.05) > 0
    assert smap.share_near == pytest.approx(np.mean(kappa < 0.05), abs=0.0)
    vox = np.floor(p / 0.1).astype(np.int64)
    uniq, inv = np.unique(vox, axis=0, return_inverse=True)
    inv = inv.ravel()
    assert np.array_equal(smap.voxels, uniq)      # sorted x, then y, then z
    assert np.array_equal(smap.count, np.bincount(inv))
    assert np.array_equal(smap.near_count, np.bincount(inv, weights=kappa < 0.05))
    low = np.full(len(uniq), np.inf)
    np.minimum.at(low, inv, kappa)
    assert np.array_equal(smap.kappa_low, low)
    assert np.array_equal(kappa[smap.worst], low)
    # quantile q: within one bin (1.2 %) of the ceil(q N)-th smallest kappa
    probs = np.array([0.001, 0.01, 0.1, 0.5, 0.9, 1.0])
    kth = np.sort(kappa)[np.ceil(probs * len(kappa)).astype(int) - 1]
    ratio = smap.quantiles(probs) / kth
    assert np.all(np.abs(np.log10(ratio)) <= 1.0 / sm.BINS_PER_DECADE)
    assert smap.quantiles([0.0, 1.0]).tolist() == [kappa.min(), kappa.max()]
    assert smap.kappa_max == kappa.max() and smap.minimum()[0] == kappa.min()
    # every tip within the reach of the shoulder (the base joint's origin on the z axis)
    centre = (smap.voxels + 0.5) * 0.1
    assert np.all(np.linalg.norm(centre, axis=1) <= spec.reach + 0.089159 + 0.1 * math.sqrt(3))


def test_a_voxels_worst_sample_is_regenerated_from_the_seed_and_its_index():
    spec = _spec(samples=2200, chunk=1000)
    smap = sm.compute_map(spec)
    kmin, worst = smap.minimum()
    q = sm.posture(spec, worst)
    np.testing.assert_allclose(sm.evaluate(spec, q[None])[1][0], kmin, rtol=1e-12)
    chunk, row = divmod(worst, 1000)
    assert np.array_equal(q, sm.postures(spec, chunk)[row])
    # the short last chunk is the start of the full-size draw of its index
    longer = sm.known_spec('ur5', UR5[1], samples=3000, chunk=1000)
    assert np.array_equal(sm.postures(spec, 2), sm.postures(longer, 2)[:200])
    arm = spec.arm
    assert np.all((q >= arm.lower) & (q <= arm.upper))
    other = sm.known_spec('ur5', UR5[1], samples=2200, chunk=1000, seed=1)
    assert not np.array_equal(sm.postures(spec, 0), sm.postures(other, 0))


def test_kappa_does_not_depend_on_the_base_joint_angle_and_the_tip_turns_with_it():
    # joint 1 turns the whole arm about the vertical: J -> Rz J, M unchanged, so
    # Da M~aa Da^T -> Rz (.) Rz^T keeps its eigenvalues (m = 3: Ds = I / L)
    spec = _spec(samples=200, chunk=200)
    q = sm.postures(spec, 0)
    turned = q.copy()
    turned[:, 0] += 0.7
    p1, k1 = sm.evaluate(spec, q)
    p2, k2 = sm.evaluate(spec, turned)
    np.testing.assert_allclose(k2, k1, rtol=1e-9)
    c, s = math.cos(0.7), math.sin(0.7)
    rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    np.testing.assert_allclose(p2, p1 @ rz.T, atol=1e-12)


def test_a_map_saved_and_loaded_is_the_same_map(tmp_path):
    spec = _spec(samples=1500, chunk=500)
    smap = sm.compute_map(spec)
    path = str(tmp_path / 'map.npz')
    smap.save(path)
    back = sm.load(path)
    _same_maps(smap, back)
    assert back.spec == spec and back.spec.key() == spec.key()
    text = '\n'.join(back.summary())
    assert 'singularity map ur5 (free: wrist_2_joint), m = 3, nominal 0.7, 1500 samples' in text
    assert f'smallest kappa {smap.minimum()[0]:.3g} (sample {smap.minimum()[1]})' in text


@pytest.mark.parametrize('kwargs,name', [
    ({'samples': 0}, 'samples'), ({'samples': 1.5}, 'samples'), ({'chunk': 0}, 'chunk'),
    ({'voxel': -0.1}, 'voxel'), ({'voxel': 1e-9}, 'voxel'), ({'voxel': 'big'}, 'voxel'),
    ({'kappa_min': 1.5}, 'kappa_min'), ({'kappa_min': 0.0}, 'kappa_min'), ({'m': 4}, 'm'),
    ({'seed': -1}, 'seed'), ({'scale': math.nan}, 'scale')])
def test_a_bad_map_argument_is_refused_naming_it(kwargs, name):
    with pytest.raises(FreejointValueError, match=f'^{name}:'):
        _spec(**kwargs)


def test_bad_arms_postures_and_maps_are_refused_naming_them(tmp_path):
    with pytest.raises(FreejointValueError, match="^passive: 'nope' is not a joint"):
        sm.known_spec('ur5', ['nope'])
    with pytest.raises(FreejointValueError, match='^passive: expected a list'):
        sm.known_spec('ur5', 'wrist_2_joint')
    with pytest.raises(FreejointValueError, match='^passive: 5 active joints cannot drive m = 6'):
        sm.known_spec('ur5', UR5[1], m=6)
    with pytest.raises(FreejointValueError, match='^name:'):
        sm.known_spec('kuka')
    spec = _spec(samples=10, chunk=10)
    with pytest.raises(FreejointValueError, match=r'^q: expected \(k, 6\)'):
        sm.evaluate(spec, np.zeros((2, 7)))
    with pytest.raises(FreejointValueError, match=r'^q: expected \(k, 6\)'):
        sm.evaluate(spec, np.full((1, 6), np.nan))
    with pytest.raises(FreejointValueError, match='^index:'):
        sm.postures(spec, 1)
    with pytest.raises(FreejointValueError, match='^sample:'):
        sm.posture(spec, 10)
    with pytest.raises(FreejointValueError, match='^workers:'):
        sm.compute_map(spec, workers=0)
    other = _spec(samples=10, chunk=10, seed=3)
    with pytest.raises(FreejointValueError, match='^maps: of different'):
        sm.merge([sm.map_chunk(spec, 0), sm.map_chunk(other, 0)])
    with pytest.raises(FreejointValueError, match='^maps: nothing'):
        sm.merge([])
    with pytest.raises(FreejointValueError, match='^qs:'):
        sm.compute_map(spec).quantiles([1.5])
    bad = tmp_path / 'not_a_map.npz'
    np.savez(bad, x=np.zeros(2))
    with pytest.raises(FreejointValueError, match='^path:'):
        sm.load(str(bad))
    stuck = re.sub(r'lower="[^"]*" upper="[^"]*"', 'lower="0.5" upper="0.5"', spec.urdf,
                   count=1)                   # the first joint of the file: shoulder_pan
    with pytest.raises(FreejointValueError, match="^urdf: joint 'shoulder_pan_joint' has no "
                       r'position range to sample within \(lower 0.5, upper 0.5\)'):
        sm.MapSpec(stuck, spec.base_link, spec.tip_link, (), 10)
