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

from dataclasses import dataclass

from geometry_msgs.msg import AccelStamped, PoseStamped, TwistStamped
from rclpy.parameter import Parameter
from rosgraph_msgs.msg import Clock

from .. import topics
from ..control.reference import Path, make_path
from .common import (DATA_QOS, AdapterNode, Param, StartupError, check_mode, fill_reference,
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


@dataclass(frozen=True)
class ReferenceSettings:
    """The reference node's validated parameters (see :data:`PARAMS`)."""

    mode: str
    path: Path
    publish_rate: float


def reference_settings(values: dict) -> ReferenceSettings:
    """Validate the reference's parameter values; InputError (e.g. PathError) if bad."""
    mode = check_mode(values['mode'])
    center = list(values['center'])
    if len(center) != 2:
        raise StartupError(f'center needs [x, y], got {center}')
    path = make_path(values['path'], radius=values['radius'], rate=values['rate'],
                     center_x=center[0], center_y=center[1], phase=values['phase'])
    return ReferenceSettings(mode=mode, path=path, publish_rate=values['publish_rate'])


class ReferenceNode(AdapterNode):
    """ROS adapter around :class:`control.reference.Path`."""

    def __init__(self, node_name: str = 'reference', **node_kwargs):
        super().__init__(node_name, **node_kwargs)
        self.config = self.bind_parameters(PARAMS, reference_settings)
        self.mode = self.config.mode
        self.path = self.config.path
        self.pub_pose = self.create_publisher(PoseStamped, topics.REF_POSE, DATA_QOS)
        self.pub_twist = self.create_publisher(TwistStamped, topics.REF_TWIST, DATA_QOS)
        self.pub_accel = self.create_publisher(AccelStamped, topics.REF_ACCEL, DATA_QOS)
        self._msgs = (PoseStamped(), TwistStamped(), AccelStamped())
        for m in self._msgs:
            m.header.frame_id = topics.ODOM_FRAME
        if self.mode == 'lockstep':
            self.set_parameters([Parameter('use_sim_time', value=True)])
            self.sub_clock = self.create_subscription(Clock, topics.CLOCK, self._on_clock,
                                                      DATA_QOS)
        else:
            self.t0_ns = self.get_clock().now().nanoseconds   # path time 0 = node start
            self.timer = self.create_timer(1.0 / self.config.publish_rate, self._on_timer)

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
