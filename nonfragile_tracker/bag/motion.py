"""Velocity commands and odometry of any rosbag2 bag, for latency identification.

:func:`read_motion` returns the series
:func:`~nonfragile_tracker.control.identification.identify.identify_latency` needs, from a
bag of this package or of any robot: commands (Twist by receive time, TwistStamped by
header stamp) and odometry (by header stamp), on topics found as ``bag report`` finds them;
a missing, ambiguous or wrongly typed topic raises :class:`~.errors.MissingTopicsError`.
No ROS (rclpy) import; rosbags only.

See doc/tutorial.md, section "Identify the latency (``identify``)".
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np
from rosbags.rosbag2 import ReaderError

from ..interface import topics
from ..errors import InputError
from ..control.identification.identify import CommandSamples, OdometrySamples
from ..control.simulation.model import quaternion_to_yaw
from .reader import MissingTopicsError, BagError, open_reader, pick_topic
from .typestore import jazzy_typestore

if TYPE_CHECKING:
    from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__Twist as TwistMsg
    from rosbags.typesys.stores.ros2_jazzy import \
        geometry_msgs__msg__TwistStamped as TwistStampedMsg
    from rosbags.typesys.stores.ros2_jazzy import nav_msgs__msg__Odometry as OdometryMsg

__all__ = ['MotionData', 'read_motion', 'read_poses', 'TWIST', 'TWIST_STAMPED', 'ODOMETRY',
           'POSE_STAMPED', 'TRUTH_TYPES',
           'CMD_TYPES', 'ODOM_TYPES']

TWIST = 'geometry_msgs/msg/Twist'
TWIST_STAMPED = 'geometry_msgs/msg/TwistStamped'
ODOMETRY = 'nav_msgs/msg/Odometry'
CMD_TYPES = (TWIST, TWIST_STAMPED)
ODOM_TYPES = (ODOMETRY,)


@dataclass(frozen=True)
class MotionData:
    """What :func:`read_motion` found (times in s on the bag's clock)."""

    path: Path
    commands: CommandSamples
    odometry: OdometrySamples
    cmd_topic: str
    cmd_type: str
    #: 'receive time' or 'header stamp'
    cmd_time: str
    odom_topic: str
    #: 'header stamp' or 'receive time' (all odometry stamps were zero)
    odom_time: str
    #: median of (receive time - header stamp) of the odometry; NaN if stamps unused
    odom_delay_s: float
    #: odometry messages dropped because their stamp repeated an earlier one
    duplicates: int


def read_motion(path: str | os.PathLike[str], *, cmd_topic: str = topics.CMD_VEL,
                odom_topic: str = topics.ODOM, cmd_time: str = 'auto') -> MotionData:
    """Read velocity commands and odometry of a bag for :func:`.identify_latency`.

    Parameters
    ----------
    path : path-like
        A rosbag2 bag directory (any storage rosbags reads: MCAP, sqlite3).
    cmd_topic, odom_topic : str
        Topic names (defaults ``cmd_vel``, ``odom``; see :func:`.pick_topic`).
    cmd_time : {'auto', 'receive', 'stamp'}
        How commands are timed: ``auto`` = header stamp of a TwistStamped (receive
        time if it is zero), receive time of a Twist.

    Returns
    -------
    MotionData

    Raises
    ------
    MissingTopicsError
        A topic is absent, ambiguous or of the wrong type.
    BagError, BagNotFoundError
        As :func:`nonfragile_tracker.bag.reader.open_reader`.
    """
    if cmd_time not in ('auto', 'receive', 'stamp'):
        raise InputError(f"cmd_time must be 'auto', 'receive' or 'stamp', got {cmd_time!r}")
    reader = open_reader(path)
    try:
        available: dict[str, str] = {}
        for c in reader.connections:
            available.setdefault(c.topic, c.msgtype)
        ctopic = pick_topic(available, cmd_topic, CMD_TYPES, role='velocity commands',
                            option='--cmd-topic', by_type=cmd_topic == topics.CMD_VEL)
        otopic = pick_topic(available, odom_topic, ODOM_TYPES, role='odometry',
                            option='--odom-topic', by_type=odom_topic == topics.ODOM)
        ctype = available[ctopic]
        if cmd_time == 'stamp' and ctype != TWIST_STAMPED:
            raise MissingTopicsError(f'--cmd-time stamp needs a TwistStamped command topic; '
                                     f'{ctopic} is {ctype}', [ctopic])
        conns = [c for c in reader.connections if c.topic in (ctopic, otopic)
                 and c.msgtype == available[c.topic]]
        crows, orows = _motion_rows(path, reader, conns, ctopic, ctype)
    finally:
        reader.close()

    for what, rows, topic in (('velocity commands', crows, ctopic), ('odometry', orows, otopic)):
        if not rows:
            raise MissingTopicsError(f'{what}: topic {topic} in {path} has no messages', [topic])

    cv = np.array(crows, dtype=np.float64).reshape(-1, 4)
    c_recv = np.array([r[0] for r in crows], dtype=np.int64)
    c_stamp = np.array([r[1] for r in crows], dtype=np.int64)
    use_stamp = ctype == TWIST_STAMPED and cmd_time != 'receive' and bool(np.any(c_stamp > 0))
    if cmd_time == 'stamp' and not use_stamp:
        raise MissingTopicsError(f'--cmd-time stamp: {ctopic} has zero header stamps', [ctopic])
    c_ns = c_stamp if use_stamp else c_recv
    order = np.argsort(c_ns, kind='stable')
    commands = CommandSamples((c_ns[order] * 1e-9), cv[order, 2], cv[order, 3])

    o = np.array([r[2:] for r in orows], dtype=float).reshape(-1, 5)
    o_recv = np.array([r[0] for r in orows], dtype=np.int64)
    o_stamp = np.array([r[1] for r in orows], dtype=np.int64)
    stamped = bool(np.any(o_stamp > 0))
    o_ns = o_stamp if stamped else o_recv
    order = np.argsort(o_ns, kind='stable')
    o_ns, o, o_recv = o_ns[order], o[order], o_recv[order]
    keep = np.concatenate([[True], np.diff(o_ns) > 0])
    odometry = OdometrySamples(o_ns[keep] * 1e-9, o[keep, 0], o[keep, 1], o[keep, 2],
                               o[keep, 3], o[keep, 4])
    delay = float(np.median((o_recv - o_ns) * 1e-9)) if stamped else math.nan
    return MotionData(path=Path(path), commands=commands, odometry=odometry, cmd_topic=ctopic,
                      cmd_type=ctype, cmd_time='header stamp' if use_stamp else 'receive time',
                      odom_topic=otopic, odom_time='header stamp' if stamped else 'receive time',
                      odom_delay_s=delay, duplicates=int(np.count_nonzero(~keep)))


def _motion_rows(path: Any, reader: Any, conns: list[Any], ctopic: str, ctype: str
                 ) -> tuple[list[tuple[int, int, float, float]],
                            list[tuple[int, int, float, float, float, float, float]]]:
    """One pass over the command and odometry messages: their rows, receive time first."""
    ts = jazzy_typestore()
    crows: list[tuple[int, int, float, float]] = []
    orows: list[tuple[int, int, float, float, float, float, float]] = []
    try:
        for conn, timestamp, raw in reader.messages(connections=conns):
            # the connection's msgtype (checked against CMD_TYPES / ODOM_TYPES by
            # pick_topic) decides the class deserialize_cdr returns
            msg = ts.deserialize_cdr(raw, conn.msgtype)
            if conn.topic == ctopic:
                tw: TwistMsg
                if ctype == TWIST_STAMPED:
                    cmd = cast('TwistStampedMsg', msg)
                    st = cmd.header.stamp
                    stamp = int(st.sec) * 1_000_000_000 + int(st.nanosec)
                    tw = cmd.twist
                else:
                    stamp, tw = 0, cast('TwistMsg', msg)
                crows.append((timestamp, stamp, float(tw.linear.x), float(tw.angular.z)))
            else:
                odom = cast('OdometryMsg', msg)
                st = odom.header.stamp
                p = odom.pose.pose
                q = p.orientation
                orows.append((timestamp, int(st.sec) * 1_000_000_000 + int(st.nanosec),
                              float(p.position.x), float(p.position.y),
                              quaternion_to_yaw(q.x, q.y, q.z, q.w),
                              float(odom.twist.twist.linear.x),
                              float(odom.twist.twist.angular.z)))
    except (ReaderError, ValueError, IndexError, KeyError, AssertionError) as exc:
        raise BagError(f'{path}: a message cannot be read ({exc}); the bag is '
                       'damaged - try `nonfragile_tracker bag repair`') from None
    return crows, orows


#: Types an external pose (``identify --truth``) may have: a motion-capture or simulator pose.
POSE_STAMPED = 'geometry_msgs/msg/PoseStamped'
TRUTH_TYPES = (POSE_STAMPED, ODOMETRY)


def read_poses(path: str | os.PathLike[str], topic: str) -> OdometrySamples:
    """The poses of ``topic`` (PoseStamped or Odometry), by header stamp (receive time if 0).

    For an external pose (motion capture, a simulator's true pose) beside the odometry:
    :func:`~nonfragile_tracker.control.identification.slip.identify_side_slip`.

    Parameters
    ----------
    path : path-like
        A rosbag2 bag directory.
    topic : str
        The pose topic (looked up as :func:`.pick_topic` does; no fallback by type).

    Returns
    -------
    OdometrySamples
        Pose only (``v``, ``w`` None); repeated stamps dropped.

    Raises
    ------
    MissingTopicsError
        The topic is absent, of another type, or has no messages.
    BagError, BagNotFoundError
        As :func:`nonfragile_tracker.bag.reader.open_reader`.
    """
    reader = open_reader(path)
    rows: list[tuple[int, int, float, float, float]] = []
    try:
        available: dict[str, str] = {}
        for c in reader.connections:
            available.setdefault(c.topic, c.msgtype)
        name = pick_topic(available, topic, TRUTH_TYPES, role='external pose',
                          option='--truth', by_type=False)
        conns = [c for c in reader.connections if c.topic == name
                 and c.msgtype == available[name]]
        ts = jazzy_typestore()
        try:
            for conn, timestamp, raw in reader.messages(connections=conns):
                msg: Any = ts.deserialize_cdr(raw, conn.msgtype)
                pose = msg.pose.pose if conn.msgtype == ODOMETRY else msg.pose
                st = msg.header.stamp
                q = pose.orientation
                rows.append((timestamp, int(st.sec) * 1_000_000_000 + int(st.nanosec),
                             float(pose.position.x), float(pose.position.y),
                             quaternion_to_yaw(q.x, q.y, q.z, q.w)))
        except (ReaderError, ValueError, IndexError, KeyError, AssertionError) as exc:
            raise BagError(f'{path}: a message cannot be read ({exc}); the bag is '
                           'damaged - try `nonfragile_tracker bag repair`') from None
    finally:
        reader.close()
    if not rows:
        raise MissingTopicsError(f'external pose: topic {name} in {path} has no messages',
                                 [name])
    recv = np.array([r[0] for r in rows], dtype=np.int64)
    stamp = np.array([r[1] for r in rows], dtype=np.int64)
    t_ns = stamp if bool(np.any(stamp > 0)) else recv
    p = np.array([r[2:] for r in rows], dtype=float)
    order = np.argsort(t_ns, kind='stable')
    t_ns, p = t_ns[order], p[order]
    keep = np.concatenate([[True], np.diff(t_ns) > 0])
    return OdometrySamples(t_ns[keep] * 1e-9, p[keep, 0], p[keep, 1], p[keep, 2])
