"""Read a recorded run back from a rosbag2 bag into numpy arrays.

:func:`read_bag` returns per-topic message counts and receive times and a :class:`RunData`
with the robot pose, the reference (matched by header stamp) and the commands;
:func:`read_messages` yields ``(receive time, message)`` of one topic.  Topics are found
under their fully qualified names (a namespace given or guessed); a step republished with
the same stamp is counted and dropped.  All errors are
:class:`~nonfragile_tracker.bag.errors.BagError` subclasses that say what to do.  No ROS
(rclpy) import; rosbags only.

See doc/bags.md, section "Recording and golden bags" (reading).
"""
from __future__ import annotations

import math
import os
import struct
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.interfaces import Connection, ConnectionExtRosbag2, MessageDefinition, Qos
from rosbags.rosbag2 import Reader, ReaderError
from rosbags.typesys.store import Typestore

from ..interface import topics
from ..control.simulation.follow import REST_SPEED, START_TOLERANCE, start_offset, trajectory_time
from ..control.simulation.model import quaternion_to_yaw
from ..control.simulation.trajectory import TrajectoryError
from ..interface.msgconv import multidof_to_trajectory, path_to_trajectory
from .errors import BagError, BagNotFoundError, MissingTopicsError
from .typestore import jazzy_typestore

__all__ = ['BagError', 'BagNotFoundError', 'MissingTopicsError', 'PoseSeries', 'ReferenceSeries',
           'CommandSeries', 'RunData', 'BagData', 'read_bag', 'read_messages', 'open_reader',
           'check_bag', 'bag_location', 'mcap_is_complete', 'resolve_topics', 'pick_topic',
           'typestore_for', 'fast_fields', 'RUN_TOPICS', 'MCAP_MAGIC']

MCAP_MAGIC = b'\x89MCAP0\r\n'
#: Logical topics a tracking run needs (odom may be replaced by pose).
RUN_TOPICS = topics.RUN_TOPICS


# ---------------------------------------------------------------------------------------------
# Data

@dataclass(frozen=True)
class PoseSeries:
    """Robot pose by header stamp: ``t`` (s), x, y (m), th (rad), v = odom twist.linear.x (m/s).

    ``v`` is NaN when the pose comes from ``pose`` (PoseStamped has no twist).
    """

    stamp_ns: np.ndarray
    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    th: np.ndarray
    v: np.ndarray
    topic: str = ''
    receive_ns: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    frame_id: str = ''
    child_frame_id: str = ''

    def __len__(self) -> int:
        return int(self.t.size)


@dataclass(frozen=True)
class ReferenceSeries:
    """Reference by header stamp: position (m), velocity (m/s), acceleration (m/s^2)."""

    stamp_ns: np.ndarray
    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    vx: np.ndarray
    vy: np.ndarray
    ax: np.ndarray
    ay: np.ndarray
    source: str = ''           # where it came from: the reference topics or a Path topic
    #: per sample: 0 before the trajectory's start (waiting), 1 while it is active, 2 after
    #: its end (holding the end point at rest); None when unknown (reference samples)
    phase: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.t.size)


@dataclass(frozen=True)
class CommandSeries:
    """Commands by receive time: ``t`` (s), v = linear.x (m/s), w = angular.z (rad/s).

    ``stamp_ns`` is the header stamp of a TwistStamped command, else the receive time.
    """

    receive_ns: np.ndarray
    t: np.ndarray
    v: np.ndarray
    w: np.ndarray
    stamp_ns: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    stamped: bool = False
    topic: str = ''

    def __len__(self) -> int:
        return int(self.t.size)


@dataclass(frozen=True)
class RunData:
    """The arrays of a tracking run; ``t`` everywhere is seconds on the bag's clock."""

    pose: PoseSeries
    reference: ReferenceSeries
    commands: CommandSeries


@dataclass(frozen=True)
class BagData:
    """What :func:`read_bag` found.  Dict keys are the topic names stored in the bag."""

    path: Path
    msgtypes: dict[str, str]
    counts: dict[str, int]
    receive_ns: dict[str, np.ndarray]
    offered_qos: dict[str, list[Qos]]
    topic_map: dict[str, str]            # logical name (topics.ODOM ...) -> bag topic
    duplicates: dict[str, int]           # bag topic -> messages dropped as repeated stamps
    run: RunData
    missing: tuple[str, ...] = field(default=())

    @property
    def message_count(self) -> int:
        """Messages on all topics."""
        return sum(self.counts.values())

    def count(self, name: str) -> int:
        """Messages on a logical topic name (0 if absent).

        Parameters
        ----------
        name : str
            A logical name (``topics.ODOM``, ...) or a stored topic.

        Returns
        -------
        int
        """
        topic = self.topic_map.get(name, name)
        return self.counts.get(topic, 0)


# ---------------------------------------------------------------------------------------------
# Opening

def mcap_is_complete(path: str | os.PathLike[str]) -> bool:
    """True if the MCAP file starts and ends with the MCAP magic (i.e. it was closed).

    Parameters
    ----------
    path : path-like
        The MCAP file (unreadable or too short: False).

    Returns
    -------
    bool
    """
    p = Path(path)
    try:
        size = p.stat().st_size
        if size < 2 * len(MCAP_MAGIC):
            return False
        with p.open('rb') as f:
            head = f.read(len(MCAP_MAGIC))
            f.seek(size - len(MCAP_MAGIC))
            tail = f.read(len(MCAP_MAGIC))
    except OSError:
        return False
    return head == MCAP_MAGIC and tail == MCAP_MAGIC


def bag_location(path: str | os.PathLike[str]) -> Path:
    """``path`` as a :class:`~pathlib.Path` once it exists and, if a file, is an MCAP file.

    What every reader of a bag (and ``bag repair``) checks first; what the directory or
    file holds is checked by :func:`check_bag` and :func:`~.repair.repair_bag`.

    Parameters
    ----------
    path : path-like
        The bag directory the recorder created, or one ``.mcap`` file.

    Raises
    ------
    BagNotFoundError
        If ``path`` does not exist.
    BagError
        If it is a file without the ``.mcap`` suffix.
    """
    p = Path(path)
    if not p.exists():
        raise BagNotFoundError(f'bag directory {p} does not exist; pass the directory the '
                               'recorder created (it holds metadata.yaml and a .mcap file)')
    if p.is_file() and p.suffix != '.mcap':
        raise BagError(f'{p} is a file, not a bag directory; pass the directory that '
                       'holds metadata.yaml and the .mcap file (or a .mcap file)')
    return p


def check_bag(path: str | os.PathLike[str]) -> Path:
    """Check that ``path`` is a readable bag directory and return the path to open.

    That is the directory (with metadata.yaml) or, when metadata.yaml is
    missing but there is one complete MCAP file, that file.

    Parameters
    ----------
    path : path-like
        A bag directory or an MCAP file.

    Returns
    -------
    pathlib.Path

    Raises
    ------
    BagNotFoundError
        If ``path`` does not exist.
    BagError
        If it is neither a bag directory nor an MCAP file (or holds several MCAP files
        without metadata.yaml).
        If an MCAP file was not closed (``bag repair`` recovers it).
    """
    p = bag_location(path)
    if p.is_file():
        if not mcap_is_complete(p):
            raise BagError(
                f'{p} is not a complete MCAP file (no MCAP magic at both ends: truncated or not '
                f'MCAP). Run `nonfragile_tracker bag repair {p}` to recover what it holds.')
        return p
    meta = p / 'metadata.yaml'
    mcaps = sorted(p.glob('*.mcap'))
    if not meta.exists() and not mcaps:
        raise BagError(f'{p} is not a rosbag2 bag: it holds neither metadata.yaml nor a '
                       '.mcap file')
    for m in mcaps:
        if not mcap_is_complete(m):
            raise BagError(
                f'{m} is truncated: it has no MCAP summary/end magic, so the recorder did not '
                f'close it (killed?). Run `nonfragile_tracker bag repair {p}` to recover the '
                f'complete chunks into {p}_repaired, then read that bag.')
    if meta.exists():
        return p
    if len(mcaps) == 1:
        return mcaps[0]
    raise BagError(f'{p} has no metadata.yaml and {len(mcaps)} .mcap files; run '
                   f'`nonfragile_tracker bag repair {p}` to merge them into one bag')


def open_reader(path: str | os.PathLike[str]) -> Reader:
    """An opened rosbags ``Reader`` after :func:`check_bag`; close it when done.

    Parameters
    ----------
    path : path-like
        A bag directory or an MCAP file, checked by :func:`check_bag`.

    Returns
    -------
    rosbags.rosbag2.Reader
        Opened on what :func:`check_bag` returned (the directory, or the one MCAP file).

    Raises
    ------
    BagError
        As :func:`check_bag`, or :class:`.BagError` when rosbags cannot open it.
    """
    target = check_bag(path)
    try:
        reader = Reader(target)
        reader.open()
    except Exception as exc:  # noqa: BLE001 - rosbags/yaml/mcap raise many kinds
        hint = ''
        if target.is_file() or not (target / 'metadata.yaml').exists():
            hint = (f'; if it is an MCAP from another recorder, `nonfragile_tracker bag repair '
                    f'{path}` rewrites it as a rosbag2 bag')
        elif 'missing' in str(exc):
            hint = '; metadata.yaml names storage files that are not there'
        msg = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise BagError(f'{path} cannot be read as a rosbag2 bag: {msg}{hint}') from None
    return reader


def typestore_for(reader: Reader) -> Typestore:
    """The Jazzy typestore, plus the bag's own definitions of types it does not know.

    A bag from another system may carry custom messages; their ros2msg definitions are
    stored in the bag, so they are registered in a private copy of the typestore.

    Parameters
    ----------
    reader : rosbags.rosbag2.Reader
        An opened bag.

    Returns
    -------
    rosbags.typesys.store.Typestore
        The shared one when the bag has no unknown type, else a private copy.

    Raises
    ------
    BagError
        If a stored definition cannot be parsed.
    """
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore
    ts = jazzy_typestore()
    unknown = {c.msgtype: c.msgdef for c in reader.connections if c.msgtype not in ts.types}
    if not unknown:
        return ts
    own = get_typestore(Stores.ROS2_JAZZY)
    for msgtype, msgdef in unknown.items():
        text = msgdef.data if isinstance(msgdef, MessageDefinition) else str(msgdef)
        try:
            own.register(get_types_from_msg(text, msgtype))
        except Exception as exc:  # noqa: BLE001 - rosbags raises several parser errors
            raise BagError(f'message type {msgtype} is not a ROS 2 Jazzy type and its '
                           f'definition stored in the bag cannot be parsed ({exc})') from None
    return own


# ---------------------------------------------------------------------------------------------
# Topic names

def _namespace_of(topic: str, name: str) -> str | None:
    if topic == name:
        return ''                          # stored relative: same as the root namespace
    if topic.endswith('/' + name):
        return topic[:-len(name) - 1]
    return None


def resolve_topics(available: Iterable[str], names: Iterable[str],
                   namespace: str | None = None) -> dict[str, str]:
    """Map logical topic names to the stored topics (absent names are left out).

    A relative name ``n`` is looked up in ``namespace`` (``'/robot1'``: as ``/robot1/n``;
    the root: as stored, ``n``, or as ``/n``); without one, in the namespace that holds
    the most logical names of :data:`.topics.TYPES` (ties: the shorter, then the first).
    Absolute names (``/clock``) are looked up as they are.

    Parameters
    ----------
    available : iterable of str
        The stored topics.
    names : iterable of str
        Logical names (relative, ``odom``, or absolute, ``/clock``).
    namespace : str, optional
        The namespace of the relative names (``''`` or ``'/'``: the root); guessed
        when ``None``.

    Returns
    -------
    dict
        ``{logical name: stored topic}`` of the names found.
    """
    avail = set(available)
    names = list(names)
    if namespace is None:
        namespace = _namespace_scores(avail)[0][0]
    ns = '/' + namespace.strip('/') if namespace.strip('/') else ''
    out = {}
    for n in names:
        for cand in ((n,) if n.startswith('/') else (f'{ns}/{n}', n if not ns else None)):
            if cand and cand in avail:
                out[n] = cand
                break
    return out


def _namespace_scores(avail: Iterable[str]) -> list[tuple[str, int]]:
    """Namespaces by how many logical names of :data:`.topics.TYPES` they hold, most first.

    Ties: the shorter, then the first in name order; the root alone when none match.
    """
    score: dict[str, int] = {}
    for n in topics.TYPES:
        if n.startswith('/'):
            continue
        for t in avail:
            found = _namespace_of(t, n)
            if found is not None and (found == '' or found.startswith('/')):
                score[found] = score.get(found, 0) + 1
    return sorted(score.items(), key=lambda s: (-s[1], len(s[0]), s[0])) or [('', 0)]


def _describe(by_type: Mapping[str, str]) -> str:
    return ', '.join(f'{t} ({ty})' for t, ty in sorted(by_type.items())) or 'no topics'


def pick_topic(available: Mapping[str, str], name: str, types: Iterable[str], *, role: str,
               option: str, by_type: bool = True, namespace: str | None = None) -> str:
    """The stored topic for ``name``, of one of ``types`` (the rule of bag report and identify).

    ``name`` is looked up as :func:`resolve_topics` does (in ``namespace``, or in the
    namespace guessed from the whole bag, so a report and an identification of one bag
    read the same topics), then at the root; if it is absent and ``by_type``, the one
    topic of an accepted type is taken.  A tie of namespaces holding ``name``, a wrong
    type, several topics of the type or none raises :class:`.MissingTopicsError` naming the
    topics the bag has and ``option``.

    Parameters
    ----------
    available : mapping of str to str
        Stored topic -> message type.
    name : str
        Requested name (``cmd_vel``, ``/robot1/odom``).
    types : iterable of str
        Accepted message types.
    role, option : str
        For the messages: what the topic is (``'velocity commands'``) and the CLI
        option that sets it (``'--cmd-topic'``).
    by_type : bool
        Fall back to the one topic of an accepted type when ``name`` is absent.
    namespace : str, optional
        The namespace of a relative ``name``; guessed when ``None``.

    Returns
    -------
    str
    """
    types = tuple(types)
    want = ' or '.join(types)
    found = resolve_topics(available, [name], namespace).get(name)
    if found is None:
        found = resolve_topics(available, [name], '').get(name)
    if found is not None and namespace is None and not name.startswith('/'):
        scores = _namespace_scores(available)
        tied = [s for s, n in scores if n == scores[0][1]]
        matching = sorted(m for s in tied for m in resolve_topics(available, [name], s).values())
        if len(matching) > 1:
            raise MissingTopicsError(
                f'{role}: several topics match {name!r}: {", ".join(matching)}; choose one '
                f'with {option}', [name])
    if found is not None:
        if available[found] not in types:
            raise MissingTopicsError(
                f'{role}: topic {found} has type {available[found]}, expected {want}; pass '
                f'the right topic with {option} (the bag has {_describe(available)})', [name])
        return found
    if by_type:
        good = sorted(t for t, ty in available.items() if ty in types)
        if len(good) == 1:
            return good[0]
        if len(good) > 1:
            raise MissingTopicsError(
                f'{role}: the bag has no topic {name!r} and several of type {want}: '
                f'{", ".join(good)}; choose one with {option}', [name])
    raise MissingTopicsError(
        f'{role}: the bag has no topic {name!r}' + (f' and none of type {want}' if by_type
                                                    else '') +
        f'; it has {_describe(available)}. Record {name} ({want}) or name the topic with '
        f'{option}', [name])


# ---------------------------------------------------------------------------------------------
# Reading

# Fast path: the fields a report needs, read straight from little-endian CDR (about 10x
# faster than deserializing the message; the same numbers - test_bag_fast_cdr checks).
_U32 = struct.Struct('<I')
_STAMP = struct.Struct('<iI')
_D2 = struct.Struct('<2d')
_D7 = struct.Struct('<7d')


_FAST_TYPES = frozenset(('geometry_msgs/msg/Twist', 'nav_msgs/msg/Odometry',
                         'geometry_msgs/msg/PoseStamped', 'geometry_msgs/msg/TwistStamped',
                         'geometry_msgs/msg/AccelStamped'))


def _align8(pos: int) -> int:
    return 4 + ((pos - 4 + 7) & ~7)          # CDR alignment counts from after the 4-byte header


def _string_end(raw: bytes | memoryview, pos: int) -> int:
    pos = 4 + ((pos - 4 + 3) & ~3)
    return pos + 4 + int(_U32.unpack_from(raw, pos)[0])


def _fast_header(raw: bytes | memoryview) -> tuple[int, int]:
    """(stamp ns, position after the header) of a message that starts with a Header."""
    sec, nsec = _STAMP.unpack_from(raw, 4)
    return sec * 1_000_000_000 + nsec, _string_end(raw, 12)


def fast_fields(raw: bytes | memoryview, msgtype: str, command: bool = False
                ) -> tuple[Any, ...] | None:
    """The report's fields of a CDR message, or None when the fast path does not apply.

    Odometry -> (stamp, x, y, qx, qy, qz, qw, twist.linear.x); PoseStamped -> (stamp, x, y,
    qx, qy, qz, qw); TwistStamped / AccelStamped -> (stamp, linear.x, linear.y), or with
    ``command`` a TwistStamped -> (stamp, linear.x, angular.z); Twist -> (linear.x, angular.z).

    Parameters
    ----------
    raw : bytes
        The serialized message (CDR with its 4-byte header).
    msgtype : str
        Its ROS type (``nav_msgs/msg/Odometry``, ...).
    command : bool, optional
        Read a TwistStamped as a command (its angular.z).

    Returns
    -------
    tuple or None
        Stamps in ns, lengths in m, speeds in m/s and rad/s; None for another type or
        a big-endian message.
    """
    if msgtype not in _FAST_TYPES or len(raw) < 16 or raw[1] != 1:    # CDR_LE only
        return None
    if msgtype == 'geometry_msgs/msg/Twist':
        return struct.unpack_from('<d', raw, 4)[0], struct.unpack_from('<d', raw, 44)[0]
    stamp, pos = _fast_header(raw)
    if msgtype == 'nav_msgs/msg/Odometry':
        pos = _align8(_string_end(raw, pos))          # child_frame_id
        x, y, _, qx, qy, qz, qw = _D7.unpack_from(raw, pos)
        v = struct.unpack_from('<d', raw, pos + (7 + 36) * 8)[0]
        return stamp, x, y, qx, qy, qz, qw, v
    if msgtype == 'geometry_msgs/msg/PoseStamped':
        x, y, _, qx, qy, qz, qw = _D7.unpack_from(raw, _align8(pos))
        return stamp, x, y, qx, qy, qz, qw
    if command and msgtype == 'geometry_msgs/msg/TwistStamped':
        pos = _align8(pos)
        return (stamp, struct.unpack_from('<d', raw, pos)[0],
                struct.unpack_from('<d', raw, pos + 40)[0])
    if msgtype in ('geometry_msgs/msg/TwistStamped', 'geometry_msgs/msg/AccelStamped'):
        return (stamp, *_D2.unpack_from(raw, _align8(pos)))
    return None


def _stamp_ns(header: Any) -> int:
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def _connections_by_topic(reader: Reader) -> dict[str, Connection]:
    out: dict[str, Connection] = {}
    for c in reader.connections:
        out.setdefault(c.topic, c)
    return out


def read_messages(path: str | os.PathLike[str], topic: str, *, namespace: str | None = None
                  ) -> Iterator[tuple[int, Any]]:
    """Yield ``(timestamp_ns, message)`` of ``topic`` in bag order (receive time).

    ``topic`` is a stored name (``/odom``) or a logical one (``odom``).
    Messages are deserialized with the Jazzy typestore.

    Parameters
    ----------
    path : path-like
        A bag directory or an MCAP file.
    topic : str
        The topic.
    namespace : str, optional
        The namespace of a logical name (:func:`resolve_topics`).

    Yields
    ------
    (int, object)
        Receive time [ns] and the deserialized message.

    Raises
    ------
    MissingTopicsError
        If the bag has no such topic.
    """
    reader = open_reader(path)
    try:
        conns = [c for c in reader.connections if c.topic == topic]
        if not conns:
            found = resolve_topics((c.topic for c in reader.connections), [topic], namespace)
            conns = [c for c in reader.connections if c.topic == found.get(topic)]
        if not conns:
            raise MissingTopicsError(
                f'bag {path} has no topic {topic!r}; it has '
                f'{sorted({c.topic for c in reader.connections})}', [topic])
        ts = jazzy_typestore()
        for conn, timestamp, raw in reader.messages(connections=conns):
            yield timestamp, ts.deserialize_cdr(raw, conn.msgtype)
    finally:
        reader.close()


#: Accepted types of the command topic.
_CMD_VEL_TYPES = ('geometry_msgs/msg/Twist', 'geometry_msgs/msg/TwistStamped')
_EXPECTED_TYPES = {topics.ODOM: 'nav_msgs/msg/Odometry',
                   topics.POSE: 'geometry_msgs/msg/PoseStamped',
                   topics.REF_POSE: 'geometry_msgs/msg/PoseStamped',
                   topics.REF_TWIST: 'geometry_msgs/msg/TwistStamped',
                   topics.REF_ACCEL: 'geometry_msgs/msg/AccelStamped',
                   topics.CMD_VEL: _CMD_VEL_TYPES}
#: Message types accepted for the path (trajectory) topic, when the bag has one.
PATH_TYPE = 'nav_msgs/msg/Path'
#: Path topics used as the reference, in this order (the trajectory the tracker follows, then
#: the displayed reference); otherwise the bag's only Path topic.
PATH_TOPICS = ('trajectory', 'reference/path')
#: Trajectory messages a tracker follows (a lean recording keeps these instead of the
#: per-step samples), in the order the reader prefers them, with their types.
TRAJECTORY_TOPICS = ((topics.FOLLOWED_TRAJECTORY, 'trajectory_msgs/msg/MultiDOFJointTrajectory'),
                     (topics.TRAJECTORY_MULTIDOF, 'trajectory_msgs/msg/MultiDOFJointTrajectory'),
                     (topics.TRAJECTORY, PATH_TYPE))
_TRAJ_ROLE = 'trajectory message'


def _by_type(by_topic: dict[str, Connection], types: tuple[str, ...], taken: set[str]
             ) -> str | None:
    """The one topic of one of ``types`` not already taken (None if zero or several)."""
    found = [t for t, c in by_topic.items() if c.msgtype in types and t not in taken]
    return found[0] if len(found) == 1 else None


def _complete_topic_map(by_topic: dict[str, Connection], topic_map: dict[str, str],
                        overrides: dict[str, str] | None) -> dict[str, str]:
    """Stored names for the logical ones: ``overrides`` first, then by name, then by type.

    A bag from another system may name its odometry ``/wheel/odometry`` or its commands
    ``/robot/cmd_vel_stamped``: when the logical name is not found and exactly one topic
    of the right type is left, that topic is used.
    """
    out = dict(topic_map)
    for name, topic in (overrides or {}).items():
        if topic not in by_topic:
            raise MissingTopicsError(f'topic {topic!r} (given for {name}) is not in the bag; it '
                                     f'has {sorted(by_topic)}', [topic])
        out[name] = topic
    for name, types in ((topics.ODOM, ('nav_msgs/msg/Odometry',)),
                        (topics.CMD_VEL, _CMD_VEL_TYPES)):
        if name not in out:
            found = _by_type(by_topic, types, set(out.values()))
            if found is not None:
                out[name] = found
    return out


def _missing_run_topics(topic_map: dict[str, str]) -> list[str]:
    missing = []
    if topics.ODOM not in topic_map and topics.POSE not in topic_map:
        missing.append(f'{topics.ODOM} (or {topics.POSE})')
    missing += [n for n in RUN_TOPICS[1:] if n not in topic_map]
    return missing


def _slow_fields(msg: Any, name: str, timestamp: int) -> Any:
    """Like :func:`fast_fields` from a deserialized message: (fields, frames); a Path as it is.

    A TwistStamped command gives (stamp, v, w) - its angular.z, not linear.y.
    """
    frames = (str(getattr(getattr(msg, 'header', None), 'frame_id', '')),
              str(getattr(msg, 'child_frame_id', '')))
    if name == PATH_TYPE:
        return msg
    if name == topics.CMD_VEL:
        if hasattr(msg, 'header'):
            t = msg.twist
            return (_stamp_ns(msg.header), float(t.linear.x), float(t.angular.z)), frames
        return (float(msg.linear.x), float(msg.angular.z)), frames
    stamp = _stamp_ns(msg.header)
    if hasattr(msg, 'pose'):
        p = msg.pose.pose if hasattr(msg.pose, 'pose') else msg.pose
        q = p.orientation
        out: tuple[Any, ...] = (stamp, float(p.position.x), float(p.position.y),
                                q.x, q.y, q.z, q.w)
        if hasattr(msg, 'twist'):
            out += (float(msg.twist.twist.linear.x),)
        return out, frames
    vec = msg.twist.linear if hasattr(msg, 'twist') else msg.accel.linear
    return (stamp, float(vec.x), float(vec.y)), frames


def _path_reference(msg: Any, topic: str) -> ReferenceSeries:
    """A reference from a nav_msgs/Path.

    Positions at the poses' stamps, velocities and accelerations by finite differences
    (numpy.gradient, second order inside).
    """
    stamps: list[int] = []
    xs: list[float] = []
    ys: list[float] = []
    for ps in msg.poses:
        s = _stamp_ns(ps.header)
        if stamps and s <= stamps[-1]:
            continue                       # poses must advance in time
        stamps.append(s)
        xs.append(float(ps.pose.position.x))
        ys.append(float(ps.pose.position.y))
    st = np.array(stamps, dtype=np.int64)
    t = st * 1e-9
    x, y = np.array(xs), np.array(ys)
    if t.size >= 3:
        vx, vy = np.gradient(x, t), np.gradient(y, t)
        ax, ay = np.gradient(vx, t), np.gradient(vy, t)
    else:
        vx = vy = ax = ay = np.zeros_like(t)
    return ReferenceSeries(st, t, x, y, vx, vy, ax, ay, source=topic)


def _trajectory_reference(msgs: list[tuple[int, Any]], msgtype: str, topic: str,
                          stamps: np.ndarray, receive: np.ndarray, *,
                          start_tolerance: float = START_TOLERANCE,
                          rest_speed: float = REST_SPEED) -> ReferenceSeries:
    """The reference a lockstep tracker sampled from recorded trajectory messages.

    Each message is converted as the tracker converts it (:mod:`msgconv`) and sampled at
    each odometry stamp as :class:`control.simulation.follow.Follower` samples it
    (:func:`control.simulation.follow.trajectory_time`); a stamp uses the latest message received no
    later than its odometry (the first message before that); a trajectory first followed
    late is re-based as the Follower re-bases it
    (:func:`control.simulation.follow.start_offset`, the tracker's default
    ``start_tolerance``).  :class:`TrajectoryError` if a
    message cannot be converted (e.g. an untimed Path, whose times depend on the
    tracker's parameters).
    """
    built = []
    for _, msg in msgs:
        frame = str(msg.header.frame_id)
        if msgtype == PATH_TYPE:
            if msg.poses and all(int(p.header.stamp.sec) == 0 and int(p.header.stamp.nanosec) == 0
                                 for p in msg.poses):
                raise TrajectoryError(f'{topic}: an untimed Path (its times depend on the '
                                      "tracker's cruise_speed and max_accel)")
            built.append(path_to_trajectory(msg, frame=frame, source=topic))
        else:
            built.append(multidof_to_trajectory(msg, frame=frame, source=topic))
    recv = np.array([r for r, _ in msgs], dtype=np.int64)
    which = np.maximum(np.searchsorted(recv, receive, side='right') - 1, 0)
    rows = np.empty((stamps.size, 6))
    phase = np.empty(stamps.size, dtype=np.int8)
    offsets: dict[int, float] = {}       # message -> its re-basing (Follower's start rule)
    for i, (s, k) in enumerate(zip(stamps, which)):
        traj, origin = built[int(k)]
        t = trajectory_time(int(s), origin)
        if int(k) not in offsets and t >= traj.t_start:
            offsets[int(k)] = start_offset(traj, t, start_tolerance=start_tolerance,
                                           rest_speed=rest_speed)
        tt = t - offsets.get(int(k), 0.0)
        r = traj.sample(tt)
        rows[i] = (r.x, r.y, r.vx, r.vy, r.ax, r.ay)
        phase[i] = 0 if tt < traj.t_start else (2 if tt > traj.t_end else 1)
    x, y, vx, vy, ax, ay = (rows[:, i].copy() for i in range(6))
    return ReferenceSeries(stamps.copy(), stamps * 1e-9, x, y, vx, vy, ax, ay, source=topic,
                           phase=phase)


def read_bag(path: str | os.PathLike[str], *, strict: bool = True, namespace: str | None = None,
             topic_overrides: dict[str, str] | None = None) -> BagData:
    """Read a run: counts and receive times of every topic, and the run arrays.

    With ``strict`` (default) a bag without a pose (``odom`` or ``pose``), the
    three reference topics or ``cmd_vel`` raises :class:`.MissingTopicsError`
    naming the missing ones; otherwise the missing arrays are empty and
    listed in ``BagData.missing``.

    Bags from other systems: ``cmd_vel`` may be Twist or TwistStamped; odometry and
    commands under other names are found by type when unique, or named with
    ``topic_overrides`` (``{'odom': '/wheel/odometry', 'cmd_vel': '/cmd'}``).  When
    the reference topics are absent, a lean lockstep recording's reference is rebuilt
    from the recorded trajectory message (``trajectory_multidof``, else a timed
    ``trajectory`` Path) at each odometry stamp, with the tracker's own conversion and
    sampling; failing that, when a nav_msgs/Path topic exists, the reference is its last
    message (positions at the poses' stamps, velocities by differences).

    Parameters
    ----------
    path : path-like
        A bag directory or an MCAP file.
    strict : bool, optional
        Refuse a bag without the topics of a run.
    namespace : str, optional
        The namespace of the run's topics (:func:`resolve_topics`); guessed when
        ``None``.
    topic_overrides : dict, optional
        ``{logical name: stored topic}`` for topics under other names.

    Returns
    -------
    BagData

    Raises
    ------
    MissingTopicsError
        With ``strict``, naming the missing topics.
    BagError
        If the bag cannot be opened or a message cannot be read.
    """
    reader = open_reader(path)
    try:
        by_topic = _connections_by_topic(reader)
        plan = _plan(path, by_topic, namespace, topic_overrides, strict)
        scan = _scan(path, reader, by_topic, plan)
        msgtypes = {t: c.msgtype for t, c in by_topic.items()}
        offered = {t: list(c.ext.offered_qos_profiles) for t, c in by_topic.items()
                   if isinstance(c.ext, ConnectionExtRosbag2)}
    finally:
        reader.close()
    topic_map = plan.topic_map
    stamps = np.array(sorted(scan.pose_rows), dtype=np.int64)
    rows = np.array([scan.pose_rows[s] for s in stamps], dtype=float).reshape(-1, 4)
    precv = np.array([scan.pose_recv[s] for s in stamps], dtype=np.int64)
    pose = PoseSeries(stamps, stamps * 1e-9, rows[:, 0].copy(), rows[:, 1].copy(),
                      rows[:, 2].copy(), rows[:, 3].copy(), topic_map.get(plan.pose_name, ''),
                      receive_ns=precv, frame_id=scan.frames[0],
                      child_frame_id=scan.frames[1])
    reference = _run_reference(plan, scan, by_topic, stamps, precv)
    cmds = scan.cmds
    crow = np.array(cmds, dtype=float).reshape(-1, 4)
    cns = np.array([c[0] for c in cmds], dtype=np.int64)
    cst = np.array([c[3] for c in cmds], dtype=np.int64)
    commands = CommandSeries(cns, cns * 1e-9, crow[:, 1].copy(), crow[:, 2].copy(),
                             stamp_ns=cst, stamped=scan.cmd_stamped,
                             topic=topic_map.get(topics.CMD_VEL, ''))
    return BagData(path=Path(path), msgtypes=msgtypes,
                   counts={t: len(v) for t, v in scan.receive.items()},
                   receive_ns={t: np.array(v, dtype=np.int64) for t, v in scan.receive.items()},
                   offered_qos=offered, topic_map=topic_map, duplicates=scan.dup,
                   run=RunData(pose, reference, commands), missing=tuple(plan.missing))


@dataclass
class _Plan:
    """Which stored topic plays which part in a run (:func:`read_bag`)."""

    topic_map: dict[str, str]
    followed: str | None
    traj_topic: str | None
    path_topic: str | None
    missing: list[str]
    pose_name: str
    role: dict[str, str]


def _plan(path: Any, by_topic: dict[str, Connection], namespace: str | None,
          overrides: dict[str, str] | None, strict: bool) -> _Plan:
    """The topics of a run in a bag, checked for presence (with ``strict``) and type."""
    topic_map = resolve_topics(by_topic, list(topics.TYPES), namespace)
    topic_map = _complete_topic_map(by_topic, topic_map, overrides)
    path_topic = traj_topic = None
    followed = topic_map.get(topics.FOLLOWED_TRAJECTORY)
    if followed is not None and by_topic[followed].msgtype == TRAJECTORY_TOPICS[0][1]:
        traj_topic = followed        # what the tracker followed: before the samples
    elif any(n not in topic_map for n in (topics.REF_POSE, topics.REF_TWIST,
                                          topics.REF_ACCEL)):
        for logical, msgtype in TRAJECTORY_TOPICS:
            if logical in topic_map and by_topic[topic_map[logical]].msgtype == msgtype:
                traj_topic = topic_map[logical]
                break
        paths = [t for t, c in by_topic.items() if c.msgtype == PATH_TYPE]
        named = resolve_topics(paths, PATH_TOPICS, namespace)
        preferred = [named[n] for n in PATH_TOPICS if n in named]
        path_topic = preferred[0] if preferred else (paths[0] if len(paths) == 1 else None)
    missing = _missing_run_topics(topic_map)
    if path_topic is not None or traj_topic is not None:
        missing = [m for m in missing if not m.startswith('reference/')]
    if missing and strict:
        raise MissingTopicsError(
            f'bag {path} lacks topic(s) {", ".join(missing)} needed for a tracking run; '
            f'it has {sorted(by_topic) or "no topics"}. Record them (recorder parameter '
            '`topics`) or pass strict=False.', missing)
    for logical, expected in _EXPECTED_TYPES.items():
        topic = topic_map.get(logical)
        ok = (expected,) if isinstance(expected, str) else expected
        if topic is not None and by_topic[topic].msgtype not in ok:
            raise BagError(f'topic {topic} in {path} has type '
                           f'{by_topic[topic].msgtype}, expected {" or ".join(ok)}')
    pose_name = topics.ODOM if topics.ODOM in topic_map else topics.POSE
    role = {topic_map[n]: n for n in (pose_name, topics.REF_POSE, topics.REF_TWIST,
                                      topics.REF_ACCEL, topics.CMD_VEL) if n in topic_map}
    if path_topic is not None:
        role[path_topic] = PATH_TYPE
    if traj_topic is not None:
        role[traj_topic] = _TRAJ_ROLE
    return _Plan(topic_map, followed, traj_topic, path_topic, missing, pose_name, role)


@dataclass
class _Scan:
    """What one pass over a bag's messages collects (:func:`read_bag`)."""

    receive: dict[str, list[int]]
    pose_rows: dict[int, tuple[Any, ...]] = field(default_factory=dict)
    pose_recv: dict[int, int] = field(default_factory=dict)
    frames: list[str] = field(default_factory=lambda: ['', ''])
    ref_parts: dict[str, dict[int, tuple[Any, ...]]] = field(default_factory=lambda: {
        topics.REF_POSE: {}, topics.REF_TWIST: {}, topics.REF_ACCEL: {}})
    cmds: list[tuple[int, float, float, int]] = field(default_factory=list)
    cmd_stamped: bool = False
    last_path: Any = None
    dup: dict[str, int] = field(default_factory=dict)
    traj_msgs: list[tuple[int, Any]] = field(default_factory=list)


def _scan(path: Any, reader: Reader, by_topic: dict[str, Connection], plan: _Plan) -> _Scan:
    """Every message's receive time, and the run's rows of the topics in ``plan.role``."""
    ts = jazzy_typestore()
    role, pose_name, path_topic = plan.role, plan.pose_name, plan.path_topic
    out = _Scan({t: [] for t in by_topic})
    receive, pose_rows, pose_recv, frames = out.receive, out.pose_rows, out.pose_recv, out.frames
    ref_parts, cmds, dup = out.ref_parts, out.cmds, out.dup
    try:
        appenders: dict[int, Any] = {}
        for conn, timestamp, raw in reader.messages():
            key = id(conn)
            add = appenders.get(key)
            if add is None:
                add = appenders[key] = receive.setdefault(conn.topic, []).append
            add(timestamp)
            name = role.get(conn.topic)
            if name is None or conn.msgtype != by_topic[conn.topic].msgtype:
                continue
            if name == _TRAJ_ROLE:
                m_t = ts.deserialize_cdr(raw, conn.msgtype)
                out.traj_msgs.append((timestamp, m_t))
                if conn.topic == path_topic:
                    out.last_path = m_t
                continue
            fast = fast_fields(raw, conn.msgtype, name == topics.CMD_VEL) \
                if name != PATH_TYPE else None
            if fast is None:
                fast = _slow_fields(ts.deserialize_cdr(raw, conn.msgtype), name, timestamp)
                if name == PATH_TYPE:
                    out.last_path = fast
                    continue
                if name == pose_name and not frames[0]:
                    frames[:] = list(fast[1])
                fast = fast[0]
            elif name == pose_name and not frames[0]:
                m: Any = ts.deserialize_cdr(raw, conn.msgtype)
                frames[:] = [str(m.header.frame_id), str(getattr(m, 'child_frame_id', ''))]
            if name == topics.CMD_VEL:
                if len(fast) == 3:                  # TwistStamped: (stamp, v, w)
                    out.cmd_stamped = True
                    cmds.append((timestamp, fast[1], fast[2], fast[0]))
                else:
                    cmds.append((timestamp, fast[0], fast[1], timestamp))
                continue
            stamp = fast[0]
            if name == pose_name:
                target = pose_rows
                row: tuple[Any, ...] = (fast[1], fast[2], quaternion_to_yaw(*fast[3:7]),
                                        fast[7] if len(fast) > 7 else math.nan)
                if stamp not in pose_recv:
                    pose_recv[stamp] = timestamp
            else:
                target = ref_parts[name]
                row = (fast[1], fast[2])
            if stamp in target:
                dup[conn.topic] = dup.get(conn.topic, 0) + 1
            else:
                target[stamp] = row
    except (ReaderError, ValueError, IndexError, KeyError, AssertionError,
            struct.error, UnicodeDecodeError) as exc:
        raise BagError(f'{path}: a message cannot be read ({type(exc).__name__}: '
                       f'{exc}); the bag is damaged - try `nonfragile_tracker bag '
                       'repair`') from None
    return out


def _run_reference(plan: _Plan, scan: _Scan, by_topic: dict[str, Connection],
                   stamps: np.ndarray, precv: np.ndarray) -> ReferenceSeries:
    """The run's reference: its three topics, else the trajectory message, else the Path."""
    parts = scan.ref_parts
    common = set(parts[topics.REF_POSE]) & set(parts[topics.REF_TWIST]) \
        & set(parts[topics.REF_ACCEL])
    traj_topic = plan.traj_topic
    if (not common or traj_topic == plan.followed) and scan.traj_msgs and traj_topic is not None:
        try:
            return _trajectory_reference(scan.traj_msgs, by_topic[traj_topic].msgtype,
                                         traj_topic, stamps, precv)
        except TrajectoryError:
            pass                       # fall back to the Path by differences, if any
    if not common and scan.last_path is not None and plan.path_topic is not None:
        return _path_reference(scan.last_path, plan.path_topic)
    rstamps = np.array(sorted(common), dtype=np.int64)
    rrows = np.array([parts[topics.REF_POSE][s] + parts[topics.REF_TWIST][s]
                      + parts[topics.REF_ACCEL][s] for s in rstamps],
                     dtype=float).reshape(-1, 6)
    x, y, vx, vy, ax, ay = (rrows[:, i].copy() for i in range(6))
    return ReferenceSeries(rstamps, rstamps * 1e-9, x, y, vx, vy, ax, ay,
                           source=plan.topic_map.get(topics.REF_POSE, ''))
