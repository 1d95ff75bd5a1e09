"""``tracker``: the non-fragile tracking law with K from parameters.

Subscribes ``odom`` (nav_msgs/Odometry; its twist.linear.x initialises the
compensator speed), ``reference/pose``, ``reference/twist``, ``reference/accel``;
publishes ``cmd_vel`` (geometry_msgs/Twist).  The law is
:class:`control.loop.Tracker`; the gain check is :func:`control.gains.gain_from_parameters`.

Lockstep: a command is computed once per stamp, when the pose and the three
reference parts with that stamp have all arrived (repeats are ignored).  Real
time: a command per pose with the latest reference; if pose or reference is
older than ``input_timeout`` the tracker publishes a stop (zero Twist), says so
once, and re-initialises its compensator when fresh data returns.

Bad samples (non-finite values, non-unit quaternions, wrong frame, stamps that
go backwards) are ignored and counted in ``rejected``; an odom stamp that jumps
ahead by more than ``max_stamp_jump`` re-initialises the compensator (``jumps``).
"""
from __future__ import annotations

import math

import numpy as np
from geometry_msgs.msg import AccelStamped, PoseStamped, Twist, TwistStamped
from nav_msgs.msg import Odometry
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter

from .. import topics
from ..control.loop import LoopConfigError, Tracker
from ..msgconv import tracker_config
from .common import (DATA_QOS, PAPER_A_TAU, Param, StartupError, check_mode, declare, get,
                     pose_from_odom, reference_from_msgs, run, stamp_ns)

PAPER_F = [0.5] * 8
PARAMS = [
    Param('mode', 'lockstep', 'lockstep (one command per stamp, sim time) or realtime',
          read_only=True),
    Param('K_shape', [2, 4], 'shape [rows, cols] of K', read_only=True),
    Param('dt', 0.01, 'step of the compensator v\' = a (s); equals the plant step', low=1e-6,
          high=10.0, read_only=True),
    Param('max_linear_speed', 1.0, 'limit on |cmd_vel.linear.x| (m/s)', low=1e-9, high=1e3),
    Param('max_angular_speed', 2.0, 'limit on |cmd_vel.angular.z| (rad/s)', low=1e-9, high=1e3),
    Param('min_speed', 1e-3, 'floor on |v| in w = (...)/v near the v = 0 singularity (m/s)',
          low=1e-9, high=1e3),
    Param('E', [1.0, 0.0, 0.0, 1.0], 'perturbation matrix E (2x2 row-major)'),
    Param('F', PAPER_F, 'perturbation matrix F (2x4 row-major)'),
    Param('Delta', [0.0, 0.0, 0.0, 0.0], 'injected gain perturbation Delta (2x2 row-major); '
          'the applied gain is K + E Delta F'),
    Param('delay_compensation', False, 'follow the delay-consistent reference (zero '
          'steady-state error); needs A_tau and tau', read_only=True),
    Param('A_tau', PAPER_A_TAU, 'delay matrix for delay_compensation (16 doubles)',
          read_only=True),
    Param('tau', 0.2, 'delay for delay_compensation (s)', low=0.0, high=1e3, read_only=True),
    Param('input_timeout', 0.5, 'realtime: stop if pose or reference is older than this (s)',
          low=1e-6, high=1e6),
    Param('max_stamp_jump', 1.0, 'an odom stamp further ahead than this (s) is a jump: the '
          'compensator is re-initialised from the measured speed', low=1e-6, high=1e9),
]
RUNTIME = {'K', 'max_linear_speed', 'max_angular_speed', 'min_speed', 'E', 'F', 'Delta',
           'input_timeout', 'max_stamp_jump'}


class TrackerNode(Node):
    """ROS adapter around :class:`control.loop.Tracker`."""

    def __init__(self, **kwargs):
        super().__init__('tracker', **kwargs)
        from rcl_interfaces.msg import ParameterDescriptor
        self.declare_parameter('K', Parameter.Type.DOUBLE_ARRAY, ParameterDescriptor(
            description='gain K, row-major doubles (see K_shape); from a gain file written '
                        'by `nonfragile_tracker synthesize`'))
        declare(self, PARAMS)
        self.mode = check_mode(get(self, 'mode'), 'tracker')
        try:
            k_value = self.get_parameter('K').value
        except Exception:  # noqa: BLE001 - ParameterUninitializedException
            k_value = None
        if k_value is None:
            raise StartupError('tracker: parameter K is not set; pass a gain file, e.g. '
                               '--ros-args --params-file config/tracker_gains.yaml')
        try:
            self.tracker = Tracker(tracker_config(self._values()))
        except LoopConfigError as exc:
            raise StartupError(f'tracker: {exc}') from None
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.pub_cmd = self.create_publisher(Twist, topics.CMD_VEL, DATA_QOS)
        self.create_subscription(Odometry, topics.ODOM, self._on_odom, DATA_QOS)
        self.create_subscription(PoseStamped, topics.REF_POSE, self._on_ref_pose, DATA_QOS)
        self.create_subscription(TwistStamped, topics.REF_TWIST, self._on_ref_twist, DATA_QOS)
        self.create_subscription(AccelStamped, topics.REF_ACCEL, self._on_ref_accel, DATA_QOS)
        if self.mode == 'lockstep':
            self.set_parameters([Parameter('use_sim_time', value=True)])
        self._odom: Odometry | None = None
        self._ref = [None, None, None]
        self.last_stamp = -1
        self.last_odom_stamp = -1
        self.rejected = 0
        self.jumps = 0
        self.commands = 0
        self.finished = False
        self._cmd = Twist()
        self._stopped = False
        if self.mode == 'realtime':
            self._last_odom_wall = self._last_ref_wall = None
            self.create_timer(0.05, self._watchdog)

    # ------------------------------------------------------------------ parameters
    def _values(self, overrides: dict | None = None) -> dict:
        names = ['K', 'K_shape'] + [p.name for p in PARAMS]
        vals = {n: self.get_parameter(n).value for n in names}
        vals.update(overrides or {})
        return vals

    def _on_set_parameters(self, params: list[Parameter]) -> SetParametersResult:
        changes = {p.name: p.value for p in params if p.name in RUNTIME}
        if not changes:
            return SetParametersResult(successful=True)
        for p in params:
            if p.name in ('K', 'E', 'F', 'Delta') and p.type_ != Parameter.Type.DOUBLE_ARRAY:
                reason = (f'{p.name} must be a DOUBLE_ARRAY (write 1.0, not 1), got '
                          f'{p.type_.name}; keeping the old value')
                self.get_logger().error(f'rejected parameter set: {reason}')
                return SetParametersResult(successful=False, reason=reason)
        try:
            cfg = tracker_config(self._values(changes))
        except LoopConfigError as exc:
            reason = f'{exc}; keeping the old value'
            self.get_logger().error(f'rejected parameter set: {reason}')
            return SetParametersResult(successful=False, reason=reason)
        self.tracker.config = cfg
        self.get_logger().info(f'accepted parameter set: {sorted(changes)}')
        return SetParametersResult(successful=True)

    # ------------------------------------------------------------------ inputs
    def _reject(self, what: str) -> None:
        self.rejected += 1
        if self.rejected <= 10 or self.rejected % 1000 == 0:
            self.get_logger().warn(f'ignored {what} (rejected so far: {self.rejected})')

    def _on_odom(self, msg: Odometry) -> None:
        if msg.header.frame_id != topics.ODOM_FRAME:
            return self._reject(f'odom in frame {msg.header.frame_id!r} (expected '
                                f'{topics.ODOM_FRAME!r})')
        s = stamp_ns(msg.header.stamp)
        if s <= self.last_odom_stamp:
            if s < self.last_odom_stamp:
                self._reject(f'odom stamp going backwards ({s} < {self.last_odom_stamp} ns)')
            return                         # repeat of the current step: already handled
        jump = s - self.last_odom_stamp
        if self.last_odom_stamp >= 0 and jump > get(self, 'max_stamp_jump') * 1e9:
            self.jumps += 1
            self.get_logger().warn(f'odom stamp jumped {jump * 1e-9:.3f} s '
                                   'ahead: re-initialising the compensator from odom')
            self.tracker.reset()
        self._odom = msg
        self.last_odom_stamp = s
        if self.mode == 'realtime':
            self._last_odom_wall = self.get_clock().now().nanoseconds
        self._try_compute()

    def _on_ref(self, i: int, msg) -> None:
        if msg.header.frame_id != topics.ODOM_FRAME:
            return self._reject(f'reference in frame {msg.header.frame_id!r}')
        self._ref[i] = msg
        if self.mode == 'realtime':
            self._last_ref_wall = self.get_clock().now().nanoseconds
        else:
            self._try_compute()

    def _on_ref_pose(self, msg):
        self._on_ref(0, msg)

    def _on_ref_twist(self, msg):
        self._on_ref(1, msg)

    def _on_ref_accel(self, msg):
        self._on_ref(2, msg)

    # ------------------------------------------------------------------ law
    def _try_compute(self) -> None:
        odom = self._odom
        if odom is None or any(r is None for r in self._ref):
            return
        if self.mode == 'realtime' and self._stopped:
            return                         # the watchdog publishes the stop
        s = stamp_ns(odom.header.stamp)
        if self.mode == 'lockstep':
            if s <= self.last_stamp or any(stamp_ns(r.header.stamp) != s for r in self._ref):
                return
        pose = pose_from_odom(odom.pose.pose)
        if isinstance(pose, str):
            self._odom = None
            return self._reject(f'odom: {pose}')
        t_ref = stamp_ns(self._ref[0].header.stamp) * 1e-9
        ref = reference_from_msgs(t_ref, *self._ref)
        if isinstance(ref, str):
            return self._reject(ref)
        self.last_stamp = s
        speed = odom.twist.twist.linear.x
        cmd = self.tracker.step(pose[0], pose[1], pose[2], ref,
                                measured_speed=speed if math.isfinite(speed) else 0.0)
        self._publish(cmd.v, cmd.w)

    def _publish(self, v: float, w: float) -> None:
        c = self.tracker.config
        if not (math.isfinite(v) and math.isfinite(w)):     # never reached by the law
            v = w = 0.0
        self._cmd.linear.x = max(-c.max_linear_speed, min(c.max_linear_speed, v))
        self._cmd.angular.z = max(-c.max_angular_speed, min(c.max_angular_speed, w))
        self.pub_cmd.publish(self._cmd)
        self.commands += 1

    def _watchdog(self) -> None:
        if self._last_odom_wall is None or self._last_ref_wall is None:
            return                          # not started yet: nothing has been commanded
        now = self.get_clock().now().nanoseconds
        limit = get(self, 'input_timeout') * 1e9
        stale = [name for name, t in (('odom', self._last_odom_wall),
                                      ('reference', self._last_ref_wall))
                 if now - t > limit]
        if stale:
            if not self._stopped:
                self.get_logger().warn(f'no {" or ".join(stale)} for more than '
                                       f'{get(self, "input_timeout")} s: publishing stop')
                self._stopped = True
                self.tracker.reset()
            self._publish(0.0, 0.0)
        elif not stale and self._stopped:
            self.get_logger().info('inputs fresh again: resuming')
            self._stopped = False


def main(args=None) -> int:
    return run(TrackerNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
