"""ROS-free conversions between messages and the control types, and tracker parameters.

Duck-typed: the functions read attributes, so they take rclpy messages (nodes) and
rosbags' deserialized messages (bag replay) alike - one meaning, one place.
:func:`tracker_config` maps the tracker node's parameter values to
:class:`~nonfragile_tracker.control.loop.TrackerConfig` for the node and for replay.
"""
from __future__ import annotations

import math

import numpy as np

from .control.gains import gain_from_parameters
from .control.loop import LoopConfigError, TrackerConfig, quaternion_to_yaw, yaw_to_quaternion
from .control.reference import RefSample
from .control.validate import as_matrix

__all__ = ['stamp_ns', 'ns_to_stamp', 'fill_pose', 'pose_from_odom', 'fill_reference',
           'reference_from_msgs', 'PREDICT_PARAMS', 'tracker_config']


def stamp_ns(stamp) -> int:
    """builtin_interfaces/Time -> integer nanoseconds."""
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def ns_to_stamp(ns: int, stamp) -> None:
    """Integer nanoseconds -> builtin_interfaces/Time ``stamp`` (in place)."""
    stamp.sec, stamp.nanosec = divmod(int(ns), 1_000_000_000)


def fill_pose(pose, x: float, y: float, th: float) -> None:
    """Fill a geometry_msgs/Pose from a planar pose (REP-103: yaw about +z)."""
    pose.position.x, pose.position.y, pose.position.z = float(x), float(y), 0.0
    q = pose.orientation
    q.x, q.y, q.z, q.w = yaw_to_quaternion(th)


def pose_from_odom(pose) -> tuple[float, float, float] | str:
    """Planar pose from a geometry_msgs/Pose, or a reason string if it is unusable.

    On the tracker's real-time path: each field is read once (message fields are
    properties) and checked without building temporaries.
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


def fill_reference(ref: RefSample, pose_msg, twist_msg, accel_msg) -> None:
    """Fill the three reference messages (pose, twist, accel) from a sample."""
    fill_pose(pose_msg.pose, ref.x, ref.y, ref.heading)
    tw = twist_msg.twist.linear
    tw.x, tw.y, tw.z = ref.vx, ref.vy, 0.0
    ac = accel_msg.accel.linear
    ac.x, ac.y, ac.z = ref.ax, ref.ay, 0.0


def reference_from_msgs(t: float, pose_msg, twist_msg, accel_msg) -> RefSample | str:
    """RefSample from the three reference messages, or a reason string if unusable."""
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


def tracker_config(values: dict) -> TrackerConfig:
    """Build and validate the TrackerConfig from parameter values (startup and runtime)."""
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
                         **{n: values.get(n, 0.0) for n in PREDICT_PARAMS})
