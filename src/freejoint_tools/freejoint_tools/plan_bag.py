"""
The arrays of a bag that ``freejoint_core.plan_figures.plan_figures`` takes: the arm vs the plan.

From the recorded topics only, independent of what the controller says it tracked:

* the state stamps and the measured end effector: ``ee_position`` (the simulator's or
  driver's forward kinematics of each state it published; the first per stamp);
* the plan: the ``setpoints`` batches (stamps, positions, velocities, plan ids, plan
  times, end marks; the last recorded per stamp);
* per state, whether the controller did not track the plan from it: no command
  (``effort_controller/commands``, labelled with the stamp answered) answered it or any
  state of the :data:`SILENT` s before it - a drive's watchdog brakes then; a single state
  left unanswered only leaves the previous command on - or its ``controller_state`` (the
  one of the stamp, else the last one before it: a thinned stream publishes every change
  of status) has ``STATUS_HOLDING``.

Stamps become seconds from the first state's stamp (integer ns subtracted first: system
time keeps its sub-microsecond resolution); ``origin_ns`` says from which.
"""

from freejoint_common.contract import COMMANDS, CONTROLLER_STATE, EE_POSITION, PLAN_OUTCOME
from freejoint_common.contract import label_stamp, setpoint_samples, SETPOINTS, to_ns
import numpy as np

STATUS_HOLDING = 32
"""``freejoint_msgs/ControllerState.STATUS_HOLDING``."""
SILENT = 0.05
"""[s] A state none of whose last this long was answered counts as braked (the simulator's
``brake_timeout``: its drive watchdog's wait)."""


def plan_arrays(bag, store=None, window_ns=None):
    """
    Return the keyword arguments of ``plan_figures`` of an open bag (without the bound).

    Parameters
    ----------
    bag : freejoint_tools.bagfile.Bag
        An open bag with ``ee_position`` and ``setpoints``.
    store : optional
        Its type store (``bag.typestore()``), if already made.
    window_ns : tuple of int, optional
        ``(first, last)``: only the states stamped in it [ns] (the setpoints all).

    Returns
    -------
    tuple of (dict, int)
        ``t``, ``p``, ``sp_t``, ``sp_p``, ``sp_v``, ``held`` (None without commands
        recorded), ``plan_id``, ``plan_time``, ``final``, ``plan_end`` (with
        ``plan_outcome`` recorded: each plan's outcome stamp [s]); and ``origin_ns`` (the
        first state's stamp [ns], the time the stamps count from).

    Raises
    ------
    ValueError
        The bag lacks ``ee_position`` or ``setpoints`` messages (named).

    """
    store = store or bag.typestore()
    names = [EE_POSITION.absolute, SETPOINTS.absolute]
    for name in names:
        if name not in bag.topics or not bag.topics[name].count:
            raise ValueError('no %s in the bag: no figures against the plan' % name)
    extra = [n for n in (COMMANDS.absolute, CONTROLLER_STATE.absolute, PLAN_OUTCOME.absolute)
             if n in bag.topics and bag.topics[n].count]
    decoded = bag.decode_topics(names + extra, store)
    ee = {}
    for _, msg in decoded[EE_POSITION.absolute]:
        ee.setdefault(to_ns(msg.header.stamp), msg.point)
    stamps = np.array(sorted(ee), dtype=np.int64)
    if window_ns is not None:
        stamps = stamps[(stamps >= window_ns[0]) & (stamps <= window_ns[1])]
    setpoints = {}
    for _, msg in decoded[SETPOINTS.absolute]:
        for sp in setpoint_samples(msg):
            setpoints[sp.stamp_ns] = sp
    if not setpoints:
        raise ValueError('the %s messages hold no setpoint' % SETPOINTS.absolute)
    sp_ns = np.array(sorted(setpoints), dtype=np.int64)
    sps = [setpoints[k] for k in sp_ns.tolist()]
    m = len(sps[0].position)
    if m not in (2, 3):
        raise ValueError('setpoints of %d values per vector (2 or 3 expected)' % m)
    if any(len(sp.position) != m for sp in sps):
        raise ValueError('setpoints: the number of values per vector changes')
    points = [ee[k] for k in stamps.tolist()]
    p = np.array([(q.x, q.y, q.z)[:m] for q in points], dtype=float).reshape(-1, m)
    origin = int(stamps[0]) if len(stamps) else int(sp_ns[0])
    out = {'t': (stamps - origin) * 1e-9, 'p': p,
           'sp_t': (sp_ns - origin) * 1e-9,
           'sp_p': np.array([sp.position for sp in sps], dtype=float),
           'sp_v': np.array([sp.velocity for sp in sps], dtype=float),
           'held': None,
           'plan_id': np.array([sp.plan_id for sp in sps], dtype=np.int64),
           'plan_time': np.array([sp.plan_time for sp in sps], dtype=float),
           'final': np.array([sp.final for sp in sps], dtype=bool)}
    if PLAN_OUTCOME.absolute in extra:
        out['plan_end'] = {int(msg.plan_id): (to_ns(msg.stamp) - origin) * 1e-9
                           for _, msg in decoded[PLAN_OUTCOME.absolute] if msg.plan_id > 0}
    if COMMANDS.absolute in extra:
        answered = {label_stamp(msg.layout.dim) for _, msg in decoded[COMMANDS.absolute]}
        answered = np.array(sorted(k for k in answered if k is not None), dtype=np.int64)
        i = np.searchsorted(answered, stamps, side='right') - 1
        last = np.where(i >= 0, answered[np.maximum(i, 0)] if len(answered) else 0, 0)
        held = (i < 0) | (stamps - last > round(SILENT * 1e9))
        if CONTROLLER_STATE.absolute in extra:
            first = {}
            for _, msg in decoded[CONTROLLER_STATE.absolute]:
                first.setdefault(to_ns(msg.header.stamp), int(msg.status))
            cs_ns = np.array(sorted(first), dtype=np.int64)
            status = np.array([first[k] for k in cs_ns.tolist()], dtype=np.int64)
            i = np.searchsorted(cs_ns, stamps, side='right') - 1
            holding = np.where(i >= 0, status[np.maximum(i, 0)] & STATUS_HOLDING, 0) != 0
            held |= holding
        out['held'] = held
    return out, origin


def bag_plan_figures(path, bound_mm=None, window_ns=None):
    """
    Return the figures against the plan of the bag at ``path`` (opened here).

    Parameters
    ----------
    path : str
        A bag directory.
    bound_mm : float, optional
        The run's tracking bound [mm] (``freejoint_core.plan_figures.tracking_bound_mm``).
    window_ns : tuple of int, optional
        Only the states stamped in ``(first, last)`` [ns].

    Returns
    -------
    dict
        ``plan_figures``'s, with ``origin_ns`` added.

    """
    from freejoint_core.plan_figures import plan_figures
    from .bagfile import open_bag
    arrays, origin = plan_arrays(open_bag(path), window_ns=window_ns)
    figures = plan_figures(bound_mm=bound_mm, **arrays)
    figures['origin_ns'] = origin
    return figures


def plan_summary(path, case=None):
    """
    Return one line of the figures against the plan of the bag at ``path``.

    The recorder's end-of-run summary. The bound is the paper's case's
    (``tracking_bound_mm``) when ``case`` (the run information's) is one, else none.

    Parameters
    ----------
    path : str
        A finalised bag directory.
    case : str, optional
        'horizontal' or 'vertical'.

    Returns
    -------
    str
        ``format_figures`` of the bag.

    """
    from freejoint_core.plan_figures import format_figures, tracking_bound_mm
    bound = tracking_bound_mm(case)[0] if case in ('horizontal', 'vertical') else None
    return format_figures(bag_plan_figures(path, bound))
