"""
Per-tick arrays of a run from its messages (the graph's and the bag analysis's records).

The ROS graph publishes, per control tick k (stamp t_k), one ``ControllerState`` and one
``JointState``.  :func:`arrays_from_messages` pairs them by stamp and returns the arrays
that ``freejoint_core.metrics.compute_record`` takes, so that the demo (messages received
live) and the bag analysis (messages read back from a bag) compute the same record from
the same messages.  Only attribute access is used, so messages deserialised by rclpy and
by ``rosbags`` both work.

"""

from freejoint_common.contract import to_ns
import numpy as np


def stamp_ns(msg):
    """
    Return the header stamp of ``msg`` in integer nanoseconds.

    Parameters
    ----------
    msg : object
        A message with ``header.stamp.sec`` and ``header.stamp.nanosec``.

    Returns
    -------
    int

    """
    return to_ns(msg.header.stamp)


THETA_NAMES = tuple('theta_hat[%d]' % i for i in range(5))
"""The names of the paper's law's adaptive estimate in ``ControllerState.law_state_names``."""


def theta_hat(msg):
    """
    Return the paper's law's adaptive estimate (5 values) of a ControllerState, either layout.

    Parameters
    ----------
    msg : freejoint_msgs/ControllerState
        Since the law's state is generic: ``law_state`` named by ``law_state_names``
        (``theta_hat[0]`` .. ``theta_hat[4]``); before (old bags): ``theta_hat float64[5]``.

    Returns
    -------
    tuple of float, (5,)
        Zeros for a law without a theta_hat (its state has no such names).

    """
    names = getattr(msg, 'law_state_names', None)
    if names is None:
        return tuple(msg.theta_hat)
    names = list(names)
    values = msg.law_state
    if names[:5] == list(THETA_NAMES):
        return tuple(values[:5])
    try:
        return tuple(values[names.index(n)] for n in THETA_NAMES)
    except ValueError:
        return (0.0,) * 5


def arrays_from_messages(states, joint_states, passive_joint, max_ticks=None):
    """
    Pair controller states with joint states by stamp; return the per-tick arrays.

    A tick is a stamp that has both a ``ControllerState`` and a ``JointState`` carrying
    ``passive_joint``.  For a stamp seen more than once (a republished start state, an
    answer repeated for a repeated state), the first message counts: it is the one the
    simulator acted on.  Ticks are returned in stamp order.

    Parameters
    ----------
    states : iterable of freejoint_msgs/ControllerState
        Per tick: ``position`` (p), ``position_desired`` (p_d), ``effort`` (tau),
        ``det_dd`` and theta_hat (:func:`theta_hat`: ``law_state`` by its names, or the
        field ``theta_hat`` of the layout before the law's state was generic).
    joint_states : iterable of sensor_msgs/JointState
        Per tick: the position of ``passive_joint`` (the passive angle, rad).
    passive_joint : str
        Name of the passive joint in ``JointState.name``.
    max_ticks : int, optional
        Keep only the first ``max_ticks`` ticks.

    Returns
    -------
    dict
        ``t`` (N,) s, ``p`` (N, m), ``p_d`` (N, m), ``tau`` (N, r), ``theta`` (N, 5),
        ``q_passive`` (N,), ``det`` (N,): the keyword arguments of
        ``compute_record`` (``compute_record(case, variant, seed, **arrays, ...)``).

    Raises
    ------
    ValueError
        No tick found (the message names what was missing), or the effort length
        changes between ticks.

    """
    by_stamp = {}
    for msg in states:
        by_stamp.setdefault(stamp_ns(msg), msg)
    q_passive = {}
    for msg in joint_states:
        ns = stamp_ns(msg)
        if ns in q_passive or ns not in by_stamp:
            continue
        names = list(msg.name)
        if passive_joint in names:
            q_passive[ns] = float(msg.position[names.index(passive_joint)])
    stamps = sorted(ns for ns in by_stamp if ns in q_passive)
    if not stamps:
        raise ValueError(
            f'no tick has both a ControllerState and a JointState with {passive_joint!r} '
            f'({len(by_stamp)} controller stamps, {len(q_passive)} matching joint states)')
    if max_ticks is not None:
        stamps = stamps[:max_ticks]
    picked = [by_stamp[ns] for ns in stamps]
    r = len(picked[0].effort)
    if any(len(m.effort) != r for m in picked):
        raise ValueError(f'effort: the number of active joints changes between ticks '
                         f'(first tick has {r})')
    return {
        't': np.array(stamps, dtype=np.int64) * 1e-9,
        'p': np.array([tuple(m.position) for m in picked], dtype=float),
        'p_d': np.array([tuple(m.position_desired) for m in picked], dtype=float),
        'tau': np.array([tuple(m.effort) for m in picked], dtype=float).reshape(-1, r),
        'theta': np.array([theta_hat(m) for m in picked], dtype=float).reshape(-1, 5),
        'q_passive': np.array([q_passive[ns] for ns in stamps], dtype=float),
        'det': np.array([m.det_dd for m in picked], dtype=float),
    }
