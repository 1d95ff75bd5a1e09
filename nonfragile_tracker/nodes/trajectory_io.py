"""Trajectory messages <-> the core's arrays (nav_msgs/Path, MultiDOFJointTrajectory).

The core (:mod:`nonfragile_tracker.control.simulation.trajectory`) takes arrays; this module
only reads and fills messages, with times in integer nanoseconds relative to an *origin*
stamp (so the tracker samples exactly as the in-process simulation does).

See doc/trajectories.md, section "Sources" (messages to arrays: the stamps, the origin,
the frames, the fields read).
"""
from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
from nav_msgs.msg import Path as PathMsg
from numpy.typing import ArrayLike

from ..control.simulation.model import yaw_to_quaternion
from ..control.simulation.trajectory import Trajectory, TrajectorySamples
# the message -> trajectory conversions are ROS-free (bag/ reconstructs references with them)
from ..interface.msgconv import multidof_cdr, multidof_to_trajectory, path_to_trajectory, stamp_ns

__all__ = ['path_to_trajectory', 'trajectory_to_path', 'multidof_to_trajectory',
           'states_to_multidof', 'followed_to_multidof', 'stamp_ns']


if TYPE_CHECKING:
    from trajectory_msgs.msg import MultiDOFJointTrajectory


def followed_to_multidof(traj: Trajectory, origin_ns: int, frame: str,
                         header_ns: int | None = None) -> bytes:
    """MultiDOFJointTrajectory of a bounded trajectory at its knots (pose, velocity, accel).

    As its CDR bytes (:func:`~nonfragile_tracker.interface.msgconv.multidof_cdr`; a publisher sends
    them as is): made in milliseconds also for 50,000 knots, where the message object
    took seconds in the tracker's callback.

    Stamped ``origin_ns + t_start`` with times from ``t_start`` (or stamped ``header_ns``
    with times from there: the same knots at the same absolute times); its quintic Hermite
    rebuild (:func:`.multidof_to_trajectory`) is the trajectory itself (a cubic or quintic
    piece is matched exactly by its end values), sampled at the same stamps.

    Parameters
    ----------
    traj : Trajectory
        A bounded trajectory (with knots).
    origin_ns : int
        Stamp [ns] of the trajectory's ``t = 0``.
    frame : str
        ``frame_id`` of the header.
    header_ns : int, optional
        The header's stamp [ns] (the tracker: the odometry at which it adopted the
        trajectory); default ``origin_ns + t_start``.

    Returns
    -------
    bytes
        The serialized trajectory_msgs/MultiDOFJointTrajectory.
    """
    knots = traj.knots
    if header_ns is None:
        header_ns = int(origin_ns) + int(round(traj.t_start * 1e9))
        t_ns = np.round((knots - traj.t_start) * 1e9).astype(np.int64)
    else:
        t_ns = np.round(knots * 1e9).astype(np.int64) + (int(origin_ns) - int(header_ns))
    s = traj.evaluate(knots)
    return multidof_cdr(t_ns, s.x, s.y, s.heading, s.vx, s.vy, s.ax, s.ay, int(header_ns),
                        frame)


def trajectory_to_path(traj: Trajectory, origin_ns: int, frame: str,
                       times: ArrayLike | None = None, msg: PathMsg | None = None) -> PathMsg:
    """nav_msgs/Path of ``traj`` at ``times`` (default its knots), stamped ``origin + t``.

    Parameters
    ----------
    traj : Trajectory
        The trajectory.
    origin_ns : int
        Stamp [ns] of ``t = 0`` (the header's stamp).
    frame : str
        ``frame_id`` of the header and of every pose.
    times : array_like, optional
        Sample times [s] after the origin; the trajectory's knots when ``None`` (an
        analytic path has none: then they are required).
    msg : nav_msgs.msg.Path, optional
        A message to fill (reused); a new one when ``None``.

    Returns
    -------
    nav_msgs.msg.Path
    """
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


def states_to_multidof(t_ns: Sequence[int] | np.ndarray, samples: TrajectorySamples,
                       origin_ns: int, frame: str, joint: str = 'base_link'
                       ) -> MultiDOFJointTrajectory:
    """trajectory_msgs/MultiDOFJointTrajectory of timed states (one joint, the planar base).

    ``t_ns``: integer nanoseconds after ``origin_ns`` (the header stamp); ``samples``: a
    :class:`~.control.simulation.trajectory.TrajectorySamples` (position, velocity, acceleration in
    ``frame`` and heading) - e.g. :func:`.control.simulation.trajectory.analytic_knots`.
    :func:`.multidof_to_trajectory` turns it back into the quintic Hermite trajectory.

    Parameters
    ----------
    t_ns : sequence of int
        Times [ns] after ``origin_ns``, one per sample.
    samples : TrajectorySamples
        Positions [m], velocities [m/s], accelerations [m/s^2] and heading [rad].
    origin_ns : int
        The header's stamp [ns].
    frame : str
        The header's ``frame_id``.
    joint : str, optional
        The one joint name.

    Returns
    -------
    trajectory_msgs.msg.MultiDOFJointTrajectory
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
