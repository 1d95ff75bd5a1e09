"""ROS-free conversions between messages and the control types, and tracker parameters.

Duck-typed: the functions read attributes, so they take rclpy messages (nodes) and
rosbags' deserialized messages (bag replay) alike - one meaning, one place.
:func:`tracker_config` maps the tracker node's parameter values to
:class:`~.control.simulation.tracker.TrackerConfig` for the node and for replay.

See doc/trajectories.md, section "Sources" (messages to arrays), and doc/ros-interface.md,
section "Input rules" (which applies these readers).
"""
from __future__ import annotations

import math
import struct
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from ..control.simulation.gains import gain_from_parameters
from ..control.simulation.interfaces import DEFAULT_CONTROLLER, load_factory
from ..control.simulation.errors import LoopConfigError
from ..control.simulation.tracker import TrackerConfig
from ..control.simulation.model import quaternion_to_yaw, yaw_to_quaternion
from ..control.simulation.reference import RefSample
from ..control.simulation.trajectory import (Trajectory, TrajectoryError, check_frame, from_poses,
                                            from_states, from_waypoints)
from ..control.validate import as_matrix

__all__ = ['stamp_ns', 'ns_to_stamp', 'fill_pose', 'pose_from_odom', 'fill_reference',
           'reference_from_msgs', 'path_arrays', 'path_to_trajectory', 'multidof_to_trajectory',
           'MultiDOFArrays', 'multidof_arrays', 'multidof_cdr', 'multidof_from_cdr',
           'PREDICT_PARAMS', 'LIMIT_PARAMS', 'GAIN_PARAMS', 'SLIP_PARAMS', 'tracker_config',
           'LAW_DEFAULTS', 'tracker_config_from']


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
#: Tracker parameters of the base's static channel gains (1 = none: no compensation).
GAIN_PARAMS = ('gain_v', 'gain_w')
#: Tracker parameters of the base's side-slip table ([0] and [0]: none).
SLIP_PARAMS = ('side_slip_rates', 'side_slip')


#: The tracker node's defaults for the parameters of the law (nodes/tracker.PARAMS; a test
#: keeps them equal): what :func:`tracker_config_from` takes for a missing parameter.
LAW_DEFAULTS: dict[str, Any] = {
    'K_shape': [2, 4], 'dt': 0.0, 'max_linear_speed': 1.0, 'max_angular_speed': 2.0,
    'min_speed': 1e-3, 'E': [1.0, 0.0, 0.0, 1.0], 'F': [0.0] * 8, 'Delta': [0.0] * 4,
    'delay_compensation': False, 'A_tau': [0.0] * 16, 'tau': 0.0,
    'predict_latency': 0.0, 'predict_odom_latency': 0.0, 'predict_lag_v': 0.0,
    'predict_lag_w': 0.0, 'max_linear_accel': 0.0, 'max_angular_accel': 0.0,
    'gain_v': 1.0, 'gain_w': 1.0, 'side_slip_rates': [0.0], 'side_slip': [0.0],
}


def tracker_config_from(params: Mapping[str, Any], K: Any, **overrides: Any) -> TrackerConfig:
    """The law's configuration from a node's tracker parameters and a gain, as the node does.

    Parameters
    ----------
    params : mapping
        Tracker parameters (a scenario's or robot file's ``tracker`` section); a missing one
        takes the node's default (:data:`LAW_DEFAULTS`).
    K : array_like
        The m x n gain.
    **overrides
        Parameters that replace ``params`` (e.g. ``delay_compensation``).

    Returns
    -------
    TrackerConfig
        What :func:`tracker_config` makes of the same values (the node's one mapping).
    """
    gain = np.asarray(K, dtype=float)
    values = {**LAW_DEFAULTS, **params, **overrides}
    values['K'], values['K_shape'] = gain.ravel().tolist(), list(gain.shape)
    return tracker_config(values)


def tracker_config(values: Mapping[str, Any]) -> TrackerConfig:
    """Build and validate the TrackerConfig from parameter values (startup and runtime).

    Parameters
    ----------
    values : mapping
        The tracker's parameter values by name (``K``, ``K_shape``, ``E``, ``F``,
        ``Delta``, ``A_tau``, ``dt``, speeds, ``tau``, ``delay_compensation``; the
        predictor and acceleration-limit ones default to 0, the channel gains to 1, the
        side-slip table to none, ``controller`` to our law).

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
    controller = values.get('controller') or ''
    if controller and controller != DEFAULT_CONTROLLER:
        load_factory(controller)                # a name that cannot be loaded: refused here
    else:
        controller = ''
    return TrackerConfig(K=tuple(map(tuple, K.tolist())), dt=values['dt'],
                         max_linear_speed=values['max_linear_speed'],
                         max_angular_speed=values['max_angular_speed'],
                         min_speed=values['min_speed'],
                         perturbation=pert if np.any(pert) else None,
                         delay_compensation=values['delay_compensation'],
                         A_tau=tuple(map(tuple, a_tau.tolist())),
                         tau=values['tau'], controller=controller,
                         **{n: values.get(n, 0.0) for n in PREDICT_PARAMS + LIMIT_PARAMS},
                         **{n: values.get(n, 1.0) for n in GAIN_PARAMS},
                         side_slip_rates=_floats(values, 'side_slip_rates'),
                         side_slip=_floats(values, 'side_slip'))


def _floats(values: Mapping[str, Any], name: str) -> tuple[float, ...]:
    """A parameter's list of numbers as a tuple (its default when missing)."""
    val = values.get(name, LAW_DEFAULTS[name])
    if isinstance(val, (str, bytes)) or not hasattr(val, '__iter__'):
        raise LoopConfigError(f'{name} must be a list of numbers, got {val!r}')
    return tuple(val)


def _yaw(q: _Quaternion, source: str, i: int) -> float:
    vals = (q.x, q.y, q.z, q.w)
    norm = math.sqrt(sum(v * v for v in vals))
    if not all(math.isfinite(v) for v in vals) or abs(norm - 1.0) > 1e-3:
        raise TrajectoryError(f'{source}: point {i}: orientation {vals} is not a unit '
                              'quaternion')
    return quaternion_to_yaw(*vals)


def path_arrays(msg: Any, *, frame: str, source: str
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The pose stamps (ns), positions (m) and headings (rad) of a nav_msgs/Path.

    Parameters
    ----------
    msg : nav_msgs/Path
        The path (rclpy's or rosbags' message).
    frame : str
        The frame its header and poses must be in ('' poses: the header's).
    source : str
        Where it came from, for error messages.

    Returns
    -------
    (numpy.ndarray, numpy.ndarray, numpy.ndarray, numpy.ndarray)
        ``stamps`` (int64), ``x``, ``y``, ``yaw``.

    Raises
    ------
    TrajectoryError
        A header or pose in another frame, a bad orientation.
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
    return stamps, x, y, yaw


def path_to_trajectory(msg: Any, *, frame: str, source: str,
                       cruise_speed: float | None = None, max_accel: float | None = None,
                       now_ns: int | None = None) -> tuple[Trajectory, int]:
    """Trajectory and origin stamp (ns) of a nav_msgs/Path; :class:`.TrajectoryError` if bad.

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
    stamps, x, y, yaw = path_arrays(msg, frame=frame, source=source)
    n = stamps.size
    if n and np.all(stamps == 0):            # untimed: the time law along the path
        traj = from_poses(np.zeros(n), x, y, yaw, cruise_speed=cruise_speed,
                          max_accel=max_accel, source=source)
        origin = stamp_ns(msg.header.stamp)
        return traj, origin if origin or now_ns is None else int(now_ns)
    origin = int(stamps[0]) if n else 0
    return from_waypoints((stamps - origin) * 1e-9, x, y, yaw=yaw, source=source), origin


@dataclass(frozen=True)
class MultiDOFArrays:
    """A trajectory_msgs/MultiDOFJointTrajectory of the planar base, as arrays.

    What :func:`multidof_to_trajectory` reads: from a message object
    (:func:`multidof_arrays`) or straight from its CDR bytes (:func:`multidof_from_cdr`).
    ``vel``/``acc`` are ``(n, 2)`` (linear x, y); a row of NaN where a point has none.
    ``counts`` is the number of transforms of each point (one is expected).
    """

    frame_id: str
    origin_ns: int
    joint_names: tuple[str, ...]
    t_ns: np.ndarray
    x: np.ndarray
    y: np.ndarray
    quaternion: np.ndarray          #: the orientations, one row (x, y, z, w) per point
    vel: np.ndarray
    acc: np.ndarray
    counts: np.ndarray
    have_v: bool
    have_a: bool


def multidof_arrays(msg: Any) -> MultiDOFArrays:
    """The arrays of a MultiDOFJointTrajectory message object (rclpy's or rosbags').

    Parameters
    ----------
    msg : trajectory_msgs/MultiDOFJointTrajectory
        The message.

    Returns
    -------
    MultiDOFArrays
    """
    n = len(msg.points)
    t_ns = np.empty(n, dtype=np.int64)
    x, y = np.empty(n), np.empty(n)
    quat = np.full((n, 4), np.nan)
    vel = np.full((n, 2), np.nan)
    acc = np.full((n, 2), np.nan)
    counts = np.empty(n, dtype=np.int64)
    for i, p in enumerate(msg.points):
        counts[i] = len(p.transforms)
        t_ns[i] = stamp_ns(p.time_from_start)
        if p.transforms:
            tr = p.transforms[0]
            x[i], y[i] = tr.translation.x, tr.translation.y
            q = tr.rotation
            quat[i] = (q.x, q.y, q.z, q.w)
        if p.velocities:
            vel[i] = (p.velocities[0].linear.x, p.velocities[0].linear.y)
        if p.accelerations:
            acc[i] = (p.accelerations[0].linear.x, p.accelerations[0].linear.y)
    return MultiDOFArrays(
        msg.header.frame_id, stamp_ns(msg.header.stamp), tuple(msg.joint_names), t_ns, x, y,
        quat, vel, acc, counts,
        have_v=n > 0 and all(len(p.velocities) == 1 for p in msg.points),
        have_a=n > 0 and all(len(p.accelerations) == 1 for p in msg.points))


def multidof_to_trajectory(msg: Any, *, frame: str, source: str) -> tuple[Trajectory, int]:
    """Trajectory and origin stamp (ns) of a trajectory_msgs/MultiDOFJointTrajectory.

    Parameters
    ----------
    msg : trajectory_msgs/MultiDOFJointTrajectory or MultiDOFArrays
        The trajectory of one joint (the planar base; rclpy's or rosbags' message, or its
        arrays as :func:`multidof_from_cdr` reads them from the CDR bytes).
    frame : str
        The frame its header must be in.
    source : str
        Where it came from, for error messages.

    Raises
    ------
    TrajectoryError
        If it is not one joint with one transform per point, or the points are bad.
    """
    m = msg if isinstance(msg, MultiDOFArrays) else multidof_arrays(msg)
    check_frame(m.frame_id, frame, source)
    if len(m.joint_names) > 1:
        raise TrajectoryError(f'{source}: {len(m.joint_names)} joints '
                              f'{list(m.joint_names)}; expected one (the planar base)')
    bad = np.flatnonzero(m.counts != 1)
    if bad.size:
        i = int(bad[0])
        raise TrajectoryError(f'{source}: point {i}: {int(m.counts[i])} transforms; '
                              'expected one')
    q = m.quaternion
    norm = np.sqrt((q * q).sum(axis=1))
    bad = np.flatnonzero(~(np.isfinite(q).all(axis=1) & (np.abs(norm - 1.0) <= 1e-3)))
    if bad.size:
        i = int(bad[0])
        raise TrajectoryError(f'{source}: point {i}: orientation '
                              f'{tuple(float(v) for v in q[i])} is not a unit quaternion')
    # quaternion_to_yaw, over all points
    qx, qy, qz, qw = q.T
    yaw = np.arctan2(2.0 * (qw * qz + qx * qy), qw * qw + qx * qx - qy * qy - qz * qz)
    t = m.t_ns * 1e-9
    if m.have_v:
        traj = from_states(t, m.x, m.y, m.vel[:, 0], m.vel[:, 1],
                           m.acc[:, 0] if m.have_a else None,
                           m.acc[:, 1] if m.have_a else None, yaw=yaw, source=source)
    else:
        traj = from_waypoints(t, m.x, m.y, yaw=yaw, source=source)
    return traj, m.origin_ns


# ------------------------------------------------------------------ MultiDOF as CDR bytes
# A trajectory of the planar base, one transform, velocity and acceleration per point, as
# the middleware serializes it (CDR, little endian, the form rclpy publishes and a raw
# subscription receives), made and read with numpy over all points at once.  Building the
# message object point by point took 2.4 s for the 48,000 knots of an hour of the
# reference's path, reading it back 0.5 s, and both run in one piece in a node (the
# reference's start-up, the tracker's callback), where no stop signal is acted on.
# test/test_multidof_cdr.py checks both ways against rclpy's own (de)serialization.

_CDR_LE = b'\x00\x01\x00\x00'          # encapsulation: plain CDR, little endian
#: One point when it starts 8-aligned (every point but maybe the first): the count of each
#: sequence (1), 4 bytes of padding before its doubles, the doubles; then time_from_start.
_POINT = np.dtype({
    'names': ['nt', 'tx', 'ty', 'tz', 'qx', 'qy', 'qz', 'qw',
              'nv', 'vx', 'vy', 'vz', 'wvx', 'wvy', 'wvz',
              'na', 'ax', 'ay', 'az', 'wax', 'way', 'waz', 'sec', 'nsec'],
    'formats': ['<u4'] + ['<f8'] * 7 + ['<u4'] + ['<f8'] * 6 + ['<u4'] + ['<f8'] * 6
               + ['<i4', '<u4'],
    'offsets': [0, *range(8, 64, 8), 64, *range(72, 120, 8), 120, *range(128, 176, 8),
                176, 180],
    'itemsize': 184})


def _cdr_string(buf: bytearray, text: str) -> None:
    data = text.encode() + b'\x00'
    buf += b'\x00' * (-len(buf) % 4)
    buf += struct.pack('<I', len(data)) + data


def multidof_cdr(t_ns: Any, x: Any, y: Any, heading: Any, vx: Any, vy: Any, ax: Any,
                 ay: Any, origin_ns: int, frame: str, joint: str = 'base_link') -> bytes:
    """The CDR bytes of a MultiDOFJointTrajectory of one joint (rclpy publishes bytes as is).

    The same message as the node layer's ``states_to_multidof`` builds point by point
    (pose with the heading as quaternion, linear velocity and acceleration, zero
    z/angular parts), in milliseconds for 50,000 points.

    Parameters
    ----------
    t_ns : array_like of int
        ``time_from_start`` of each point [ns].
    x, y, heading, vx, vy, ax, ay : array_like
        Position [m], heading [rad], velocity [m/s], acceleration [m/s^2] per point.
    origin_ns : int
        The header's stamp [ns].
    frame : str
        The header's ``frame_id``.
    joint : str, optional
        The one joint name.

    Returns
    -------
    bytes
    """
    t = np.asarray(t_ns, dtype=np.int64)
    n = t.size
    head = bytearray(struct.pack('<iI', *divmod(int(origin_ns), 1_000_000_000)))
    _cdr_string(head, frame)
    head += b'\x00' * (-len(head) % 4) + struct.pack('<I', 1)
    _cdr_string(head, joint)
    head += b'\x00' * (-len(head) % 4) + struct.pack('<I', n)
    rec = np.zeros(n, dtype=_POINT)
    rec['nt'] = rec['nv'] = rec['na'] = 1
    rec['tx'], rec['ty'] = x, y
    half = [0.5 * h for h in np.asarray(heading, float).tolist()]
    rec['qz'] = [math.sin(h) for h in half]      # yaw_to_quaternion's floats exactly
    rec['qw'] = [math.cos(h) for h in half]
    rec['vx'], rec['vy'], rec['ax'], rec['ay'] = vx, vy, ax, ay
    rec['sec'], rec['nsec'] = np.divmod(t, 1_000_000_000)
    body = rec.tobytes()
    if n and len(head) % 8 == 4:        # the first point starts 4 past an 8 boundary: its
        body = body[:4] + body[8:]      # first doubles need no padding (offsets of the body)
    return _CDR_LE + bytes(head) + body


def multidof_from_cdr(raw: bytes | bytearray | memoryview) -> MultiDOFArrays | None:
    """The arrays of a MultiDOFJointTrajectory's CDR bytes, or None if not the compact form.

    The compact form: little-endian CDR with one transform, one velocity and one
    acceleration at every point (what :func:`multidof_cdr` writes and every planner of
    one planar base sends).  Anything else - another layout, a truncated or malformed
    buffer - gives None: deserialize it then and read the message object.

    Parameters
    ----------
    raw : bytes
        The serialized message (a raw subscription's, or a bag's).

    Returns
    -------
    MultiDOFArrays or None
    """
    buf = memoryview(raw).cast('B')
    if bytes(buf[:4]) != _CDR_LE:
        return None
    body = buf[4:]
    try:
        sec, nsec = struct.unpack_from('<iI', body, 0)
        pos = 8

        def string(pos: int) -> tuple[str, int]:
            pos += -pos % 4
            (length,) = struct.unpack_from('<I', body, pos)
            if length < 1 or pos + 4 + length > len(body):
                raise ValueError('bad string')
            return bytes(body[pos + 4:pos + 3 + length]).decode(), pos + 4 + length

        frame, pos = string(pos)
        pos += -pos % 4
        (joints,) = struct.unpack_from('<I', body, pos)
        pos += 4
        if joints > 64:
            return None
        names = []
        for _ in range(joints):
            name, pos = string(pos)
            names.append(name)
        pos += -pos % 4
        (n,) = struct.unpack_from('<I', body, pos)
        pos += 4
    except (struct.error, ValueError, UnicodeDecodeError):
        return None
    first = b''
    if n and pos % 8 == 4:              # the first point without its padding
        first = bytes(body[pos:pos + 4]) + b'\x00' * 4 + bytes(body[pos + 4:pos + 180])
        pos += 180
        n_rest = n - 1
    else:
        n_rest = n
    if len(body) != pos + n_rest * _POINT.itemsize or (first and len(first) != 184):
        return None                     # another layout (or not this message at all)
    rest = np.frombuffer(body, dtype=_POINT, count=n_rest, offset=pos)
    rec = np.concatenate([np.frombuffer(first, dtype=_POINT), rest]) if first else rest
    if not (np.all(rec['nt'] == 1) and np.all(rec['nv'] == 1) and np.all(rec['na'] == 1)):
        return None
    t_ns = rec['sec'].astype(np.int64) * 1_000_000_000 + rec['nsec']
    quat = np.stack([rec['qx'], rec['qy'], rec['qz'], rec['qw']], axis=1)
    return MultiDOFArrays(frame, sec * 1_000_000_000 + nsec, tuple(names), t_ns,
                          rec['tx'].copy(), rec['ty'].copy(), quat,
                          np.stack([rec['vx'], rec['vy']], axis=1),
                          np.stack([rec['ax'], rec['ay']], axis=1),
                          np.ones(n, dtype=np.int64), have_v=n > 0, have_a=n > 0)
