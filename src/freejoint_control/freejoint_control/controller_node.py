"""
Controller node: the robust Cartesian controller of freejoint_core as a ROS 2 node.

Subscribes ``joint_states`` (sensor_msgs/JointState, joints matched by name, any order,
extra joints ignored) and ``setpoint`` (freejoint_msgs/CartesianSetpoint); per state it
publishes the active joint efforts on ``effort_controller/commands``
(std_msgs/Float64MultiArray in the order of parameter ``joints``, the topic of
ros2_control's JointGroupEffortController) and a ``controller_state``
(freejoint_msgs/ControllerState).  The law itself is ``RobustController.step``; this
node only converts messages, pairs states with setpoints and guards its inputs
(docs/GRAPH.md: lockstep protocol, staleness, parameters).

"""

import math
import time

from freejoint_common.node_tools import declare, plain, request_scheduling, run
from freejoint_common.node_tools import scheduling_refusal, Throttle
from freejoint_control.params import build_config, SPECS
from freejoint_core.control import (RobustController, STATUS_BAD_INPUT, STATUS_NEAR_SINGULAR,
                                    STATUS_STALE_SETPOINT, STATUS_STALE_STATE,
                                    STATUS_TORQUE_LIMITED)
from freejoint_core.errors import FreejointValueError
from freejoint_msgs.msg import CartesianSetpoint, ControllerState
from rcl_interfaces.msg import SetParametersResult
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

QUEUE_DEPTH = 1000
"""Keep-last depth of the run's streams: 1 s at 1 kHz, so a recorder that stalls
for less than that loses nothing (docs/GRAPH.md)."""
QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=QUEUE_DEPTH,
                 reliability=ReliabilityPolicy.RELIABLE)
"""QoS of joint_states, commands and controller_state (docs/GRAPH.md)."""
SETPOINT_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=QUEUE_DEPTH,
                          reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""QoS of setpoint: transient local, so a controller started after the planner still gets
the ticks streamed ahead while the simulator waited for its first command (GRAPH.md)."""

_isfinite = math.isfinite
_monotonic = time.monotonic
_NAME_MAP_CACHE = 16


class ControllerNode(Node):
    """The robust controller between JointState/CartesianSetpoint and effort commands."""

    def __init__(self, **kwargs):
        super().__init__('controller_node', **kwargs)
        self._values = declare(self, SPECS)
        self.config = build_config(self._values)   # raises: bad start-up parameters
        request_scheduling(self, self._values, at_start=True)
        cfg = self.config
        self._ctl = RobustController(cfg.nominal, cfg.gains)
        self._install(cfg)
        self.add_on_set_parameters_callback(self._on_set_parameters)

        self._cmd = Float64MultiArray()
        self._cmd.layout.dim = [MultiArrayDimension(label='stamp_ns=0', size=len(cfg.joints),
                                                    stride=len(cfg.joints))]
        self._dim = self._cmd.layout.dim[0]
        self._state = ControllerState()
        self._state.joint_names = list(cfg.joints)
        self._zero = [0.0] * len(cfg.joints)

        self._last_ns = -1            # stamp of the last answered state
        self._pending = None          # lockstep: (ns, stamp, q, qd, since) waiting for a setpoint
        self._setpoints = {}          # lockstep: stamp_ns -> (px, py, vx, vy, ax, ay)
        self._recent = []             # real time: [(stamp_ns, values)], in arrival order
        self._setpoint_seen = False
        self._last_sp = (0.0, 0.0)
        self._last_state_wall = None
        self._stale_reported = False
        self._last_q = None
        self._last_det = 0.0
        self._name_maps = {}
        self._map_names = None
        self._map = None
        self._ticks = 0
        self._zero_answers = 0
        self._throttle = Throttle(1.0)

        self._pub_cmd = self.create_publisher(Float64MultiArray, 'effort_controller/commands',
                                              QOS)
        self._pub_state = self.create_publisher(ControllerState, 'controller_state', QOS)
        self.create_subscription(JointState, 'joint_states', self._on_joint_state, QOS)
        self.create_subscription(CartesianSetpoint, 'setpoint', self._on_setpoint, SETPOINT_QOS)
        period = min(0.05, cfg.stale_timeout / 4.0)
        self.create_timer(period, self._watchdog, clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.get_logger().info(
            'controller ready: %s, nominal scale %g, %s, joints %s, dt %g s, robust %s' % (
                self._values['case'], self._values['nominal_scale'],
                'lockstep' if cfg.lockstep else 'real time', list(cfg.joints), cfg.dt,
                cfg.gains.robust))

    # -- parameters ------------------------------------------------------------
    def _install(self, cfg):
        """Cache what the tick needs from a validated configuration."""
        self.config = cfg
        self._dt = cfg.dt
        self._half_ns = cfg.dt_ns // 2
        self._stale = cfg.stale_timeout
        self._lockstep = cfg.lockstep
        self._identity = cfg.cmd_index == tuple(range(len(cfg.cmd_index)))

    def _on_set_parameters(self, params):
        values = dict(self._values)
        for param in params:
            if param.name in values:
                values[param.name] = plain(param.value)
        try:
            cfg = build_config(values)
        except FreejointValueError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        reason = scheduling_refusal(self, params, values)
        if reason is not None:
            return SetParametersResult(successful=False, reason=reason)
        old = self.config
        if cfg.nominal != old.nominal:
            self._ctl.set_nominal(cfg.nominal)
        if cfg.gains != old.gains:
            self._ctl.set_gains(cfg.gains)
            if cfg.gains.theta0 != old.gains.theta0:
                self._ctl.reset()
        self._install(cfg)
        self._values = values
        changed = ', '.join('%s=%s' % (p.name, plain(p.value)) for p in params)
        self.get_logger().info('parameters set (effective next tick): ' + changed)
        return SetParametersResult(successful=True)

    # -- inputs ----------------------------------------------------------------
    def _joint_map(self, names):
        """Map a JointState name list to the model joints' indices (cached per list)."""
        key = tuple(names)
        found = self._name_maps.get(key)
        if found is None:
            want = self.config.joint_names
            missing = [n for n in want if n not in key]
            if missing:
                found = (None, 'JointState lacks joint(s) %s (has %s)' % (missing, list(key)),
                         'missing')
            else:
                found = (tuple(key.index(n) for n in want), '', '')
            if len(self._name_maps) >= _NAME_MAP_CACHE:
                self._name_maps.clear()
            self._name_maps[key] = found
        self._map_names = names
        self._map = found
        return found

    def _on_joint_state(self, msg):
        stamp = msg.header.stamp
        ns = stamp.sec * 1_000_000_000 + stamp.nanosec
        self._last_state_wall = _monotonic()
        self._stale_reported = False
        if ns == self._last_ns:
            # A repeated state (the sim's start-up republication): same answer, no new update.
            self._pub_cmd.publish(self._cmd)
            self._pub_state.publish(self._state)
            return
        if ns < self._last_ns:
            self.get_logger().warn(
                'state time went back from %d to %d ns (simulator restarted?): theta_hat '
                'reset to theta0' % (self._last_ns, ns))
            self._ctl.reset()
            self._setpoints.clear()
            self._recent.clear()
        names = msg.name
        found = self._map if names == self._map_names else self._joint_map(names)
        idx, reason, kind = found
        if idx is not None:
            pos = msg.position
            vel = msg.velocity
            try:
                i0, i1, i2 = idx
                q = (pos[i0], pos[i1], pos[i2])
                qd = (vel[i0], vel[i1], vel[i2])
            except (IndexError, ValueError):
                q = None
                kind = 'short'
                reason = 'JointState has %d names but %d positions and %d velocities' % (
                    len(names), len(pos), len(vel))
            if q is not None and not (_isfinite(q[0]) and _isfinite(q[1]) and _isfinite(q[2])
                                      and _isfinite(qd[0]) and _isfinite(qd[1])
                                      and _isfinite(qd[2])):
                kind = 'nonfinite'
                reason = 'JointState has a non-finite position or velocity: q=%s qd=%s' % (
                    list(q), list(qd))
                q = None
        else:
            q = None
        if q is None:
            self._throttle(self.get_logger().error, kind,
                           'state refused: %s; zero effort' % reason)
            self._answer_zero(ns, stamp, STATUS_BAD_INPUT, 'bad input: ' + reason)
            return
        self._last_q = q
        if self._lockstep:
            sp = self._setpoints.pop(ns, None)
            if sp is None:
                self._pending = (ns, stamp, q, qd, _monotonic())
                return
            self._pending = None
            self._tick(ns, stamp, q, qd, sp)
        else:
            sp = self._realtime_setpoint(ns)
            if sp is None:
                self._answer_zero(ns, stamp, STATUS_STALE_SETPOINT,
                                  'stale setpoint: none stamped within %g s before the state'
                                  % self._stale)
                self._throttle(self.get_logger().warn, 'stale_setpoint',
                               'no fresh setpoint: zero effort')
                return
            self._tick(ns, stamp, q, qd, sp)

    def _realtime_setpoint(self, ns):
        """Newest setpoint stamped <= ns + dt/2 and not older than stale_timeout, or None."""
        recent = self._recent
        limit = ns + self._half_ns
        while len(recent) > 1 and recent[1][0] <= limit:
            del recent[0]
        if not recent or recent[0][0] > limit:
            return None
        sp_ns, values = recent[0]
        if (ns - sp_ns) * 1e-9 > self._stale:
            return None
        return values

    def _on_setpoint(self, msg):
        stamp = msg.header.stamp
        ns = stamp.sec * 1_000_000_000 + stamp.nanosec
        p = msg.position
        v = msg.velocity
        a = msg.acceleration
        values = (p[0], p[1], v[0], v[1], a[0], a[1])
        for x in values:
            if not _isfinite(x):
                self._throttle(
                    self.get_logger().error, 'setpoint',
                    'setpoint refused: non-finite value in position %s, velocity %s, '
                    'acceleration %s' % (list(p), list(v), list(a)))
                return
        self._setpoint_seen = True
        if not self._lockstep:
            recent = self._recent
            recent.append((ns, values))
            if len(recent) > 1000:
                del recent[:500]
            return
        pending = self._pending
        if pending is not None and pending[0] == ns:
            self._pending = None
            self._tick(ns, pending[1], pending[2], pending[3], values)
        elif ns > self._last_ns:
            setpoints = self._setpoints
            setpoints[ns] = values
            if len(setpoints) > 10000:
                for key in sorted(setpoints)[:5000]:
                    del setpoints[key]

    # -- outputs ---------------------------------------------------------------
    def _tick(self, ns, stamp, q, qd, sp):
        px, py, vx, vy, ax, ay = sp
        out = self._ctl.step(q, qd, (px, py), (vx, vy), (ax, ay), self._dt)
        tau = out.tau.tolist()
        effort = tau if self._identity else [tau[i] for i in self.config.cmd_index]
        cmd = self._cmd
        cmd.data = effort
        self._dim.label = 'stamp_ns=%d' % ns
        self._pub_cmd.publish(cmd)
        st = self._state
        st.header.stamp = stamp
        st.error = out.e
        st.error_rate = out.edot
        st.sliding = out.s
        st.theta_hat = out.theta
        st.rho_hat = out.rho
        st.delta_v = out.dv
        st.effort = effort
        st.det_dd = out.det
        st.position = out.p
        st.position_desired = (px, py)
        status = out.status
        st.status = status
        st.message = _status_message(status, out.det, self._values) if status else ''
        self._pub_state.publish(st)
        self._last_ns = ns
        self._last_sp = (px, py)
        self._last_det = out.det
        self._ticks += 1

    def _answer_zero(self, ns, stamp, status, message):
        """Command zero effort for the state stamped ns; say why in the state message."""
        cmd = self._cmd
        cmd.data = self._zero
        self._dim.label = 'stamp_ns=%d' % ns
        self._pub_cmd.publish(cmd)
        st = self._state
        st.header.stamp = stamp
        zero2 = (0.0, 0.0)
        st.error = zero2
        st.error_rate = zero2
        st.sliding = zero2
        st.theta_hat = self._ctl.theta
        st.rho_hat = 0.0
        st.delta_v = zero2
        st.effort = self._zero
        st.det_dd = self._last_det
        q = self._last_q
        st.position = self._ctl.model.fk(q) if q is not None else self._last_sp
        st.position_desired = self._last_sp
        st.status = status
        st.message = message
        self._pub_state.publish(st)
        self._last_ns = ns
        self._zero_answers += 1

    def _watchdog(self):
        """Wall-clock staleness: a held lockstep state without setpoint, or no state."""
        now = _monotonic()
        pending = self._pending
        if pending is not None:
            if self._setpoint_seen and now - pending[4] > self._stale:
                self._pending = None
                self._throttle(
                    self.get_logger().warn, 'stale_setpoint',
                    'no setpoint for the state stamped %d ns within %g s: zero effort'
                    % (pending[0], self._stale))
                self._answer_zero(pending[0], pending[1], STATUS_STALE_SETPOINT,
                                  'stale setpoint: none for this stamp within %g s'
                                  % self._stale)
            return
        last = self._last_state_wall
        if last is not None and not self._stale_reported and now - last > self._stale:
            self._stale_reported = True
            self.get_logger().warn('no joint_states for %g s: zero effort' % self._stale)
            stamp = self._state.header.stamp
            self._answer_zero(self._last_ns, stamp, STATUS_STALE_STATE,
                              'stale state: no joint_states within %g s' % self._stale)

    def report(self):
        """One line for the end of the run: ticks computed, zero-effort answers."""
        return 'controller stopped: %d ticks computed, %d zero-effort answers (stale or bad ' \
            'input)' % (self._ticks, self._zero_answers)


def _status_message(status, det, values):
    parts = []
    if status & STATUS_NEAR_SINGULAR:
        parts.append('near singular: |det(Da Da^T)| = %.3g < %.3g, damped pseudo-inverse'
                     % (det, values['det_threshold']))
    if status & STATUS_TORQUE_LIMITED:
        parts.append('torque limited to %g N m' % values['tau_limit'])
    return '; '.join(parts)


def main(args=None):
    """Run the node until SIGINT/SIGTERM."""
    run(ControllerNode, 'controller_node', args,
        lambda node: node.get_logger().info(node.report()))


if __name__ == '__main__':
    main()
