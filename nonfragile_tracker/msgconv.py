"""ROS-free conversions between messages and the control types, and tracker parameters.

Duck-typed: the functions read attributes, so they take rclpy messages (nodes) and
rosbags' deserialized messages (bag replay) alike - one meaning, one place.
:func:`tracker_config` maps the tracker node's parameter values to
:class:`~nonfragile_tracker.control.simulation.loop.TrackerConfig` for the node and for replay.
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, Protocol

import numpy as np

from .control.simulation.gains import gain_from_parameters
from .control.simulation.loop import (LoopConfigError, TrackerConfig, quaternion_to_yaw,
                                      yaw_to_quaternion)
from .control.simulation.reference import RefSample
from .control.simulation.trajectory import (Trajectory, TrajectoryError, check_frame, from_poses,
                                            from_states, from_waypoints)
from .control.validate import as_matrix

__all__ = ['stamp_ns', 'ns_to_stamp', 'fill_pose', 'pose_from_odom', 'fill_reference',
           'reference_from_msgs', 'path_to_trajectory', 'multidof_to_trajectory',
           'PREDICT_PARAMS', 'LIMIT_PARAMS', 'tracker_config']


# The fields these functions read or write, as protocols: rclpy's messages and rosbags'
# deserialized ones both have them.  The whole-trajectory messages (nav_msgs/Path,
# trajectory_msgs/MultiDOFJointTrajectory) are read field by field and typed ``Any``.

class _Time(Protocol):
    """builtin_interfaces/Time or Duration."""

    sec: int
    nanosec: int


class _Vector(Protocol):
    """geometry_msgs/Point or Vector3."""

    x: float
    y: float
    z: float


class _Quaternion(_Vector, Protocol):
    """geometry_msgs/Quaternion."""

    w: float


class _Pose(Protocol):
    """geometry_msgs/Pose."""

    position: _Vector
    orientation: _Quaternion


class _PoseStamped(Protocol):
    pose: _Pose


class _Twist(Protocol):
    linear: _Vector


class _TwistStamped(Protocol):
    twist: _Twist


class _Accel(Protocol):
    linear: _Vector


class _AccelStamped(Protocol):
    accel: _Accel


def stamp_ns(stamp: _Time) -> int:
    """builtin_interfaces/Time -> integer nanoseconds.

    Parameters
    ----------
    stamp : builtin_interfaces/Time or Duration
        A message stamp.
    """
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def ns_to_stamp(ns: int, stamp: _Time) -> None:
    """Integer nanoseconds -> builtin_interfaces/Time ``stamp`` (in place).

    Parameters
    ----------
    ns : int
        Nanoseconds.
    stamp : builtin_interfaces/Time
        The message field to set.
    """
    stamp.sec, stamp.nanosec = divmod(int(ns), 1_000_000_000)


def fill_pose(pose: _Pose, x: float, y: float, th: float) -> None:
    """Fill a geometry_msgs/Pose from a planar pose (REP-103: yaw about +z).

    Parameters
    ----------
    pose : geometry_msgs/Pose
        The message field to set (in place).
    x, y : float
        Position (m).
    th : float
        Yaw (rad).
    """
    pose.position.x, pose.position.y, pose.position.z = float(x), float(y), 0.0
    q = pose.orientation
    q.x, q.y, q.z, q.w = yaw_to_quaternion(th)


def pose_from_odom(pose: _Pose) -> tuple[float, float, float] | str:
    """Planar pose from a geometry_msgs/Pose, or a reason string if it is unusable.

    On the tracker's real-time path: each field is read once (message fields are
    properties) and checked without building temporaries.

    Parameters
    ----------
    pose : geometry_msgs/Pose
        E.g. an odometry's ``pose.pose``.

    Returns
    -------
    tuple of float or str
        ``(x, y, yaw)`` (m, m, rad), or why the pose is unusable (not finite, not a unit
        quaternion).
    """
    p, q = pose.position, pose.orientation
    px, py, qx, qy, qz, qw = p.x, p.y, q.x, q.y, q.z, q.w
    isfinite = math.isfinite
    if not (isfinite(px) and isfinite(py) and isfinite(qx) and isfinite(qy)
            and isfinite(qz) and isfinite(qw)):
        return f'non-finite pose {(px, py, qx, qy, qz, qw)}'
    norm = math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw)
    if abs(norm - 1.0) > 1e-3:
        return f'quaternion norm {norm:.6g} is not 1'
    return (px, py, quaternion_to_yaw(qx, qy, qz, qw))


def fill_reference(ref: RefSample, pose_msg: _PoseStamped, twist_msg: _TwistStamped,
                   accel_msg: _AccelStamped) -> None:
    """Fill the three reference messages (pose, twist, accel) from a sample.

    Parameters
    ----------
    ref : RefSample
        The reference sample.
    pose_msg, twist_msg, accel_msg : PoseStamped, TwistStamped, AccelStamped
        The messages to fill (in place; headers untouched).
    """
    fill_pose(pose_msg.pose, ref.x, ref.y, ref.heading)
    tw = twist_msg.twist.linear
    tw.x, tw.y, tw.z = ref.vx, ref.vy, 0.0
    ac = accel_msg.accel.linear
    ac.x, ac.y, ac.z = ref.ax, ref.ay, 0.0


def reference_from_msgs(t: float, pose_msg: _PoseStamped, twist_msg: _TwistStamped,
                        accel_msg: _AccelStamped) -> RefSample | str:
    """RefSample from the three reference messages, or a reason string if unusable.

    Parameters
    ----------
    t : float
        The sample's time (s).
    pose_msg, twist_msg, accel_msg : PoseStamped, TwistStamped, AccelStamped
        The reference messages of one step.
    """
    pose = pose_from_odom(pose_msg.pose)
    if isinstance(pose, str):
        return f'reference/pose: {pose}'
    tw, ac = twist_msg.twist.linear, accel_msg.accel.linear
    vx, vy, ax, ay = tw.x, tw.y, ac.x, ac.y
    isfinite = math.isfinite
    if not (isfinite(vx) and isfinite(vy) and isfinite(ax) and isfinite(ay)):
        return f'reference twist/accel not finite: {(vx, vy, ax, ay)}'
    return RefSample(t, pose[0], pose[1], vx, vy, ax, ay, pose[2])


#: Tracker parameters of the latency predictor (all 0: no prediction, today's law).
PREDICT_PARAMS = ('predict_latency', 'predict_odom_latency', 'predict_lag_v', 'predict_lag_w')
#: Tracker parameters of the base's acceleration limits (0 = unknown: no rate limit).
LIMIT_PARAMS = ('max_linear_accel', 'max_angular_accel')


def tracker_config(values: Mapping[str, Any]) -> TrackerConfig:
    """Build and validate the TrackerConfig from parameter values (startup and runtime).

    Parameters
    ----------
    values : mapping
        The tracker's parameter values by name (``K``, ``K_shape``, ``E``, ``F``,
        ``Delta``, ``A_tau``, ``dt``, speeds, ``tau``, ``delay_compensation``; the
        predictor and acceleration-limit ones default to 0).

    Raises
    ------
    LoopConfigError
        If a value is invalid (an ``InputError``).
    """
    K = gain_from_parameters(values['K'], values['K_shape'])
    E = as_matrix(values['E'], 'E', (2, 2), flat=True, error=LoopConfigError)
    F = as_matrix(values['F'], 'F', (2, 4), flat=True, error=LoopConfigError)
    D = as_matrix(values['Delta'], 'Delta', (2, 2), flat=True, error=LoopConfigError)
    pert = E @ D @ F
    a_tau = as_matrix(values['A_tau'], 'A_tau', (4, 4), flat=True, error=LoopConfigError)
    return TrackerConfig(K=tuple(map(tuple, K.tolist())), dt=values['dt'],
                         max_linear_speed=values['max_linear_speed'],
                         max_angular_speed=values['max_angular_speed'],
                         min_speed=values['min_speed'],
                         perturbation=pert if np.any(pert) else None,
                         delay_compensation=values['delay_compensation'],
                         A_tau=tuple(map(tuple, a_tau.tolist())),
                         tau=values['tau'],
                         **{n: values.get(n, 0.0) for n in PREDICT_PARAMS + LIMIT_PARAMS})


def _yaw(q: _Quaternion, source: str, i: int) -> float:
    vals = (q.x, q.y, q.z, q.w)
    norm = math.sqrt(sum(v * v for v in vals))
    if not all(math.isfinite(v) for v in vals) or abs(norm - 1.0) > 1e-3:
        raise TrajectoryError(f'{source}: point {i}: orientation {vals} is not a unit '
                              'quaternion')
    return quaternion_to_yaw(*vals)


def path_to_trajectory(msg: Any, *, frame: str, source: str,
                       cruise_speed: float | None = None, max_accel: float | None = None,
                       now_ns: int | None = None) -> tuple[Trajectory, int]:
    """Trajectory and origin stamp (ns) of a nav_msgs/Path; :class:`TrajectoryError` if bad.

    An untimed Path (all pose stamps zero) starts at its header stamp, or at ``now_ns``
    (the receiver's clock) when that is zero too.

    Parameters
    ----------
    msg : nav_msgs/Path
        The path (rclpy's or rosbags' message).
    frame : str
        The frame its header and poses must be in ('' poses: the header's).
    source : str
        Where it came from, for error messages.
    cruise_speed, max_accel : float, optional
        The time law of an untimed path (m/s, m/s^2; default: the trajectory module's).
    now_ns : int, optional
        The receiver's clock (ns): the origin of an untimed path without a header stamp.
    """
    check_frame(msg.header.frame_id, frame, source)
    n = len(msg.poses)
    stamps = np.zeros(n, dtype=np.int64)
    x, y, yaw = np.empty(n), np.empty(n), np.empty(n)
    for i, ps in enumerate(msg.poses):
        if ps.header.frame_id not in ('', frame):
            raise TrajectoryError(f'{source}: point {i}: frame_id {ps.header.frame_id!r}; '
                                  f'every pose must be in {frame!r}')
        stamps[i] = stamp_ns(ps.header.stamp)
        x[i], y[i] = ps.pose.position.x, ps.pose.position.y
        yaw[i] = _yaw(ps.pose.orientation, source, i)
    if n and np.all(stamps == 0):            # untimed: the time law along the path
        traj = from_poses(np.zeros(n), x, y, yaw, cruise_speed=cruise_speed,
                          max_accel=max_accel, source=source)
        origin = stamp_ns(msg.header.stamp)
        return traj, origin if origin or now_ns is None else int(now_ns)
    origin = int(stamps[0]) if n else 0
    return from_waypoints((stamps - origin) * 1e-9, x, y, yaw=yaw, source=source), origin


def multidof_to_trajectory(msg: Any, *, frame: str, source: str) -> tuple[Trajectory, int]:
    """Trajectory and origin stamp (ns) of a trajectory_msgs/MultiDOFJointTrajectory.

    Parameters
    ----------
    msg : trajectory_msgs/MultiDOFJointTrajectory
        The trajectory of one joint (the planar base; rclpy's or rosbags' message).
    frame : str
        The frame its header must be in.
    source : str
        Where it came from, for error messages.

    Raises
    ------
    TrajectoryError
        If it is not one joint with one transform per point, or the points are bad.
    """
    check_frame(msg.header.frame_id, frame, source)
    if len(msg.joint_names) > 1:
        raise TrajectoryError(f'{source}: {len(msg.joint_names)} joints '
                              f'{list(msg.joint_names)}; expected one (the planar base)')
    n = len(msg.points)
    t, x, y, yaw = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    vel = np.full((n, 2), np.nan)
    acc = np.full((n, 2), np.nan)
    for i, p in enumerate(msg.points):
        if len(p.transforms) != 1:
            raise TrajectoryError(f'{source}: point {i}: {len(p.transforms)} transforms; '
                                  'expected one')
        t[i] = stamp_ns(p.time_from_start) * 1e-9
        tr = p.transforms[0]
        x[i], y[i] = tr.translation.x, tr.translation.y
        yaw[i] = _yaw(tr.rotation, source, i)
        if p.velocities:
            vel[i] = (p.velocities[0].linear.x, p.velocities[0].linear.y)
        if p.accelerations:
            acc[i] = (p.accelerations[0].linear.x, p.accelerations[0].linear.y)
    origin = stamp_ns(msg.header.stamp)
    have_v = n > 0 and all(len(p.velocities) == 1 for p in msg.points)
    have_a = n > 0 and all(len(p.accelerations) == 1 for p in msg.points)
    if have_v:
        traj = from_states(t, x, y, vel[:, 0], vel[:, 1],
                           acc[:, 0] if have_a else None, acc[:, 1] if have_a else None,
                           yaw=yaw, source=source)
    else:
        traj = from_waypoints(t, x, y, yaw=yaw, source=source)
    return traj, origin
