"""Topic names, message types and QoS of a run (ROS-free constants, one place).

Names are relative, so a namespace (``--ros-args -r __ns:=/robot1``) moves a whole
system; ``/clock`` is global by ROS convention.
"""
from __future__ import annotations

CLOCK = '/clock'
ODOM = 'odom'
POSE = 'pose'
REF_POSE = 'reference/pose'
REF_TWIST = 'reference/twist'
REF_ACCEL = 'reference/accel'
CMD_VEL = 'cmd_vel'
RUN_DONE = 'run_done'

#: topic -> ROS 2 message type, for every topic a run records.
TYPES: dict[str, str] = {
    CLOCK: 'rosgraph_msgs/msg/Clock',
    ODOM: 'nav_msgs/msg/Odometry',
    POSE: 'geometry_msgs/msg/PoseStamped',
    REF_POSE: 'geometry_msgs/msg/PoseStamped',
    REF_TWIST: 'geometry_msgs/msg/TwistStamped',
    REF_ACCEL: 'geometry_msgs/msg/AccelStamped',
    CMD_VEL: 'geometry_msgs/msg/Twist',
    RUN_DONE: 'std_msgs/msg/UInt64',
}

#: The topics a tracking run's analysis reads (bag reader, golden bags): pose, reference,
#: command.  ``/clock`` and ``pose`` repeat ``odom``'s stamps and pose.
RUN_TOPICS: tuple[str, ...] = (ODOM, REF_POSE, REF_TWIST, REF_ACCEL, CMD_VEL)
#: Topics whose S+1 samples the recorder waits for after ``run_done`` = S (lockstep).
LOCKSTEP_TOPICS: tuple[str, ...] = (ODOM, POSE, REF_POSE, REF_TWIST, REF_ACCEL, CMD_VEL)

#: QoS of the data topics: reliable, volatile, keep last DEPTH.
DEPTH = 100
#: Frames (REP-105): poses and references in ``odom``; the robot body is ``base_link``.
ODOM_FRAME = 'odom'
BASE_FRAME = 'base_link'
