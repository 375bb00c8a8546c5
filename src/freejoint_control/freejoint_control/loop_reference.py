"""
The reference the controller's law tracks: the plan's setpoint, held, blended or carried.

:class:`Reference` gives, per answered state, the position, velocity and acceleration
(``3 m`` values) the law is to track, through ``freejoint_core.reference.ReferenceShaper``:
without a setpoint a hold (at the end effector where the arm is when it starts, or, asked
to, at the end of a stop along the moving reference's path); with one,
in real time carried forward along its velocity and acceleration to the state's stamp
(``extrapolate``; older than ``late_periods`` periods: late), blended from a hold or from
the motion back to it. It says so in the status bits (holding, late, stale, resuming) and
gives the hold's stiffness scale. No ROS, no clock.
"""

from freejoint_control.loop_status import STATUS_HOLDING, STATUS_RESUMING, STATUS_SETPOINT_LATE
from freejoint_core.control import STATUS_STALE_SETPOINT
from freejoint_core.reference import extrapolate, MODE_HOLD, MODE_NONE, ReferenceShaper


class Reference:
    """
    The law's reference from the setpoints (module notes).

    Parameters
    ----------
    resume_time : float
        The blend's duration [s] (``resume_time``).
    lockstep : bool
        The lockstep loop (no blend at start, no carrying forward).
    m : int
        The task dimension.

    Attributes
    ----------
    shaper : freejoint_core.reference.ReferenceShaper
        The hold and blend.
    used : bool
        A setpoint was tracked (else: 'no setpoint yet').

    """

    def __init__(self, resume_time, lockstep, m):
        self.shaper = ReferenceShaper(resume_time, blend_on_start=not lockstep, m=m)
        self.used = False
        self._late = False      # real time: the last setpoint used was late
        self._hold_scale = None     # the hold's own stiffness scale (None: hold_stiffness)
        self._ns = None             # stamp [ns] of the last reference given

    def configure(self, cfg):
        """Take the blend's and the hold's parameters and the lateness of a configuration."""
        self._lockstep = cfg.lockstep
        self._late_ns = cfg.late_periods * cfg.dt_ns
        self._hold_stiffness = cfg.hold_stiffness
        self._stop_acceleration = cfg.readiness_stop_acceleration
        self.shaper.set_resume_time(cfg.resume_time)
        self.shaper.set_bounds(cfg.resume_max_velocity, cfg.resume_max_acceleration)

    def step(self, model, q, ns, sp_ns, sp, late, hold_scale=None, stop=False):
        """
        Return ``(ref, status, held)``: the reference for the state stamped ``ns``.

        Parameters
        ----------
        model : ArmModel or SpatialArm
            The law's model (``fk`` of the state: where a hold or blend starts).
        q : tuple of float, (n,)
            The state's angles [rad].
        ns, sp_ns : int
            The state's and the setpoint's stamps [ns] (``sp_ns`` None with ``sp``).
        sp : sequence of float, (3 m,) or None
            The setpoint (None: hold).
        late : bool
            Holding for a late stream (not a stale one).
        hold_scale : float, optional
            The stiffness scale of a hold that starts here (a not-ready loop's,
            ``readiness_hold_stiffness``); None: ``hold_stiffness``. It holds until the
            blend after the hold is over.
        stop : bool, optional
            A hold that starts here while the reference moves stops along its path first
            (``ReferenceShaper.stop`` at ``readiness_stop_acceleration``, from the last
            reference given; real time, the acceleration > 0) instead of holding where the
            arm is.

        Returns
        -------
        ref : sequence of float, (3 m,)
            Position [m], velocity [m/s], acceleration [m/s^2].
        status : int
            Its status bits (holding, late, stale, resuming).
        held : bool
            A hold started here (the command's rate limit is armed again).

        """
        shaper = self.shaper
        status = 0
        held = False
        if sp is None:
            self._late = False
            if shaper.mode != MODE_HOLD:
                ref = None
                if stop and self._stop_acceleration > 0.0 and self._ns is not None \
                        and not self._lockstep:
                    ref = shaper.stop(self._ns * 1e-9, ns * 1e-9, self._stop_acceleration)
                if ref is None:
                    ref = shaper.hold(model.fk(q).tolist(), ns * 1e-9)
                held = True
                self._hold_scale = hold_scale
            else:
                ref = shaper.hold(None, ns * 1e-9)
            self._ns = ns
            status |= STATUS_HOLDING
            if late:
                status |= STATUS_SETPOINT_LATE
            elif self.used:
                status |= STATUS_STALE_SETPOINT
            return ref, status, held
        if not self._lockstep:
            age_ns = ns - sp_ns
            if age_ns > 0:
                sp = extrapolate(sp, age_ns * 1e-9)
            late = age_ns > self._late_ns
            if late:
                status |= STATUS_SETPOINT_LATE
            elif self._late:
                shaper.restart_blend()       # the stream is back: no step to it
            self._late = late
        p_now = model.fk(q).tolist() if shaper.mode == MODE_NONE else None
        ref, blending = shaper.track(ns * 1e-9, sp, p_now)
        self.used = True
        self._ns = ns
        if blending:
            status |= STATUS_RESUMING
        return ref, status, held

    def stiffness(self):
        """
        Return the stiffness scale the law runs at now.

        ``hold_stiffness`` in a hold (or the hold's own scale, ``step``'s ``hold_scale``),
        brought back to 1 over the blend after it.
        """
        scale = self._hold_scale
        return self.shaper.stiffness(self._hold_stiffness if scale is None else scale)
