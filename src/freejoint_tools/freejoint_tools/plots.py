"""
The paper's figures from analysed bags (matplotlib, Agg, PNG; no pyplot state).

* :func:`figure2` - Fig. 2: (a) the singular samples of ``|det(Da Da^T)| <= eps_d`` in
  joint space (the relative joints 2 and 3; any base angle; a longer arm's map projected
  onto them) and (b) the semi-singular annuli in Cartesian space, both recomputed by
  ``freejoint_core.singularity_nlink.arm_region`` for the nominal model of the bag's arm
  (``analyze.bag_arm``: the recorded URDF, else Table I), on the finest grid of
  ``FIG2_GRIDS_DEG`` the map allows (0.25 deg for a 3-link arm; the title states it), with
  the recorded planner map (OccupancyGrid, shaded) and planned path (Marker) overlaid when
  the bag has them, and the run's recorded path and joint trajectory;
* :func:`figure_run` - Figs. 3/4 of one run: path in the x-y plane (desired and actual),
  tracking errors, active torques, passive joint angle, theta-hat over time, error norm;
* :func:`figure_compare` - several runs side by side.
"""

import os

import matplotlib
matplotlib.use('Agg')
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.patches import Circle, Wedge  # noqa: E402
import numpy as np  # noqa: E402

DPI = 72
FIG2_GRIDS_DEG = (0.25, 0.5, 1.0, 2.0, 3.0, 4.0, 6.0, 8.0, 10.0)
"""Fig. 2's joint-space grid steps, finest first: the first whose map is within the core's
sample limit is computed (0.25 deg, the planner's default, for a 3-link arm)."""
FIG_NUMBER = {'horizontal': 3, 'vertical': 4}
CASE_TITLE = {'horizontal': 'Case 1 (horizontal motion)',
              'vertical': 'Case 2 (vertical motion)'}


def _label(trace):
    info = trace['info']
    seed = '' if info['seed'] is None else ', seed %d' % info['seed']
    return '%s (%s%s)' % (trace['name'], info['variant'], seed)


def _passive(trace):
    """Return the name of the plotted passive joint."""
    return trace['info']['passive_joint']


def _arm_text(trace):
    """Return the arm of a run for a title ('' for the paper's Table I arm)."""
    arm = trace.get('arm')
    if not arm or arm['name'] == 'Table I':
        return ''
    return '%s arm, passive %s' % (arm['name'], ', '.join(arm['passive']))


def run_title(trace):
    """
    Return the title of a run's figure: the case once, then what else tells the run apart.

    ``Case 1 (horizontal motion): robust, seed 0`` for a bag named after its case; the
    bag's name is added when it says something else, and the arm when it is not Table I.
    """
    info = trace['info']
    case = info['case']
    parts = [CASE_TITLE.get(case, 'case %s' % case)]
    what = [info['variant']] + ([] if info['seed'] is None else ['seed %d' % info['seed']])
    if trace['name'] != case:
        what.append('bag %s' % trace['name'])
    arm = _arm_text(trace)
    if arm:
        what.append(arm)
    return '%s: %s, from the bag%s' % (parts[0], ', '.join(what),
                                       '' if trace['finalised'] else ' (not finalised)')


def _time_label(trace):
    """Return the time axis label: sim time, or system time from the run's first tick."""
    return 't [s]' if not trace.get('t0') else 't [s] from the first tick'


def run_figure_name(trace):
    """Return the file name of a run's figure: fig3_<bag>.png, fig4_<bag>.png or run_."""
    number = FIG_NUMBER.get(trace['info']['case'])
    return ('fig%d_%s.png' % (number, trace['name'])) if number else (
        'run_%s.png' % trace['name'])


def path_plane(p_d):
    """
    Return the plane a tip path is drawn in: ``(origin (m,), u (m,), v (m,), labels)``.

    A planar arm's (m = 2): its own x, y. A spatial arm's (m = 3): the plane of the
    desired path's two largest principal directions (the circle's plane), through its
    mean, ``u`` with a non-negative largest entry.
    """
    p_d = np.asarray(p_d, dtype=float)
    if p_d.shape[1] == 2:
        return np.zeros(2), np.array([1.0, 0.0]), np.array([0.0, 1.0]), ('x [m]', 'y [m]')
    origin = p_d.mean(axis=0)
    _, _, vt = np.linalg.svd(p_d - origin, full_matrices=False)
    u, v = (w if w[np.argmax(np.abs(w))] >= 0.0 else -w for w in vt[:2])
    return origin, u, v, ('u [m] (in the plane of the path)', 'v [m]')


def _drawn(p, plane):
    """Return the coordinates (N, 2) of points ``p`` (N, m) in a ``path_plane``."""
    origin, u, v, _ = plane
    d = np.asarray(p, dtype=float) - origin
    return np.column_stack((d @ u, d @ v))


def figure_run(trace, path):
    """Write Fig. 3/4 of one run to ``path`` (a spatial arm: its path in the path's plane)."""
    t = trace['t']
    tlabel = _time_label(trace)
    p, p_d = trace['p'], trace['p_d']
    err_mm = 1000.0 * (p - p_d)
    fig = Figure(figsize=(12.0, 6.6))
    axes = fig.subplots(2, 3)
    ax = axes[0, 0]
    plane = path_plane(p_d)
    if p.shape[1] != 2:
        p, p_d = _drawn(p, plane), _drawn(p_d, plane)
    ax.plot(p_d[:, 0], p_d[:, 1], 'k--', lw=1.2, label='desired')
    ax.plot(p[:, 0], p[:, 1], 'C3', lw=1.0, label='actual')
    ax.plot(p_d[0, 0], p_d[0, 1], 'ko', ms=4)
    ax.set_aspect('equal', adjustable='datalim')
    ax.set_xlabel(plane[3][0])
    ax.set_ylabel(plane[3][1])
    ax.set_title('(a) end-effector path')
    ax.legend(loc='upper right', fontsize=8)
    ax = axes[0, 1]
    for i, name in enumerate('xyz'[:err_mm.shape[1]]):
        ax.plot(t, err_mm[:, i], label='$e_%s$' % name)
    ax.set_xlabel(tlabel)
    ax.set_ylabel('error [mm]')
    ax.set_title('(b) tracking errors')
    ax.legend(fontsize=8)
    ax = axes[0, 2]
    for i in range(trace['tau'].shape[1]):
        ax.plot(t, trace['tau'][:, i], lw=0.8, label=r'$\tau_%d$' % (i + 1))
    ax.set_xlabel(tlabel)
    ax.set_ylabel('torque [N m]')
    ax.set_title('(c) active joint torques')
    ax.legend(fontsize=8)
    ax = axes[1, 0]
    ax.plot(t, np.degrees(trace['q_passive']), 'C2')
    ax.set_xlabel(tlabel)
    ax.set_ylabel('%s [deg]' % _passive(trace))
    ax.set_title('(d) passive joint %s' % _passive(trace))
    ax = axes[1, 1]
    theta = np.atleast_2d(trace['theta'])
    for i in range(theta.shape[1]):
        ax.plot(t, theta[:, i], lw=1.0, label=r'$\hat\theta_%d$' % (i + 1))
    ax.set_xlabel(tlabel)
    ax.set_ylabel(r'$\hat\theta$')
    ax.set_title(r'(e) adaptive estimates $\hat\theta$')
    ax.legend(fontsize=7, ncol=2)
    ax = axes[1, 2]
    norm = np.hypot(err_mm[:, 0], err_mm[:, 1]) if err_mm.shape[1] == 2 else \
        np.linalg.norm(err_mm, axis=1)
    ax.semilogy(t, np.maximum(norm, 1e-6), 'C4')
    ax.set_xlabel(tlabel)
    ax.set_ylabel(r'$\|p - p_d\|$ [mm]')
    ax.set_title('(f) error norm')
    for ax in axes.flat:
        ax.grid(True, alpha=0.3)
    _mark_failures(trace, axes.flat[1:])
    fig.suptitle(run_title(trace))
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    return path


def _mark_failures(trace, axes):
    """Mark each joint failure (dashed) and its detection (dotted) on the time axes."""
    t0 = trace.get('t0', 0.0)
    for i, f in enumerate(trace.get('failures') or ()):
        for key, style, what in (('failed_s', '--', 'failed'), ('detected_s', ':', 'detected')):
            if f[key] is None:
                continue
            for ax in axes:
                ax.axvline(f[key] - t0, color='k', ls=style, lw=0.8,
                           label='%s %s' % (f['joint'], what) if ax is axes[0] else None)
    if trace.get('failures'):
        axes[0].legend(fontsize=8)


def fig2_region(params, scale, grids=FIG2_GRIDS_DEG):
    """
    Return ``(region, resolution_deg, nominal)`` of Fig. 2 for an arm's real parameters.

    The nominal model ``params.scaled(scale)``; the region of
    ``freejoint_core.singularity_nlink.arm_region`` on the finest step of ``grids`` whose
    map the core computes (a longer arm's finer maps exceed its sample limit).
    """
    from freejoint_core.errors import FreejointValueError
    from freejoint_core.singularity import EPS_D
    from freejoint_core.singularity_nlink import arm_region
    nominal = params.scaled(scale)
    last = None
    for step in grids:
        try:
            return arm_region(nominal, step, EPS_D, cells=False), step, nominal
        except FreejointValueError as exc:      # above the sample limit: a coarser grid
            last = exc
    raise last


def _joint_space_mask(region, pixels=180):
    """
    Return the flagged samples over the relative joints 2 and 3 (others projected).

    A grid finer than ``pixels`` a side is shown in blocks (a block is flagged if any of
    its samples is): one-sample bands of a 0.25 deg map would vanish in the figure.
    Returns ``(mask, samples per block a side)``.
    """
    mask = np.asarray(region.singular_mask, dtype=bool)
    while mask.ndim > 2:
        mask = mask.any(axis=-1)
    side = mask.shape[0]
    block = -(-side // pixels)
    if block > 1 and side % block == 0 and mask.shape[1] == side:
        return mask.reshape(side // block, block, side // block, block).any(axis=(1, 3)), block
    return mask, 1


def figure2(trace, path):
    """Write Fig. 2 (singular regions of the run's arm; see the module notes) to ``path``."""
    from freejoint_core.arm import NOMINAL_SCALE, table1
    info = trace['info']
    case = info['case'] if info['case'] in FIG_NUMBER else 'horizontal'
    scale = info.get('nominal_scale') or NOMINAL_SCALE
    arm = trace.get('arm') or {'params': table1(case), 'joints': ['joint1', 'joint2', 'joint3'],
                               'name': 'Table I', 'passive': ['joint3']}
    region, resolution_deg, _ = fig2_region(arm['params'], scale)
    names = list(arm['joints'])
    fig = Figure(figsize=(11.0, 5.2))
    ax_j, ax_c = fig.subplots(1, 2)
    mask, block = _joint_space_mask(region)
    mask = mask.astype(float)
    ax_j.imshow(np.ma.masked_equal(mask.T, 0.0), origin='lower', extent=(0, 360, 0, 360),
                cmap='Reds', vmin=0.0, vmax=1.2, interpolation='nearest', aspect='auto')
    joints = trace.get('joints') or {}
    ja, jb = names[1], names[2]
    if ja in joints and jb in joints:
        qa = np.degrees(joints[ja]) % 360.0
        qb = np.degrees(joints[jb]) % 360.0
        ax_j.plot(qa, qb, '.', ms=1.0, color='C0', label='run (%s, %s)' % (ja, jb))
        ax_j.legend(loc='upper right', fontsize=8)
    ax_j.set_xlim(-6, 366)      # the q2 = 0 band sits on the edge
    ax_j.set_ylim(-6, 366)
    ax_j.set_xlabel('%s [deg]' % ja)
    ax_j.set_ylabel('%s [deg]' % jb)
    projected = '' if len(names) <= 3 else ', projected over %s' % ', '.join(names[3:])
    if block > 1:
        projected += ', in %g deg blocks' % (block * resolution_deg)
    ax_j.set_title(r'(a) joint space: singular ($|\det(\hat D_a \hat D_a^T)| \leq %g$, red)%s'
                   % (region.eps_d, projected), fontsize=10)
    lo, hi = region.reach
    grid = trace.get('grid')
    if grid is not None and grid.info.width and grid.info.height:
        data = np.asarray(grid.data, dtype=float).reshape(grid.info.height, grid.info.width)
        x0, y0 = grid.info.origin.position.x, grid.info.origin.position.y
        res = grid.info.resolution
        shade = np.ma.masked_where(data <= 0, data)
        ax_c.imshow(shade, origin='lower', cmap='Greys', vmin=0, vmax=200, alpha=0.6,
                    extent=(x0, x0 + res * grid.info.width, y0, y0 + res * grid.info.height),
                    interpolation='nearest')
    for a, b in region.intervals:
        ax_c.add_patch(Wedge((0.0, 0.0), b, 0.0, 360.0, width=max(b - a, 1e-4),
                             color='C3', alpha=0.35, lw=0))
    ax_c.add_patch(Circle((0.0, 0.0), hi, fill=False, ls='--', color='k', lw=0.8))
    if lo > 0:
        ax_c.add_patch(Circle((0.0, 0.0), lo, fill=False, ls='--', color='k', lw=0.8))
    marker = trace.get('path')
    if marker is not None and len(marker.points):
        xs = [pt.x for pt in marker.points]
        ys = [pt.y for pt in marker.points]
        ax_c.plot(xs, ys, 'k-', lw=1.5, label='planned path (recorded Marker)')
    else:
        ax_c.plot(trace['p_d'][:, 0], trace['p_d'][:, 1], 'k-', lw=1.5,
                  label='desired path (recorded setpoints)')
    ax_c.plot(trace['p'][:, 0], trace['p'][:, 1], 'C0', lw=0.8, label='actual path')
    ax_c.set_xlim(-hi * 1.05, hi * 1.05)
    ax_c.set_ylim(-hi * 1.05, hi * 1.05)
    ax_c.set_aspect('equal')
    ax_c.set_xlabel('x [m]')
    ax_c.set_ylabel('y [m]')
    ax_c.set_title('(b) Cartesian space: semi-singular annuli (red)%s' % (
        ', recorded map (grey)' if grid is not None else ''), fontsize=10)
    ax_c.legend(loc='lower right', fontsize=8)
    for ax in (ax_j, ax_c):
        ax.grid(True, alpha=0.3)
    who = ('Table I arm' if arm['name'] == 'Table I' else
           "recorded arm '%s', passive %s" % (arm['name'], ', '.join(arm['passive'])))
    fig.suptitle('Fig. 2 - nominal model (x%.2f) of the %s, %g deg grid; run %s'
                 % (scale, who, resolution_deg, trace['name']), fontsize=11)
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    return path


def figure_compare(traces, path):
    """Write the runs side by side (paths, error norm, passive angle, torques) to ``path``."""
    fig = Figure(figsize=(14.0, 4.4))
    ax_p, ax_e, ax_q, ax_t = fig.subplots(1, 4)
    plane = path_plane(traces[0]['p_d'])
    for i, tr in enumerate(traces):
        color = 'C%d' % (i % 10)
        label = _label(tr)
        p, p_d = tr['p'], tr['p_d']
        if p.shape[1] != 2:
            p, p_d = _drawn(p, plane), _drawn(p_d, plane)
        if i == 0:
            ax_p.plot(p_d[:, 0], p_d[:, 1], 'k--', lw=1.0, label='desired')
        ax_p.plot(p[:, 0], p[:, 1], color=color, lw=0.9, label=label)
        err = 1000.0 * np.linalg.norm(tr['p'] - tr['p_d'], axis=1)
        ax_e.semilogy(tr['t'], np.maximum(err, 1e-6), color=color, lw=0.9, label=label)
        ax_q.plot(tr['t'], np.degrees(tr['q_passive']), color=color, lw=0.9, label=label)
        ax_t.plot(tr['t'], np.max(np.abs(tr['tau']), axis=1), color=color, lw=0.8,
                  label=label)
    ax_p.set_aspect('equal', adjustable='datalim')
    ax_p.set_xlabel(plane[3][0])
    ax_p.set_ylabel(plane[3][1])
    ax_p.set_title('path')
    ax_e.set_xlabel(_time_label(traces[0]))
    ax_e.set_ylabel(r'$\|p - p_d\|$ [mm]')
    ax_e.set_title('tracking error')
    ax_q.set_xlabel(_time_label(traces[0]))
    passive = sorted({_passive(tr) for tr in traces})
    ax_q.set_ylabel('%s [deg]' % ', '.join(passive))
    ax_q.set_title('passive joint %s' % ', '.join(passive))
    ax_t.set_xlabel(_time_label(traces[0]))
    ax_t.set_ylabel(r'max$_i |\tau_i|$ [N m]')
    ax_t.set_title('largest active torque')
    for ax in (ax_p, ax_e, ax_q, ax_t):
        ax.grid(True, alpha=0.3)
    ax_p.legend(fontsize=7)
    fig.suptitle('%d runs side by side (from their bags)' % len(traces))
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    return path


def write_figures(traces, bag_paths, figures_dir=None):
    """
    Write every figure of the analysed runs; return the paths written.

    Per run its Fig. 3/4, once Fig. 2 (from the first run), and with several runs the
    comparison. Into ``figures_dir`` if given, else per-run figures into each bag and the
    others into the bags' common parent directory.
    """
    written = []
    if figures_dir:
        os.makedirs(figures_dir, exist_ok=True)
        common = figures_dir
    else:
        parents = [os.path.dirname(os.path.abspath(p)) for p in bag_paths]
        common = os.path.commonpath(parents) if parents else '.'
        common = os.path.relpath(common) if not os.path.isabs(bag_paths[0]) else common
    for trace, bag in zip(traces, bag_paths):
        out_dir = figures_dir or bag
        written.append(figure_run(trace, os.path.join(out_dir, run_figure_name(trace))))
    if traces and traces[0]['p'].shape[1] == 2:     # the planar arm's joint-space map
        written.append(figure2(traces[0], os.path.join(common, 'fig2_singularity.png')))
    if len(traces) > 1:
        written.append(figure_compare(traces, os.path.join(common, 'compare.png')))
    return written
