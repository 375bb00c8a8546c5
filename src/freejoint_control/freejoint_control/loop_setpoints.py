"""
The controller's setpoint input: each setpoint checked, kept, and paired with a state.

:class:`SetpointStream` refuses a setpoint the guards refuse
(``freejoint_core.guards.setpoint_refusal``: out of reach, too fast; the reason kept for
the next hold's message) and keeps the others: lockstep by stamp, the state of the same
stamp takes it; real time in arrival order, a state takes the newest fresh one (stamped at
most half a period after it, not older than ``stale_timeout``). It also tells a hot spare
whether the stream has caught up. Stamps [ns], monotonic time [s]; no ROS, no clock.
"""

from freejoint_core.guards import setpoint_refusal

STANDBY_IDLE_STREAM = 0.25
"""[s] A matched setpoint publisher silent this long is not streaming: a spare does not
wait for it to catch up before it tells the supervisor it is ready."""
_RECENT_MAX = 1000
"""Real time: setpoints kept at most (the older half dropped beyond)."""
_STAMPED_MAX = 10000
"""Lockstep: setpoints waiting for their state kept at most (the older half dropped beyond)."""


class SetpointStream:
    """
    Setpoints as they come, for the states they are paired with (module notes).

    Attributes
    ----------
    seen : bool
        A setpoint was taken (lockstep: a state's wait for its setpoint times out).
    refusal : str
        Why the last setpoint was refused, until one is taken ('' : none).

    """

    def __init__(self):
        self.seen = False
        self.refusal = ''
        self._stamped = {}          # lockstep: stamp_ns -> (p, v, a) flat, (3 m,)
        self._recent = []           # real time: [(stamp_ns, values)], in arrival order
        self._wall = None           # standby: monotonic time of the newest setpoint
        self._matched_wall = None   # standby: when a setpoint publisher was first matched

    def configure(self, task_dim, bounds, half_ns, stale_timeout, carry_ns):
        """
        Take the checks' and the pairing's parameters.

        ``task_dim``: m; ``bounds``: ``(reach [m], max velocity [m/s], max acceleration
        [m/s^2])``; ``half_ns``: half a control period [ns]; ``stale_timeout`` [s]; ``carry_ns``:
        how long a late setpoint is carried forward [ns].
        """
        self._m = task_dim
        self._bounds = bounds
        self._half_ns = half_ns
        self._stale_timeout = stale_timeout
        self._carry_ns = carry_ns

    def refusal_of(self, values):
        """Return why the guards refuse a setpoint's ``3 m`` values, or None."""
        reach, vmax, amax = self._bounds
        return setpoint_refusal(values, reach, vmax, amax, self._m)

    def refused(self, reason):
        """Note a refused setpoint's reason (for :meth:`refusal_note`)."""
        self.refusal = reason

    def refusal_note(self):
        """Return ' (last setpoint refused: why)' after a refusal, else ''."""
        text = self.refusal
        return ' (last setpoint refused: %s)' % text if text else ''

    def taken(self, mono, standby):
        """Note a setpoint taken at monotonic time ``mono`` (``standby``: a spare's wall)."""
        self.refusal = ''
        self.seen = True
        if standby:
            self._wall = mono    # only a spare's readiness reads it

    def add(self, ns, values):
        """Real time: keep a setpoint, in arrival order."""
        recent = self._recent
        recent.append((ns, values))
        if len(recent) > _RECENT_MAX:
            del recent[:_RECENT_MAX // 2]

    def keep(self, ns, values):
        """Lockstep: keep a setpoint for the state of its stamp."""
        stamped = self._stamped
        stamped[ns] = values
        if len(stamped) > _STAMPED_MAX:
            for key in sorted(stamped)[:_STAMPED_MAX // 2]:
                del stamped[key]

    def take(self, ns):
        """Lockstep: return the setpoint stamped ``ns`` (no longer kept), or None."""
        return self._stamped.pop(ns, None)

    def clear(self):
        """Forget the setpoints kept (time went back)."""
        self._stamped.clear()
        self._recent.clear()

    def newest(self, ns):
        """
        Return (stamp_ns, values) of the newest fresh setpoint for ns, or None.

        Fresh: stamped <= ns + dt/2 and not older than stale_timeout.
        """
        recent = self._recent
        limit = ns + self._half_ns
        while len(recent) > 1 and recent[1][0] <= limit:
            del recent[0]
        if not recent or recent[0][0] > limit:
            return None
        found = recent[0]
        if (ns - found[0]) * 1e-9 > self._stale_timeout:
            return None
        return found

    def planned(self, ns, sp, lockstep):
        """
        Return the plan's position for the state stamped ``ns`` (``position_planned``).

        The setpoint ``sp`` used, as streamed; else (real time) the newest fresh one; else ().
        """
        if sp is None:
            if lockstep:
                return ()
            found = self.newest(ns)
            if found is None:
                return ()
            sp = found[1]
        return sp[0:self._m]

    def spare_waits_for(self, matched, listed, mono, now_ns, name):
        """
        Return what a spare still lacks of this stream ('' : nothing).

        Every publisher the graph lists (``listed``) matched (``matched``) and, with one,
        the stream caught up: the newest setpoint within the carry-forward time of
        ``now_ns`` [ns], or none for STANDBY_IDLE_STREAM s (a planner not streaming).
        ``name``: the topic's, for the text.
        """
        if matched < listed:
            return '%s: %d of its %d publishers matched' % (name, matched, listed)
        if matched == 0:
            return ''
        if self._matched_wall is None:
            self._matched_wall = mono
        last = self._wall if self._wall is not None else self._matched_wall
        if mono - last > STANDBY_IDLE_STREAM:
            return ''
        if not self._recent:
            return 'the setpoint stream matched, no setpoint received yet'
        behind = (now_ns - self._recent[-1][0]) * 1e-9
        if behind * 1e9 > self._carry_ns:
            return 'the setpoint stream catching up (newest %.3f s old)' % behind
        return ''
