"""Topic names, message types and QoS of a run (ROS-free constants, one place).

Names are relative, so a namespace (``--ros-args -r __ns:=/robot1``) moves a whole
system; ``/clock`` is global by ROS convention.

See doc/ros-interface.md, sections "Topics" and "Recorded topics".
"""
from __future__ import annotations

CLOCK = '/clock'
ODOM = 'odom'
POSE = 'pose'
REF_POSE = 'reference/pose'
REF_TWIST = 'reference/twist'
REF_ACCEL = 'reference/accel'
CMD_VEL = 'cmd_vel'
#: Where a tracker in a Nav2 system publishes (remapped from ``cmd_vel``): Nav2's
#: ``collision_monitor`` (or ``velocity_smoother``) reads it and publishes ``cmd_vel``.
CMD_VEL_NAV = 'cmd_vel_nav'
#: Nav2's planner_server's plan (nav_msgs/Path without timing, republished as it replans):
#: what a tracker in a Nav2 system follows (``trajectory`` remapped to it).
NAV2_PLAN = 'plan'
RUN_DONE = 'run_done'
#: The trajectory to follow (nav_msgs/Path, transient-local): reference -> tracker.
TRAJECTORY = 'trajectory'
#: The same as trajectory_msgs/MultiDOFJointTrajectory (pose, velocity, acceleration).
TRAJECTORY_MULTIDOF = 'trajectory_multidof'
#: The trajectory the tracker follows, as it follows it (MultiDOFJointTrajectory,
#: transient-local): re-timed within the limits and re-based to its start, stamped with
#: its start; published when the tracker starts following it (bag report, replay).
FOLLOWED_TRAJECTORY = 'tracker/trajectory'
#: The tracker's online tuning (``monitor_tune``; geometry_msgs/Vector3Stamped,
#: transient-local, depth 1): at each retune the latency, lag of v and lag of w it predicts
#: from then on (x, y, z, s), stamped with the odometry stamp of the step it took effect
#: at.  A replay applies them (``tuning_schedule``): a recording that joined a running
#: tracker has not seen the data they were estimated from.
TUNING = 'tracker/tuning'
#: The reference for display (nav_msgs/Path, transient-local), any source.
REF_PATH = 'reference/path'
#: What the robot drove (nav_msgs/Path), the tracking error, the reference point marker.
TRAVELLED_PATH = 'tracker/path'
TRACKING_ERROR = 'tracker/error'
REF_MARKER = 'tracker/reference_marker'
DIAGNOSTICS = '/diagnostics'
#: The tracker's certificate monitor (diagnostic_msgs/DiagnosticArray, one status: latency
#: estimate, certified interval, level), published with each /diagnostics report.
CERTIFICATE = 'tracker/certificate'
#: The recorder's lockstep readiness (std_msgs/UInt64, transient-local): published once
#: every recorded lockstep topic's subscription has matched its publisher; the plant
#: (``lockstep_recorder``) starts the run only after it.  Not recorded.
RECORDER_READY = 'recorder/ready'
#: The recorder's progress (std_msgs/UInt64, reliable, volatile): the stamp (ns) up to which
#: every recorded per-step topic has arrived; a plant with ``lockstep_recorder`` runs at
#: most ``lockstep_lead`` steps ahead of it (no sample lost to a full queue).  Not recorded.
RECORDER_PROGRESS = 'recorder/progress'
#: How many odometry messages (distinct stamps) a lockstep plant published in its run
#: (std_msgs/UInt64, transient-local), sent before ``run_done``: with odom_rate or
#: odom_latency there are fewer than steps, and each gets one ``cmd_vel``.  Not recorded.
ODOM_COUNT = 'run_done/odom_count'

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
    TRAJECTORY: 'nav_msgs/msg/Path',
    TRAJECTORY_MULTIDOF: 'trajectory_msgs/msg/MultiDOFJointTrajectory',
    REF_PATH: 'nav_msgs/msg/Path',
    FOLLOWED_TRAJECTORY: 'trajectory_msgs/msg/MultiDOFJointTrajectory',
    TUNING: 'geometry_msgs/msg/Vector3Stamped',
}

#: A lean lockstep recording (the default of ``nonfragile_tracker run`` and the launch
#: file in lockstep): per step only ``odom`` and ``cmd_vel``; the reference is kept as the
#: trajectory message(s) the tracker follows, and the bag reader samples it at each
#: odometry stamp as the tracker does.  ``/clock``, ``pose`` and the per-step reference
#: samples are left out (``--record-all`` / ``record_all:=true`` records :data:`TYPES`).
LEAN_TOPICS: tuple[str, ...] = (ODOM, CMD_VEL, RUN_DONE, TRAJECTORY, TRAJECTORY_MULTIDOF,
                                REF_PATH, FOLLOWED_TRAJECTORY, TUNING)

#: The topics a tracking run's analysis reads (bag reader, golden bags): pose, reference,
#: command.  ``/clock`` and ``pose`` repeat ``odom``'s stamps and pose.
RUN_TOPICS: tuple[str, ...] = (ODOM, REF_POSE, REF_TWIST, REF_ACCEL, CMD_VEL)
#: Topics whose S+1 samples the recorder waits for after ``run_done`` = S (lockstep).
LOCKSTEP_TOPICS: tuple[str, ...] = (ODOM, POSE, REF_POSE, REF_TWIST, REF_ACCEL, CMD_VEL)
#: cmd_vel's type with ``enable_stamped_cmd_vel`` (Nav2 name; Jazzy diff_drive_controller).
CMD_VEL_STAMPED_TYPE = 'geometry_msgs/msg/TwistStamped'

#: QoS of the data topics: reliable, volatile, keep last DEPTH.
DEPTH = 100
#: Frames (REP-105): poses and references in ``odom``; the robot body is ``base_link``.
ODOM_FRAME = 'odom'
BASE_FRAME = 'base_link'
