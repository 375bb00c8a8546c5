"""One law path: every runner builds its law through the registry; a new law is one module."""

import ast
import math
import os
import sys
import textwrap

from freejoint_core import batch, laws, offline
from freejoint_core.arm import table1
from freejoint_core.control import Gains, RobustController
from freejoint_core.errors import FreejointValueError
from freejoint_core.law_tdc import TimeDelayLaw
from freejoint_core.law_vsc import SlidingModeLaw
from freejoint_core.laws import LAWS, make_law
import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
RUNNERS = {
    'offline': 'src/freejoint_core/freejoint_core/offline.py',
    'circles': 'src/freejoint_core/freejoint_core/circles.py',
    'failure': 'src/freejoint_core/freejoint_core/failure_offline.py',
    'urdf': 'src/freejoint_core/freejoint_core/urdf_offline.py',
    'spatial': 'src/freejoint_core/freejoint_core/spatial_offline.py',
    'campaign (scalar reference)': 'src/freejoint_core/freejoint_core/batch.py',
    'node (control loop)': 'src/freejoint_control/freejoint_control/loop.py',
}
"""Every place that runs a law over time, and the file it lives in."""
LAW_CLASSES = ('RobustController', 'RobustLaw', 'SpatialLaw', 'SpatialControlLaw',
               'SlidingModeLaw', 'TimeDelayLaw', 'TaskLaw')
"""The law implementations a runner must not build itself."""


def _calls(path):
    with open(os.path.join(ROOT, path), encoding='utf-8') as f:
        tree = ast.parse(f.read())
    for node in ast.walk(tree):
        if isinstance(node, ast.Call):
            fn = node.func
            yield fn.id if isinstance(fn, ast.Name) else getattr(fn, 'attr', '')


@pytest.mark.parametrize('runner', sorted(RUNNERS))
def test_every_runner_builds_its_law_through_the_registry(runner):
    calls = set(_calls(RUNNERS[runner]))
    assert 'make_law' in calls, runner
    assert not calls & set(LAW_CLASSES), (runner, sorted(calls & set(LAW_CLASSES)))


LAW_MODULES = ('control.py', 'laws.py', 'law_tdc.py', 'law_vsc.py', 'spatial_law.py',
               'task_law.py')
"""The modules of freejoint_core that define the laws (and may build their parts)."""


def _sources():
    """Yield every Python file of src/ (tests excluded), tools/ and bench/, from ROOT."""
    for top in ('src', 'tools', 'bench'):
        for folder, dirs, files in os.walk(os.path.join(ROOT, top)):
            dirs[:] = [d for d in dirs if d != 'test' and not d.startswith('.')]
            for name in files:
                if name.endswith('.py'):
                    yield os.path.relpath(os.path.join(folder, name), ROOT)


def test_no_law_is_built_but_by_the_registry_nor_changed_after_it_is_built():
    """A law and its options (null space, the free link's damping) come from make_law."""
    built = {}
    changed = {}
    for path in _sources():
        law_module = path.startswith('src/freejoint_core/freejoint_core/') and \
            os.path.basename(path) in LAW_MODULES
        with open(os.path.join(ROOT, path), encoding='utf-8') as f:
            tree = ast.parse(f.read())
        for node in ast.walk(tree):
            if isinstance(node, ast.Call) and not law_module:
                fn = node.func
                name = fn.id if isinstance(fn, ast.Name) else getattr(fn, 'attr', '')
                if name in LAW_CLASSES + ('FreeLinkDampedLaw',):
                    built.setdefault(path, []).append(f'{name}() at line {node.lineno}')
            if isinstance(node, ast.Assign) and not law_module:
                for target in node.targets:
                    if isinstance(target, ast.Attribute) and target.attr == 'nullspace':
                        changed.setdefault(path, []).append(
                            f'.nullspace = at line {node.lineno}')
    assert built == {}
    assert changed == {}


PAPER_FIELDS = ('theta', 'rho', 'dv', 'det', 'kappa')
"""What the paper's output tuple had beyond the generic fields: a law's internals now."""


def test_no_runner_reads_a_law_output_but_by_its_generic_fields_and_declared_internals():
    found = []
    for path in _sources():
        with open(os.path.join(ROOT, path)) as f:
            tree = ast.parse(f.read(), path)
        for node in ast.walk(tree):
            if isinstance(node, ast.Name) and node.id in ('ControlOutput', 'SpatialOutput'):
                found.append((path, node.lineno, node.id))
            if (isinstance(node, ast.Attribute) and node.attr in PAPER_FIELDS
                    and isinstance(node.value, ast.Name) and node.value.id == 'out'):
                found.append((path, node.lineno, 'out.' + node.attr))
    assert found == []


def _spatial_nominal():
    from freejoint_core.spatial_model import known_arm
    return known_arm('ur5', ['wrist_2_joint'])


@pytest.mark.parametrize('name', ['robust', 'vsc', 'tdc', 'spatial'])
def test_each_law_gives_the_internal_values_it_declares_in_order_and_shape(name):
    if name == 'spatial':
        from freejoint_core.spatial_law import SpatialGains
        nominal = _spatial_nominal()
        law = make_law(name, nominal, SpatialGains(task_dim=3))
        q = np.linspace(0.2, 0.8, nominal.n)
        out = law.step(q, 0.1 * q, nominal.fk(q) + 0.01, (0.1, 0.0, 0.0), (0.0, 0.0, 0.0),
                       1e-3)
        m = 3
    else:
        law = make_law(name, table1('vertical').scaled(0.7), Gains())
        out = law.step(Q, QD, *SP, 1e-3)
        m = 2
    declared = [v.name for v in law.internals]
    assert list(out.internal) == declared and len(set(declared)) == len(declared)
    for value in law.internals:
        got = out.internal[value.name]
        if value.shape:
            shape = tuple(m if d == 'm' else d for d in value.shape)
            assert isinstance(got, np.ndarray) and got.shape == shape, value.name
        else:
            assert isinstance(got, float), value.name
        assert value.unit and value.description, value.name
    assert law.conditioning in declared
    assert out._fields == ('tau', 'e', 'edot', 's', 'p', 'status', 'internal')


def test_the_node_gets_its_null_space_through_the_registry():
    from freejoint_common.schema import nullspace_options
    nominal = table1('vertical').scaled(0.7)
    full = nominal.__class__(**dict(nominal.__dict__, passive=()))
    # the paper's arm (r = m): no null space, whatever nullspace_kd says
    assert make_law('robust', nominal, Gains(), nullspace_kd=5.0).nullspace is None
    law = make_law('robust', full, Gains(), **nullspace_options({'nullspace_kd': 5.0}))
    assert law.nullspace.kd == 5.0
    # a joint failing leaves r = m: the null space goes, and comes back with the joint
    law.set_nominal(nominal)
    assert law.nullspace is None
    law.set_nominal(full)
    assert law.nullspace.kd == 5.0
    assert nullspace_options({'nullspace_kd': 0.0, 'nullspace_kd_joints': [0.0],
                              'nullspace_kp': 0.0}) == {}
    assert nullspace_options({'nullspace_kd': 1.0, 'nullspace_kd_joints': [2.0, 3.0],
                              'nullspace_kp': 4.0}) == {'nullspace_kd': (2.0, 3.0),
                                                        'nullspace_kp': 4.0}
    with pytest.raises(FreejointValueError, match=r"^nullspace_kd: law 'vsc' has no null"):
        make_law('vsc', full, Gains(), nullspace_kd=5.0)


def test_the_shipped_laws_are_registered_with_their_namespaced_gains():
    assert {'robust', 'spatial', 'vsc', 'tdc'} <= set(LAWS)
    names = [g.name for g in laws.gain_schema()]
    assert {'vsc.phi', 'vsc.eta', 'vsc.delta', 'vsc.beta0', 'vsc.beta1', 'tdc.mbar',
            'tdc.filter'} <= set(names)
    assert all(n.split('.')[0] in LAWS for n in names)


def test_a_law_refuses_gains_it_does_not_declare_or_out_of_range():
    nominal = table1('vertical').scaled(0.7)
    with pytest.raises(FreejointValueError, match=r"^vsc\.wind: not a gain of law 'vsc'"):
        make_law('vsc', nominal, Gains(), params={'vsc.wind': 1.0})
    with pytest.raises(FreejointValueError, match=r'^vsc\.delta: expected a finite number in'):
        make_law('vsc', nominal, Gains(), params={'vsc.delta': 1.0})
    with pytest.raises(FreejointValueError, match=r"^robust\.K: law 'robust' has no gains"):
        make_law('robust', nominal, Gains(), params={'robust.K': 1.0})
    with pytest.raises(FreejointValueError, match='is not named mine.<gain>'):
        laws.register_law('mine', SlidingModeLaw)
    # another law's gains are ignored: a configuration carries every law's
    assert make_law('tdc', nominal, Gains(), params={'vsc.phi': 0.2}).params == {
        'tdc.mbar': 1.0, 'tdc.filter': 0.002}


# -- the two laws from the literature, checked by hand ----------------------------------

Q = (0.3, 1.1, -0.4)
QD = (0.5, -0.2, 0.8)
SP = ((0.2, 0.05), (0.1, -0.3), (0.5, 0.2))


def _terms(nominal):
    from freejoint_core.arm import ArmModel
    m = ArmModel(nominal)
    q, qd = np.array(Q), np.array(QD)
    da, b = m.decoupling(q, qd)
    return m.fk(q), m.jacobian(q) @ qd, da, b


def test_the_sliding_mode_law_is_its_documented_formula():
    nominal = table1('vertical').scaled(0.7)
    g = Gains()
    law = make_law('vsc', nominal, g, params={'vsc.phi': 0.05})
    p, v, da, b = _terms(nominal)
    e = p - SP[0]
    edot = v - SP[1]
    lam, k = np.array(g.Lambda), np.array(g.K)
    s = edot + lam * e
    u0 = np.array(SP[2]) - lam * edot - k * s
    ks = (0.4 * np.linalg.norm(u0 - b) + 3.0 + 0.1 * np.dot(QD, QD) + 0.5) / 0.6
    sat = s / max(np.linalg.norm(s), 0.05)
    tau = np.linalg.pinv(da) @ (u0 - ks * sat - b)
    out = law.step(Q, QD, *SP, 1e-3)
    assert out.tau == pytest.approx(tau, rel=1e-9)
    assert law.state_values() == pytest.approx([ks, np.linalg.norm(s) / 0.05], rel=1e-12)
    assert list(out.internal) == ['switching_gain', 'switching_term', 'det']
    assert out.internal['switching_gain'] == pytest.approx(ks, rel=1e-12) and out.status == 0
    # inside the layer the switching term is linear in s
    law.params['vsc.phi'] = 10.0 * np.linalg.norm(s)
    out = law.step(Q, QD, *SP, 1e-3)
    assert out.internal['switching_term'] == pytest.approx(-ks * s / law.params['vsc.phi'],
                                                           rel=1e-9)


def test_time_delay_control_starts_as_the_nominal_law_and_estimates_from_the_last_tick():
    nominal = table1('vertical').scaled(0.7)
    law = make_law('tdc', nominal, Gains(), params={'tdc.filter': 0.0})
    nominal_ct = RobustController(nominal, Gains(robust=False), use_fast=False)
    first = law.step(Q, QD, *SP, 1e-3)
    assert first.tau == pytest.approx(nominal_ct.step(Q, QD, *SP, 1e-3).tau, rel=1e-9)
    # the next tick: N^ = (v_1 - v_0) / dt - Da(q_1) tau_0 (mbar 1, no filter)
    q1 = tuple(x + 1e-3 * w for x, w in zip(Q, QD))
    qd1 = (0.51, -0.21, 0.79)
    _, v0, _, _ = _terms(nominal)
    from freejoint_core.arm import ArmModel
    m = ArmModel(nominal)
    v1 = m.jacobian(np.array(q1)) @ np.array(qd1)
    da1, _ = m.decoupling(np.array(q1), np.array(qd1))
    n_hat = (v1 - v0) / 1e-3 - da1 @ first.tau
    second = law.step(q1, qd1, *SP, 1e-3)
    assert law.state_values() == pytest.approx(n_hat.tolist(), rel=1e-9)
    e = m.fk(np.array(q1)) - SP[0]
    edot = v1 - SP[1]
    s = edot + 50.0 * e
    u0 = np.array(SP[2]) - 50.0 * edot - 100.0 * s
    assert second.tau == pytest.approx(np.linalg.pinv(da1) @ (u0 - n_hat), rel=1e-8)
    saved = law.save_state()
    law.restart_motion()                      # braked: the next tick is the nominal law again
    assert law.step(Q, QD, *SP, 1e-3).tau == pytest.approx(first.tau, rel=1e-12)
    law.restore_state(saved)
    assert law.state_values() == pytest.approx(n_hat.tolist(), rel=1e-9)


@pytest.mark.parametrize('name', ['vsc', 'tdc'])
@pytest.mark.parametrize('case', ['horizontal', 'vertical'])
def test_the_laws_from_the_literature_track_the_paper_circle_offline(name, case):
    rec, _ = offline.run_case(case, 'robust', 0, law=name)
    assert rec['diverged_at_s'] is None and rec['max_mm'] < 5.0, rec
    assert rec['variant'] == f'{name} robust' and rec['theta_final'] == []


# -- a new law: one module, one registration --------------------------------------------

NEW_LAW = '''
"""A test law: the nominal computed torque with its feedback gains scaled."""
from freejoint_core.law_base import LawGain, LawValue
from freejoint_core.laws import register_law
from freejoint_core.task_law import TaskLaw


class ScaledComputedTorque(TaskLaw):
    name = 'scaled_ct'
    gain_schema = (LawGain('scaled_ct.scale', 1.0, 'feedback scale', (0.1, 10.0)),)
    internals = (LawValue('feedback_change', ('m',), 'm/s^2', 'u - u0'),)   # its own only
    conditioning = None

    def command(self, q, qd, v, da, b, e, edot, s, u0, pdd_d, dt):
        c = self.params['scaled_ct.scale']
        u = pdd_d + c * (u0 - pdd_d)
        return u - b, {'feedback_change': u - u0}


register_law(ScaledComputedTorque.name, ScaledComputedTorque)
'''


@pytest.fixture
def new_law(tmp_path, monkeypatch):
    """Write the new law's module, import it (its registration), remove it afterwards."""
    (tmp_path / 'scaled_ct_law.py').write_text(textwrap.dedent(NEW_LAW))
    monkeypatch.syspath_prepend(str(tmp_path))
    import scaled_ct_law
    yield scaled_ct_law
    del LAWS['scaled_ct']
    sys.modules.pop('scaled_ct_law', None)


def test_a_new_law_in_one_module_runs_in_the_loop_the_offline_runner_and_a_campaign(new_law):
    from freejoint_control.loop import ControlLoop
    from freejoint_control.params import SCHEMA
    from freejoint_tools import campaign
    # the offline runner: scale 1 is the nominal computed torque (robust: false)
    rec, tr = offline.run_case('vertical', 'robust', 0, law='scaled_ct', duration=0.2,
                               record_trace=True)
    ref, tr_ref = offline.run_case('vertical', 'robust_off', 0, duration=0.2,
                                   record_trace=True)
    assert np.allclose(tr['tau'], tr_ref['tau'], rtol=1e-7, atol=1e-9)
    assert rec['max_mm'] == pytest.approx(ref['max_mm'], rel=1e-6)
    # ... reporting only what it declares: no estimate, no conditioning, no robust gain
    assert rec['theta_final'] == [] and rec['min_det'] == 0.0 and ref['min_det'] > 0.0
    assert tr['theta'].shape == (200, 0) and not tr['rho'].any() and not tr['det'].any()
    out = make_law('scaled_ct', table1('vertical'), Gains()).step(Q, QD, *SP, 1e-3)
    assert list(out.internal) == ['feedback_change'] and out.internal['feedback_change'] \
        == pytest.approx([0.0, 0.0], abs=1e-12)
    # the control loop (the node's): the parameter value names it
    values = dict(SCHEMA.yaml_values(os.path.join(ROOT, 'config', 'controller.yaml')),
                  readiness_guard=False, law='scaled_ct')
    loop = ControlLoop(SCHEMA.config(values))
    assert type(loop.law) is new_law.ScaledComputedTorque
    twin = make_law('scaled_ct', loop.law.nominal, loop.law.gains)
    names = loop.config.joint_names
    q0, qd0 = (0.1, 1.2, -0.3), (0.0, 0.1, 0.0)
    for k in range(3):
        loop.on_setpoint(k * 1_000_000, (0.2, 0.01 * k, 0.0, 0.1, 0.0, 0.0), 0, 100.0 + k * 1e-3)
        res = loop.on_state(k * 1_000_000, names, list(q0), list(qd0), k * 1_000_000,
                            100.0 + k * 1e-3)
        out = twin.step(q0, qd0, (0.2, 0.01 * k), (0.0, 0.1), (0.0, 0.0), 1e-3)
        assert res.effort == pytest.approx(out.tau.tolist(), rel=1e-12)
        assert res.det_dd == 0.0 and res.law_state_values == []
    # a small campaign comparing it with the paper's law (its scalar step: no kernel)
    camp = campaign.parse({'name': 'new_law', 'case': 'vertical', 'duration': 0.2,
                           'laws': ['robust', 'scaled_ct'],
                           'controller': {'scaled_ct.scale': 1.0},
                           'design': {'kind': 'grid'},
                           'axes': {'dist_bound': {'values': [0.0, 1.0]}}})
    rows = campaign.design(camp)
    res = campaign.run_chunk(dict(camp, _law='scaled_ct'), rows)
    for i in range(2):
        run = {k: rows[k][i] for k in batch.RUN_FIELDS if k in rows}
        run.update(vertical=True, dist_type=0)
        m, _ = batch.run_scalar(run, law='scaled_ct', duration=0.2)
        assert res['max_mm'][i] == m['max_mm'] and res['ticks'][i] == m['ticks']
        assert m['min_det'] == 0.0 and m['theta_final_norm'] == 0.0


def test_a_law_without_a_kernel_runs_in_campaigns_through_its_scalar_step(new_law):
    assert 'scaled_ct' not in batch.KERNELS
    runs = batch.run_defaults(3)
    runs['vertical'][:] = True
    runs['dist_bound'] = np.array([0.0, 0.5, 2.0])
    one = batch.simulate_law(runs, law='scaled_ct', duration=0.3, processes=1)
    two = batch.simulate_law(runs, law='scaled_ct', duration=0.3, processes=2)
    for name in batch.METRICS:
        assert np.array_equal(one[name], two[name], equal_nan=True), name
    for i in range(3):
        m, _ = batch.run_scalar({k: v[i] for k, v in runs.items()}, law='scaled_ct',
                                duration=0.3)
        assert one['max_mm'][i] == m['max_mm'] and math.isnan(one['diverged_at_s'][i])
    # the paper's law runs its batched kernel, which equals its scalar step
    ker = batch.simulate_law(runs, law='robust', duration=0.3)
    for i in range(3):
        m, _ = batch.run_scalar({k: v[i] for k, v in runs.items()}, duration=0.3)
        assert ker['max_mm'][i] == pytest.approx(m['max_mm'], rel=1e-9)


def test_the_laws_of_one_module_each_are_what_the_registry_builds():
    nominal = table1('horizontal').scaled(0.7)
    assert type(make_law('vsc', nominal, Gains())) is SlidingModeLaw
    assert type(make_law('tdc', nominal, Gains())) is TimeDelayLaw


@pytest.mark.parametrize('law, gain, value, cls', [('vsc', 'vsc.phi', 0.05, SlidingModeLaw),
                                                   ('tdc', 'tdc.filter', 0.0, TimeDelayLaw)])
def test_the_node_builds_the_laws_from_the_literature_with_their_namespaced_parameters(
        law, gain, value, cls):
    from freejoint_control.loop import ControlLoop
    from freejoint_control.params import SCHEMA
    values = dict(SCHEMA.yaml_values(os.path.join(ROOT, 'config', 'controller.yaml')),
                  readiness_guard=False, law=law)
    values[gain] = value
    loop = ControlLoop(SCHEMA.config(values))
    assert type(loop.law) is cls and loop.law.params[gain] == value
    assert loop.result.law_state_names == cls.state_names
    values[gain] = -1.0
    with pytest.raises(FreejointValueError, match=f'^{gain}: '):
        SCHEMA.config(values)


def test_the_null_space_parameters_are_one_declaration_checked_alike_in_both_nodes():
    from freejoint_common.schema import nullspace_dampings
    from freejoint_control.params import SCHEMA as CONTROLLER
    from freejoint_planner.params import SCHEMA as PLANNER
    for schema in (CONTROLLER, PLANNER):
        per_joint = schema['nullspace_kd_joints']
        assert per_joint.validator is nullspace_dampings
        # the reason names the parameter and the bad value
        assert per_joint.reason([5.0, -1.0]) == (
            'nullspace_kd_joints: expected one or more values in [0, 10000], got [5.0, -1.0]')
        assert per_joint.reason([float('nan')]).startswith('nullspace_kd_joints: expected one')
        assert per_joint.reason(['a']) == (
            "nullspace_kd_joints: expected a list of numbers, got ['a']")
        assert per_joint.reason([0.0]) is None and per_joint.reason([1.0, 2.5]) is None
        for name in ('nullspace_kd', 'nullspace_kp'):
            assert schema[name].bounds == (0.0, 1e4)
            assert schema[name].reason(2e4).startswith(f'{name}: expected a value in [0, 10000]')
    assert CONTROLLER['nullspace_kd'].default == 0.0 and PLANNER['nullspace_kd'].default == 20.0
