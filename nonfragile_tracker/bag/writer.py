"""Write rosbag2 (metadata version 9, MCAP storage) bags from raw CDR messages.

:class:`BagWriter` wraps rosbags' rosbag2 ``Writer`` with the ROS 2 Jazzy typestore and adds
what a recorder needs: it never overwrites (:class:`~.errors.BagExistsError`), writes the
raw CDR bytes unchanged under their real message type and the publishers' offered QoS
profiles (:func:`make_qos`), and flushes small chunks while recording, so a killed recorder
loses little.  :func:`new_run_dir` makes a fresh run directory that is never reused.
Nothing here imports ROS (rclpy); only rosbags.

See doc/bags.md, section "Recording and golden bags".
"""
from __future__ import annotations

import os
import time
from collections.abc import Mapping, Sequence
from datetime import datetime
from enum import Enum
from pathlib import Path
from types import TracebackType
from typing import Any, Final, Union

from rosbags.interfaces import (Qos, QosDurability, QosHistory, QosLiveliness, QosReliability,
                                QosTime)
from rosbags.rosbag2 import StoragePlugin, Writer, WriterError
from rosbags.rosbag2.metadata import dump_qos_v9
from rosbags.rosbag2.storage_mcap import McapWriter
from rosbags.typesys import get_types_from_msg
from rosbags.typesys.store import Typestore

from ..interface import topics
from .errors import BagExistsError, BagError
from .typestore import jazzy_typestore

__all__ = ['BagError', 'BagExistsError', 'BagWriter', 'make_qos', 'default_qos', 'qos_to_dicts',
           'new_run_dir', 'jazzy_typestore', 'BAG_VERSION', 'DEFAULT_CHUNK_SIZE',
           'DEFAULT_FLUSH_PERIOD', 'INFINITE_NS']

#: rosbag2 metadata version written (ROS 2 Jazzy).
BAG_VERSION: Final = 9
#: Pending chunk size (bytes of uncompressed records) at which a chunk is written out.
DEFAULT_CHUNK_SIZE = 128 * 1024
#: Longest time (s) a written message may stay in memory before its chunk is written out.
DEFAULT_FLUSH_PERIOD = 1.0
#: rosbags' own hard limit: it closes a chunk by itself above 1 MiB.
_ROSBAGS_CHUNK_LIMIT = 2 ** 20
#: ``RMW_DURATION_INFINITE`` in nanoseconds (= sec 9223372036, nsec 854775807).
INFINITE_NS = 2 ** 63 - 1

QosSpec = Union[Qos, Mapping[str, Any]]
ConnectionSpec = Union[str, tuple[str, Sequence[QosSpec]]]


# ---------------------------------------------------------------------------------------------
# QoS


def _enum(kind: type[Enum], value: Any, what: str) -> Any:
    if isinstance(value, kind):
        return value
    if isinstance(value, bool):
        raise ValueError(f'QoS {what} must be a name or an integer, got {value!r}')
    if isinstance(value, int):
        try:
            return kind(value)
        except ValueError:
            pass
    elif isinstance(value, str):
        name = value.strip().upper()
        if name in kind.__members__:
            return kind.__members__[name]
    elif hasattr(value, 'name') and str(value.name).upper() in kind.__members__:
        return kind.__members__[str(value.name).upper()]     # e.g. an rclpy policy enum
    names = ', '.join(m.lower() for m in kind.__members__)
    raise ValueError(f'QoS {what} {value!r} is not one of: {names}')


def _time(ns: Any, what: str) -> QosTime:
    if isinstance(ns, QosTime):
        return ns
    if isinstance(ns, Mapping):
        return QosTime(int(ns['sec']), int(ns['nsec']))
    if isinstance(ns, bool) or not isinstance(ns, int) or ns < 0:
        raise ValueError(f'QoS {what} must be an integer number of nanoseconds >= 0, got {ns!r}')
    sec, nsec = divmod(min(ns, INFINITE_NS), 1_000_000_000)
    return QosTime(sec, nsec)


def make_qos(*, history: Any = 'keep_last', depth: int = topics.DEPTH,
             reliability: Any = 'reliable', durability: Any = 'volatile',
             deadline_ns: Any = 0, lifespan_ns: Any = 0, liveliness: Any = 'system_default',
             liveliness_lease_duration_ns: Any = 0,
             avoid_ros_namespace_conventions: bool = False) -> Qos:
    """A rosbags :class:`~rosbags.interfaces.Qos` from names or numbers.

    Policies are rosbag2 v9 names (case-insensitive: ``keep_last``, ``keep_all``,
    ``reliable``, ``best_effort``, ``volatile``, ``transient_local``,
    ``automatic``, ``system_default``, ``unknown`` ...), the rmw integer values,
    or any enum with such a ``name`` (rclpy's policies).  Durations are integer
    nanoseconds (0 = unspecified, :data:`INFINITE_NS` = infinite) or
    ``{'sec': s, 'nsec': ns}``.  In metadata.yaml (v9) a profile is stored as::

        - history: keep_last
          depth: 100
          reliability: reliable
          durability: volatile
          deadline: {sec: 0, nsec: 0}
          lifespan: {sec: 0, nsec: 0}
          liveliness: system_default
          liveliness_lease_duration: {sec: 0, nsec: 0}
          avoid_ros_namespace_conventions: false

    Parameters
    ----------
    history : str, int or enum, optional
        ``keep_last``, ``keep_all``, ...
    depth : int, optional
        History depth (>= 0).
    reliability : str, int or enum, optional
        ``reliable``, ``best_effort``, ...
    durability : str, int or enum, optional
        ``volatile``, ``transient_local``, ...
    deadline_ns, lifespan_ns : int or mapping, optional
        Durations [ns] (or ``{'sec': s, 'nsec': ns}``).
    liveliness : str, int or enum, optional
        ``automatic``, ``manual_by_topic``, ``system_default``, ...
    liveliness_lease_duration_ns : int or mapping, optional
        Duration [ns] (or ``{'sec': s, 'nsec': ns}``).
    avoid_ros_namespace_conventions : bool, optional
        The rmw flag of that name.

    Returns
    -------
    rosbags.interfaces.Qos

    Raises
    ------
    ValueError
        For an unknown policy name, a negative depth or a negative duration.
    """
    if isinstance(depth, bool) or not isinstance(depth, int) or depth < 0:
        raise ValueError(f'QoS depth must be an integer >= 0, got {depth!r}')
    return Qos(_enum(QosHistory, history, 'history'), depth,
               _enum(QosReliability, reliability, 'reliability'),
               _enum(QosDurability, durability, 'durability'),
               _time(deadline_ns, 'deadline'), _time(lifespan_ns, 'lifespan'),
               _enum(QosLiveliness, liveliness, 'liveliness'),
               _time(liveliness_lease_duration_ns, 'liveliness_lease_duration'),
               bool(avoid_ros_namespace_conventions))


def default_qos(topic: str) -> Qos:
    """What the nodes of this package offer on ``topic`` (used when the publisher is unknown).

    ``run_done`` is reliable + transient_local, depth 1; every other topic is
    reliable + volatile, keep_last :data:`.topics.DEPTH`.

    Parameters
    ----------
    topic : str
        The stored topic name (any namespace).

    Returns
    -------
    rosbags.interfaces.Qos
    """
    if topic.rstrip('/').endswith(topics.RUN_DONE):
        return make_qos(depth=1, durability='transient_local')
    return make_qos()


def _as_qos(item: QosSpec) -> Qos:
    if isinstance(item, Qos):
        return item
    if isinstance(item, Mapping):                   # a v9 metadata dict
        keys = dict(item)
        return make_qos(history=keys.get('history', 'keep_last'),
                        depth=int(keys.get('depth', topics.DEPTH)),
                        reliability=keys.get('reliability', 'reliable'),
                        durability=keys.get('durability', 'volatile'),
                        deadline_ns=keys.get('deadline', 0), lifespan_ns=keys.get('lifespan', 0),
                        liveliness=keys.get('liveliness', 'system_default'),
                        liveliness_lease_duration_ns=keys.get('liveliness_lease_duration', 0),
                        avoid_ros_namespace_conventions=bool(
                            keys.get('avoid_ros_namespace_conventions', False)))
    raise TypeError(f'offered QoS profile must be a rosbags Qos or a dict, got {item!r}')


def qos_to_dicts(profiles: Sequence[Qos]) -> list[dict[str, Any]]:
    """Profiles as the plain dicts stored in metadata.yaml v9 (see :func:`make_qos`).

    Parameters
    ----------
    profiles : sequence of rosbags.interfaces.Qos
        The offered profiles of a connection.

    Returns
    -------
    list of dict
    """
    return [dict(d) for d in dump_qos_v9(list(profiles))]


# ---------------------------------------------------------------------------------------------
# Run directories

def _check_run_name(name: str) -> str:
    if not isinstance(name, str) or not name.strip():
        raise BagError(f'run name must be a non-empty string, got {name!r}')
    seps = {'/', '\\', os.sep} | ({os.altsep} if os.altsep else set())
    if any(s in name for s in seps) or '..' in name or '\x00' in name or name == '.':
        raise BagError(
            f'run name {name!r} is not a plain directory name: it must not contain a path '
            "separator, '..' or NUL (a run directory never leaves its root). Use e.g. "
            "'circle_tau02'.")
    return name


def new_run_dir(root: str | os.PathLike[str], name: str | None = None) -> Path:
    """Create and return a fresh, empty run directory under ``root``.

    The name is ``name`` or ``run_YYYYmmdd_HHMMSS`` (local time); if that exists
    already, ``_1``, ``_2`` ... is appended - an existing directory is never
    reused.  Creation is atomic (``mkdir`` without ``exist_ok``), so two
    processes never get the same directory.  ``root`` is created if missing.
    Put the bag *inside* the run directory (e.g. ``<run>/bag``).

    Parameters
    ----------
    root : path-like
        The parent folder (created if missing).
    name : str, optional
        The directory's name; a local time stamp when ``None``.

    Returns
    -------
    pathlib.Path
        The new, empty directory.

    Raises
    ------
    BagError
        For a name with a path separator or ``..``.
        If no free name is found.
    """
    base = _check_run_name(name) if name is not None \
        else datetime.now().strftime('run_%Y%m%d_%H%M%S')
    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    for n in range(10_000):
        candidate = root / (base if n == 0 else f'{base}_{n}')
        try:
            candidate.mkdir()
        except FileExistsError:
            continue
        return candidate
    raise BagError(f'no free run directory name {base}_N under {root} (tried 10000); '
                   'clean up old runs or pass another name')


# ---------------------------------------------------------------------------------------------
# Writer

class BagWriter:
    """A rosbag2 v9 / MCAP bag being written; raw CDR messages in, unchanged.

    ``connections`` maps topic -> message type (``'nav_msgs/msg/Odometry'``)
    or -> ``(message type, offered QoS profiles)``; more topics can be added
    with :meth:`add_connection` at any time (e.g. lazily at a topic's first
    message).  Use as a context manager or call :meth:`close`; the bag is
    closed cleanly (MCAP summary + metadata.yaml) also when the ``with`` body
    raises, so what was recorded stays readable.  Not thread-safe.

    Flush policy (what is on disk when):

    * Messages are appended to an in-memory MCAP chunk.  The chunk is written
      to the file - and the file buffer flushed to the OS - when it holds
      ``chunk_size`` bytes (default 128 KiB; rosbags itself caps chunks at
      1 MiB), when a write finds the oldest unflushed message older than
      ``flush_period`` seconds (default 1 s; ``None`` disables), or on
      :meth:`flush` (a recorder calls it from a timer so idle topics are
      flushed too).  Schema and channel records travel in the chunk that
      follows their :meth:`add_connection`.
    * A process that is killed (SIGKILL) loses only the pending chunk: at most
      ``chunk_size`` bytes or ``flush_period`` seconds of messages.  The file
      then lacks its summary and end magic and there is no metadata.yaml;
      :func:`nonfragile_tracker.bag.repair.repair_bag` recovers the complete
      chunks.  Data handed to the OS survives a process kill, not a power cut
      (there is no fsync).
    * :meth:`close` writes the last chunk, the MCAP summary (schemas,
      channels, chunk indexes, statistics, footer) and then metadata.yaml.

    Parameters
    ----------
    path : path-like
        The bag directory to create (must not exist).
    connections : mapping, optional
        ``{topic: message type}`` or ``{topic: (message type, offered QoS profiles)}``.
    chunk_size : int, optional
        Bytes [B] of a chunk before it is written (capped at 1 MiB).
    flush_period : float or None, optional
        Age [s] of the oldest unflushed message that makes a write flush the chunk.
    typestore : rosbags.typesys.store.Typestore, optional
        Message definitions (default: the shared Jazzy one).
    custom_data : mapping, optional
        ``custom_data`` of metadata.yaml (values as strings).

    Raises
    ------
    BagExistsError
        If ``path`` exists.
    ValueError
        For a bad ``chunk_size`` or ``flush_period``.
    BagError
        If the bag cannot be created, or a connection is invalid.
    """

    def __init__(self, path: str | os.PathLike[str],
                 *, connections: Mapping[str, ConnectionSpec] | None = None,
                 chunk_size: int = DEFAULT_CHUNK_SIZE,
                 flush_period: float | None = DEFAULT_FLUSH_PERIOD,
                 typestore: Typestore | None = None,
                 custom_data: Mapping[str, str] | None = None) -> None:
        self.path = Path(path)
        if isinstance(chunk_size, bool) or not isinstance(chunk_size, int) or chunk_size < 1:
            raise ValueError(f'chunk_size must be an integer number of bytes >= 1, '
                             f'got {chunk_size!r}')
        if flush_period is not None and not (flush_period > 0):
            raise ValueError(f'flush_period must be > 0 s or None, got {flush_period!r}')
        if self.path.exists() or self.path.is_symlink():
            raise BagExistsError(f'{self.path} exists already; a bag is never overwritten. '
                                 'Choose a new output directory (or remove the old one).')
        self.chunk_size = min(chunk_size, _ROSBAGS_CHUNK_LIMIT)
        self.flush_period = flush_period
        self.typestore = typestore if typestore is not None else jazzy_typestore()
        self._writer = Writer(self.path, version=BAG_VERSION, storage_plugin=StoragePlugin.MCAP)
        for key, value in (custom_data or {}).items():
            self._writer.set_custom_data(str(key), str(value))
        try:
            self._writer.open()
        except WriterError as exc:
            if self.path.exists():
                raise BagExistsError(f'{self.path} exists already (created concurrently); a '
                                     'bag is never overwritten. Choose a new output '
                                     'directory.') from None
            raise BagError(f'cannot create bag {self.path}: {exc}') from None
        except OSError as exc:
            raise BagError(f'cannot create bag {self.path}: {exc.strerror or exc}. Check that '
                           'the parent directory is writable.') from None
        storage = self._writer.storage
        if not isinstance(storage, McapWriter) or not all(
                hasattr(storage, a) for a in ('chunk', 'close_chunk', 'bio', 'chunks')):
            self._writer.abort()
            raise BagError('rosbags changed its MCAP writer (no chunk/close_chunk/bio); this '
                           'module needs rosbags 0.11.x - pin rosbags==0.11.*')
        self._mcap: McapWriter = storage
        self._connections: dict[str, Any] = {}
        self.counts: dict[str, int] = {}
        self._closed = False
        self._pending_since: float | None = None      # monotonic time of oldest unflushed msg
        self._last_chunks = 0
        try:
            for topic, spec in (connections or {}).items():
                if isinstance(spec, str):
                    self.add_connection(topic, spec)
                else:
                    msgtype, qos = spec
                    self.add_connection(topic, msgtype, qos)
        except BaseException:
            self.close()                 # leave a valid (empty) bag, not a half-open file
            raise

    # ------------------------------------------------------------------ connections
    @property
    def mcap_path(self) -> Path:
        """The MCAP file inside the bag directory."""
        return Path(self._writer.storage.path) if self._writer.storage is not None \
            else self.path / f'{self.path.name}.mcap'

    @property
    def topics(self) -> dict[str, str]:
        """Message type of every connection added so far, by topic."""
        return {t: c.msgtype for t, c in self._connections.items()}

    @property
    def closed(self) -> bool:
        """Whether :meth:`close` has run."""
        return self._closed

    def has_connection(self, topic: str) -> bool:
        """Whether ``topic`` has a connection in this bag.

        Parameters
        ----------
        topic : str
            The stored topic name.

        Returns
        -------
        bool
        """
        return topic in self._connections

    def add_connection(self, topic: str, msgtype: str,
                       offered_qos_profiles: Sequence[QosSpec] | None = None,
                       *, msgdef: str | None = None) -> None:
        """Add ``topic`` with its message type and offered QoS (default: :func:`default_qos`).

        A type unknown to the Jazzy typestore needs ``msgdef`` (the ros2msg text,
        dependencies after ``===`` / ``MSG:`` lines, as stored in MCAP schemas).

        Parameters
        ----------
        topic : str
            The stored topic name (added once).
        msgtype : str
            Its ROS type (``nav_msgs/msg/Odometry``).
        offered_qos_profiles : sequence of Qos or dict, optional
            The publishers' QoS (:func:`make_qos` dicts accepted).
        msgdef : str, optional
            The ros2msg definition of a type the typestore does not know.

        Raises
        ------
        BagError
            If the bag is closed, the topic was added, or the type is unknown without
            a usable ``msgdef``.
        """
        self._check_open()
        if not isinstance(topic, str) or not topic:
            raise BagError(f'topic must be a non-empty string, got {topic!r}')
        if topic in self._connections:
            raise BagError(f'topic {topic!r} was added already (as '
                           f'{self._connections[topic].msgtype}); each topic is added once')
        if msgtype not in self.typestore.fielddefs:
            if msgdef is None:
                raise BagError(f'message type {msgtype!r} of topic {topic!r} is not a ROS 2 '
                               'Jazzy type known to rosbags; pass msgdef= with its definition')
            try:
                self.typestore.register(get_types_from_msg(msgdef, msgtype))
            except Exception as exc:
                raise BagError(f'cannot parse the definition of {msgtype!r}: {exc}') from None
        qos = [default_qos(topic)] if offered_qos_profiles is None \
            else [_as_qos(q) for q in offered_qos_profiles]
        self._connections[topic] = self._writer.add_connection(
            topic, msgtype, typestore=self.typestore, offered_qos_profiles=qos)
        self.counts[topic] = 0

    # ------------------------------------------------------------------ writing
    def write(self, topic: str, timestamp_ns: int, rawdata: bytes | bytearray | memoryview
              ) -> None:
        """Append one serialized (CDR) message received at ``timestamp_ns``; bytes unchanged.

        Parameters
        ----------
        topic : str
            A topic added with :meth:`add_connection`.
        timestamp_ns : int
            Receive time [ns], in ``[0, 2^64)``.
        rawdata : bytes-like
            The serialized message (CDR).

        Raises
        ------
        BagError
            If the bag is closed, the topic unknown, or a value of the wrong type.
        """
        self._check_open()
        conn = self._connections.get(topic)
        if conn is None:
            raise BagError(f'no connection for topic {topic!r}; add_connection({topic!r}, '
                           f'msgtype) first (topics so far: {sorted(self._connections)})')
        if isinstance(timestamp_ns, bool) or not isinstance(timestamp_ns, int) \
                or not 0 <= timestamp_ns < 2 ** 64:
            raise BagError(f'timestamp must be integer nanoseconds in [0, 2^64), got '
                           f'{timestamp_ns!r} on {topic!r}')
        if not isinstance(rawdata, (bytes, bytearray, memoryview)):
            raise BagError(f'rawdata must be bytes (serialized CDR), got {type(rawdata).__name__} '
                           f'on {topic!r}')
        self._writer.write(conn, timestamp_ns, bytes(rawdata))
        self.counts[topic] += 1
        storage = self._mcap
        now = time.monotonic()
        if len(storage.chunks) != self._last_chunks:      # rosbags closed a 1 MiB chunk itself
            self._last_chunks = len(storage.chunks)
            storage.bio.flush()
            self._pending_since = None
        if self._pending_since is None and storage.chunk.msgs:
            self._pending_since = now
        if storage.chunk.bio.tell() >= self.chunk_size or (
                self.flush_period is not None and self._pending_since is not None
                and now - self._pending_since >= self.flush_period):
            self.flush()

    def flush(self) -> bool:
        """Write the pending chunk (if it holds messages) and flush the file to the OS.

        Returns True if a chunk was written.
        """
        if self._closed:
            return False
        storage = self._mcap
        wrote = False
        if storage.chunk.msgs:
            storage.close_chunk()
            wrote = True
        self._last_chunks = len(storage.chunks)
        storage.bio.flush()
        self._pending_since = None
        return wrote

    @property
    def message_count(self) -> int:
        """Messages written so far, all topics."""
        return sum(self.counts.values())

    def close(self) -> None:
        """Write the last chunk, the MCAP summary and metadata.yaml.  Idempotent."""
        if self._closed:
            return
        self._closed = True
        try:
            self._writer.close()
        except OSError as exc:
            raise BagError(f'closing bag {self.path} failed: {exc}. The MCAP file may lack its '
                           f'summary: run `nonfragile_tracker bag repair {self.path}`') from None

    def _check_open(self) -> None:
        if self._closed:
            raise BagError(f'bag {self.path} is closed; open a new BagWriter to write more')

    def __enter__(self) -> BagWriter:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    def __repr__(self) -> str:
        state = 'closed' if self._closed else 'open'
        return f'BagWriter({str(self.path)!r}, {state}, {self.message_count} messages)'
