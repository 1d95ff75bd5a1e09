"""Trajectory messages <-> the core's arrays (nav_msgs/Path, MultiDOFJointTrajectory).

The core (:mod:`control.trajectory`) takes arrays; this module only reads and fills
messages.  Times are kept in integer nanoseconds relative to an *origin* stamp, so the
tracker samples at ``(odom stamp - origin) * 1e-9`` exactly as
:func:`control.follow.simulate_following` does.

nav_msgs/Path: the poses' stamps are the times (absolute, the first one is the origin);
when every pose stamp is zero the times come from a trapezoidal time law (cruise speed,
acceleration limit) and the origin is the Path's header stamp.  Every pose must be in
the Path's frame, which must be the odometry frame (no tf here).

trajectory_msgs/MultiDOFJointTrajectory: one joint (the planar base): transforms[0]
gives the pose, velocities[0].linear / accelerations[0].linear (in the trajectory
frame) the velocity and acceleration, ``time_from_start`` the time after the header
stamp (the origin).  Points without velocities are interpolated by the cubic spline.
"""
from __future__ import annotations

import math

import numpy as np
from nav_msgs.msg import Path as PathMsg

from ..control.loop import quaternion_to_yaw, yaw_to_quaternion
from ..control.trajectory import (Trajectory, TrajectoryError, check_frame, from_poses,
                                  from_states, from_waypoints)

__all__ = ['path_to_trajectory', 'trajectory_to_path', 'multidof_to_trajectory',
           'states_to_multidof', 'stamp_ns']


def stamp_ns(stamp) -> int:
    """builtin_interfaces/Time or Duration -> integer nanoseconds."""
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def _yaw(q, source: str, i: int) -> float:
    vals = (q.x, q.y, q.z, q.w)
    norm = math.sqrt(sum(v * v for v in vals))
    if not all(math.isfinite(v) for v in vals) or abs(norm - 1.0) > 1e-3:
        raise TrajectoryError(f'{source}: point {i}: orientation {vals} is not a unit '
                              'quaternion')
    return quaternion_to_yaw(*vals)


def path_to_trajectory(msg, *, frame: str, source: str, cruise_speed: float | None = None,
                       max_accel: float | None = None,
                       now_ns: int | None = None) -> tuple[Trajectory, int]:
    """Trajectory and origin stamp (ns) of a nav_msgs/Path; :class:`TrajectoryError` if bad.

    An untimed Path (all pose stamps zero) starts at its header stamp, or at ``now_ns``
    (the receiver's clock) when that is zero too.
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


def trajectory_to_path(traj: Trajectory, origin_ns: int, frame: str, times=None,
                       msg: PathMsg | None = None) -> PathMsg:
    """nav_msgs/Path of ``traj`` at ``times`` (default its knots), stamped ``origin + t``."""
    msg = PathMsg() if msg is None else msg
    from geometry_msgs.msg import PoseStamped
    t, x, y, h = traj.poses(times)
    msg.header.frame_id = frame
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(int(origin_ns), 1_000_000_000)
    poses = []
    for ti, xi, yi, hi in zip(t, x, y, h):
        ps = PoseStamped()
        ps.header.frame_id = frame
        ns = int(origin_ns) + int(round(float(ti) * 1e9))
        ps.header.stamp.sec, ps.header.stamp.nanosec = divmod(ns, 1_000_000_000)
        ps.pose.position.x, ps.pose.position.y = float(xi), float(yi)
        q = ps.pose.orientation
        q.x, q.y, q.z, q.w = yaw_to_quaternion(float(hi))
        poses.append(ps)
    msg.poses = poses
    return msg


def multidof_to_trajectory(msg, *, frame: str, source: str) -> tuple[Trajectory, int]:
    """Trajectory and origin stamp (ns) of a trajectory_msgs/MultiDOFJointTrajectory."""
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


def states_to_multidof(t_ns, samples, origin_ns: int, frame: str, joint: str = 'base_link'):
    """trajectory_msgs/MultiDOFJointTrajectory of timed states (one joint, the planar base).

    ``t_ns``: integer nanoseconds after ``origin_ns`` (the header stamp); ``samples``: a
    :class:`~control.trajectory.TrajectorySamples` (position, velocity, acceleration in
    ``frame`` and heading) - e.g. :func:`control.trajectory.analytic_knots`.
    :func:`multidof_to_trajectory` turns it back into the quintic Hermite trajectory.
    """
    from geometry_msgs.msg import Transform, Twist
    from trajectory_msgs.msg import MultiDOFJointTrajectory, MultiDOFJointTrajectoryPoint
    msg = MultiDOFJointTrajectory()
    msg.header.frame_id = frame
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(int(origin_ns), 1_000_000_000)
    msg.joint_names = [joint]
    points = []
    for i, t in enumerate(t_ns):
        p = MultiDOFJointTrajectoryPoint()
        tr = Transform()
        tr.translation.x, tr.translation.y = float(samples.x[i]), float(samples.y[i])
        q = tr.rotation
        q.x, q.y, q.z, q.w = yaw_to_quaternion(float(samples.heading[i]))
        vel, acc = Twist(), Twist()
        vel.linear.x, vel.linear.y = float(samples.vx[i]), float(samples.vy[i])
        acc.linear.x, acc.linear.y = float(samples.ax[i]), float(samples.ay[i])
        p.transforms, p.velocities, p.accelerations = [tr], [vel], [acc]
        p.time_from_start.sec, p.time_from_start.nanosec = divmod(int(t), 1_000_000_000)
        points.append(p)
    msg.points = points
    return msg
