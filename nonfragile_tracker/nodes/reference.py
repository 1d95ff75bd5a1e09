"""``reference``: publishes the desired trajectory with its feedforward.

Publishes, all in frame ``odom`` and stamped with the sample time:
``reference/pose`` (geometry_msgs/PoseStamped: position and tangent heading),
``reference/twist`` (geometry_msgs/TwistStamped: linear = desired velocity in
``odom``) and ``reference/accel`` (geometry_msgs/AccelStamped: linear = desired
acceleration in ``odom``).  Lockstep: one sample per ``/clock`` message, at the
clock's time.  Real time: a wall timer at ``publish_rate``.  The path is
:func:`control.reference.make_path`.
"""
from __future__ import annotations

from geometry_msgs.msg import AccelStamped, PoseStamped, TwistStamped
from rclpy.node import Node
from rclpy.parameter import Parameter
from rosgraph_msgs.msg import Clock

from .. import topics
from ..control.reference import PathError, make_path
from .common import (DATA_QOS, Param, StartupError, check_mode, declare, fill_reference, get,
                     ns_to_stamp, run, stamp_ns)

PARAMS = [
    Param('mode', 'lockstep', 'lockstep (one sample per /clock) or realtime (wall timer)',
          read_only=True),
    Param('path', 'circle', 'path name: circle or figure_eight', read_only=True),
    Param('radius', 0.5, 'path radius / half width (m)', low=1e-9, high=1e6, read_only=True),
    Param('rate', 0.01, 'angular rate of the path parameter (rad/s)', read_only=True),
    Param('center', [0.0, 0.0], 'path centre [x, y] in odom (m)', read_only=True),
    Param('phase', 0.0, 'phase of the path parameter at t = 0 (rad)', read_only=True),
    Param('publish_rate', 100.0, 'realtime: samples per second (Hz)', low=1e-3, high=1e5,
          read_only=True),
]


class ReferenceNode(Node):
    """ROS adapter around :class:`control.reference.Path`."""

    def __init__(self, **kwargs):
        super().__init__('reference', **kwargs)
        declare(self, PARAMS)
        self.mode = check_mode(get(self, 'mode'), 'reference')
        center = list(get(self, 'center'))
        if len(center) != 2:
            raise StartupError(f'reference: center needs [x, y], got {center}')
        try:
            self.path = make_path(get(self, 'path'), radius=get(self, 'radius'),
                                  rate=get(self, 'rate'), center_x=center[0],
                                  center_y=center[1], phase=get(self, 'phase'))
        except PathError as exc:
            raise StartupError(f'reference: {exc}') from None
        self.pub_pose = self.create_publisher(PoseStamped, topics.REF_POSE, DATA_QOS)
        self.pub_twist = self.create_publisher(TwistStamped, topics.REF_TWIST, DATA_QOS)
        self.pub_accel = self.create_publisher(AccelStamped, topics.REF_ACCEL, DATA_QOS)
        self._msgs = (PoseStamped(), TwistStamped(), AccelStamped())
        for m in self._msgs:
            m.header.frame_id = topics.ODOM_FRAME
        self.finished = False
        if self.mode == 'lockstep':
            self.set_parameters([Parameter('use_sim_time', value=True)])
            self.sub_clock = self.create_subscription(Clock, topics.CLOCK, self._on_clock,
                                                      DATA_QOS)
        else:
            self.t0_ns = self.get_clock().now().nanoseconds   # path time 0 = node start
            self.timer = self.create_timer(1.0 / get(self, 'publish_rate'), self._on_timer)

    def publish_sample(self, t_ns: int, t: float) -> None:
        """Publish the sample at path time ``t`` (s) with header stamp ``t_ns``."""
        ref = self.path.sample(t)
        pose, twist, accel = self._msgs
        for m in self._msgs:
            ns_to_stamp(t_ns, m.header.stamp)
        fill_reference(ref, pose, twist, accel)
        self.pub_pose.publish(pose)
        self.pub_twist.publish(twist)
        self.pub_accel.publish(accel)

    def _on_clock(self, msg: Clock) -> None:
        t_ns = stamp_ns(msg.clock)
        self.publish_sample(t_ns, t_ns * 1e-9)

    def _on_timer(self) -> None:
        now = self.get_clock().now().nanoseconds
        self.publish_sample(now, (now - self.t0_ns) * 1e-9)


def main(args=None) -> int:
    return run(ReferenceNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
