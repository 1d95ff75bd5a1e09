"""``recorder``: records the run's topics into a rosbag2 (v9, MCAP) bag, like ``ros2 bag record``.

Subscribes the topics of its ``topics`` parameter raw and writes their CDR bytes unchanged,
stamped with the node clock at reception; in lockstep it gates the plant's start
(``recorder/ready``), reports its progress for the plant's back-pressure and drains the run's
last steps before it closes the bag.  :class:`Recorder` is also used in process (composed
runs).

See doc/ros-interface.md, sections "recorder" (how it records, how it ends, in-process use)
and "Time and lockstep" (the start gate and back-pressure).
"""
from __future__ import annotations

import importlib
import struct
import sys
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

from rclpy.clock import Clock, ClockType
from rclpy.publisher import Publisher
from rclpy.serialization import deserialize_message
from rclpy.task import Future
from rclpy.timer import Timer
from std_msgs.msg import UInt64

from ..interface import topics
from ..bag.errors import BagError
from ..bag.writer import (DEFAULT_CHUNK_SIZE, DEFAULT_FLUSH_PERIOD, BagWriter, default_qos,
                          make_qos, new_run_dir)
from .common import DATA_QOS, LATCHED_QOS, AdapterNode, Param, StartupError, run, settings_from

if TYPE_CHECKING:
    from rosbags.interfaces import Qos

__all__ = ['Recorder', 'main', 'LOCKSTEP_TOPICS', 'import_message', 'qos_from_rclpy']

#: Topics whose S+1 samples the recorder waits for after ``run_done`` = S.
LOCKSTEP_TOPICS = topics.LOCKSTEP_TOPICS
#: Topics whose subscriptions must have matched a publisher before the gate opens.
_GATED = frozenset(topics.LOCKSTEP_TOPICS) | {topics.CLOCK}
#: ... in real time (the recorder without sim time).
_GATED_REALTIME = frozenset({topics.ODOM, topics.CMD_VEL})
_STAMPED = {topics.ODOM, topics.POSE, topics.REF_POSE, topics.REF_TWIST, topics.REF_ACCEL}
#: Topics with one message per step whose latest stamp is the recorder's progress.
_PER_STEP = (topics.CLOCK, topics.POSE, topics.REF_POSE, topics.REF_TWIST, topics.REF_ACCEL)
#: Topics with one message per odometry sample (fewer than steps with odom_rate/latency).
_PER_ODOM = (topics.ODOM, topics.CMD_VEL)
#: The progress goes out every this many messages of a paced topic (and on a 20 ms timer).
PROGRESS_EVERY = 10
#: Progress that never holds a plant back (nothing recorded to pace by).
_NO_PACING = (1 << 63) - 1
_RUNS_ROOT = 'runs'

PARAMS = [
    Param('output', '', 'bag directory to create (never overwritten; relative to the working '
          'directory); empty: a new run directory runs/run_YYYYmmdd_HHMMSS[_N] with the bag in '
          'its subdirectory "bag"', read_only=True),
    Param('enable_stamped_cmd_vel', False, 'cmd_vel is geometry_msgs/TwistStamped (as the '
          'tracker publishes it with the same parameter)', read_only=True),
    Param('topics', list(topics.TYPES), 'topics to record (names of '
          'nonfragile_tracker.interface.topics; relative names resolve in the node '
          'namespace)', read_only=True),
    Param('drain_timeout', 5.0, 'after run_done: longest wait (wall s) for the last messages',
          low=0.0, high=3600.0, read_only=True),
    Param('chunk_size', DEFAULT_CHUNK_SIZE, 'write a chunk to disk when it holds this many '
          'bytes (1 .. 1048576)', read_only=True),
    Param('flush_period', DEFAULT_FLUSH_PERIOD, 'write pending messages to disk at least this '
          'often (wall s)', low=0.01, high=3600.0, read_only=True),
    Param('lockstep_gate', False, 'start gate: publish recorder/ready once the '
          'subscription of every recorded lockstep topic (with use_sim_time: odom, pose, '
          'reference samples, cmd_vel, /clock; else odom and cmd_vel) has matched its '
          'publisher (a plant with '
          'lockstep_recorder starts the run only then, in lockstep and in real time, so '
          'nothing is missed)', read_only=True),
    Param('gate_timeout', 30.0, 'lockstep_gate: announce readiness anyway after this long '
          '(wall s), with a warning naming the unmatched topics', low=0.0, high=3600.0,
          read_only=True),
]

_DATA_QOS, _LATCHED_QOS = DATA_QOS, LATCHED_QOS        # the same profiles as the publishers


def import_message(msgtype: str) -> type:
    """The rclpy message class of ``'pkg/msg/Name'`` (``importlib`` on ``pkg.msg``).

    Parameters
    ----------
    msgtype : str
        E.g. ``nav_msgs/msg/Odometry``.

    Returns
    -------
    type

    Raises
    ------
    StartupError
        If the name is malformed or the package is not installed.
    """
    parts = msgtype.split('/')
    if len(parts) != 3 or parts[1] != 'msg' or not all(parts):
        raise StartupError(f'message type {msgtype!r} is not of the form pkg/msg/Name')
    try:
        return cast(type, getattr(importlib.import_module(f'{parts[0]}.msg'), parts[2]))
    except (ImportError, AttributeError):
        raise StartupError(f'message type {msgtype} is not installed (cannot import '
                           f'{parts[0]}.msg.{parts[2]}); source the ROS environment') from None


def qos_from_rclpy(profile: Any) -> Qos:
    """An offered rclpy ``QoSProfile`` as the rosbags ``Qos`` stored in the bag (v9).

    Parameters
    ----------
    profile : rclpy.qos.QoSProfile
        As offered by a publisher (``get_publishers_info_by_topic``).

    Returns
    -------
    rosbags Qos
    """
    return make_qos(history=profile.history, depth=int(profile.depth),
                    reliability=profile.reliability, durability=profile.durability,
                    deadline_ns=int(profile.deadline.nanoseconds),
                    lifespan_ns=int(profile.lifespan.nanoseconds),
                    liveliness=profile.liveliness,
                    liveliness_lease_duration_ns=int(
                        profile.liveliness_lease_duration.nanoseconds),
                    avoid_ros_namespace_conventions=bool(profile.avoid_ros_namespace_conventions))


def _header_stamp_ns(raw: bytes) -> int | None:
    """Header stamp of a CDR message whose first field is a std_msgs/Header."""
    if len(raw) < 12:
        return None
    fmt = '<iI' if raw[1] & 1 else '>iI'          # encapsulation: 0x0001 = CDR little endian
    sec, nsec = struct.unpack_from(fmt, raw, 4)
    return int(sec) * 1_000_000_000 + int(nsec)


@dataclass(frozen=True)
class RecorderSettings:
    """The recorder's validated parameters (see ``PARAMS``)."""

    topics: tuple[str, ...]
    output: str
    chunk_size: int
    flush_period: float
    drain_timeout: float
    lockstep_gate: bool
    gate_timeout: float
    stamped_cmd_vel: bool


def recorder_settings(values: dict[str, Any]) -> RecorderSettings:
    """Validate the recorder's parameter values; InputError if bad.

    Parameters
    ----------
    values : dict
        ``PARAMS`` by name.

    Returns
    -------
    RecorderSettings

    Raises
    ------
    StartupError
        A ``chunk_size`` outside 1 byte .. 1 MiB, an unknown or no topic.
    """
    chunk = values['chunk_size']
    if not 1 <= chunk <= 2 ** 20:
        raise StartupError(f'chunk_size must be 1 .. 1048576 bytes, got {chunk}')
    return settings_from(RecorderSettings, values, topics=tuple(_topic_list(values['topics'])),
                         stamped_cmd_vel=values['enable_stamped_cmd_vel'])


def _topic_list(values: Iterable[str]) -> list[str]:
    names: list[str] = []
    for raw in values:
        name = raw if raw in topics.TYPES else raw.lstrip('/')
        if name not in topics.TYPES:
            raise StartupError(f'unknown topic {raw!r} in parameter topics; known '
                               f'topics: {", ".join(topics.TYPES)}')
        if name not in names:
            names.append(name)
    if not names:
        raise StartupError('parameter topics is empty; name at least one topic')
    return names


class Recorder(AdapterNode[RecorderSettings]):
    """Raw-CDR recorder node; ``done`` completes after a ``run_done`` drain (or on close).

    Parameters
    ----------
    node_name : str, optional
        ``recorder``.
    **node_kwargs
        rclpy ``Node`` keyword arguments (:class:`~nonfragile_tracker.nodes.common.AdapterNode`).
    """

    def __init__(self, node_name: str = 'recorder', **node_kwargs: Any):
        super().__init__(node_name, **node_kwargs)
        self.writer: BagWriter | None = None
        self._flush_timer: Timer | None = None
        self._drain_timer: Timer | None = None
        self.done: Future = Future()
        try:
            self.config = self.bind_parameters(PARAMS, recorder_settings)
            self._setup()
        except BaseException:
            if self.writer is not None:
                self.writer.close()
            super().destroy_node()
            raise

    def _setup(self) -> None:
        cfg = self.config
        self.counts: dict[str, int] = {}
        self.stamps: dict[str, set[int]] = {}
        self.final_step: int | None = None
        self.odom_count: int | None = None     # odometry messages the plant says it sent
        self.repeats = 0                  # lockstep_gate: republished steps not written again
        self._drain_deadline: float | None = None
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)

        names = list(cfg.topics)
        self.bag_path = self._output_path(cfg.output)
        self._msgtypes = dict(topics.TYPES)
        if cfg.stamped_cmd_vel:
            self._msgtypes[topics.CMD_VEL] = topics.CMD_VEL_STAMPED_TYPE
        self._types = {n: import_message(self._msgtypes[n]) for n in names}
        try:
            self.writer = BagWriter(self.bag_path, chunk_size=cfg.chunk_size,
                                    flush_period=cfg.flush_period,
                                    custom_data={'recorder': self.get_fully_qualified_name()})
        except BagError as exc:
            raise StartupError(f'recorder: {exc}') from None
        # back-pressure: the latest stamp per paced topic; their minimum is the progress
        paced = [n for n in _PER_STEP if n in names] or \
            [n for n in (topics.ODOM,) if n in names]
        self._latest: dict[str, int] = {n: -1 for n in paced}
        self._paced_count = 0
        self._progress_sent = -1
        self._subs: dict[str, Any] = {}
        self._resolved: dict[str, str] = {}
        for name in names:
            self.counts[name] = 0
            if name in _STAMPED:
                self.stamps[name] = set()
            self._subscribe(name)
        self._gate_timer: Timer | None = None
        self.pub_ready: Publisher | None = None
        self.pub_progress: Publisher | None = None
        self.ready = not cfg.lockstep_gate
        if cfg.lockstep_gate:
            self.pub_ready = self.create_publisher(UInt64, topics.RECORDER_READY, _LATCHED_QOS)
            self.pub_progress = self.create_publisher(UInt64, topics.RECORDER_PROGRESS,
                                                      _DATA_QOS)
            self._gate_started = self._steady.now()
            self._gate_timer = self.create_timer(0.02, self._check_gate, clock=self._steady)
            self._progress_timer = self.create_timer(0.02, self._publish_progress,
                                                     clock=self._steady)
        self.create_subscription(UInt64, topics.ODOM_COUNT, self._on_odom_count, _LATCHED_QOS)
        # run_done: recorded and handled by one subscription (so it is in the bag before the
        # drain can close it); a deserialized one if it is not recorded
        self._done_sub = None if topics.RUN_DONE in names else self.create_subscription(
            UInt64, topics.RUN_DONE, self._on_run_done, _LATCHED_QOS)
        self._flush_timer = self.create_timer(cfg.flush_period, self._flush, clock=self._steady)
        self.log('info', f'recording {len(names)} topics to {self.bag_path}: '
                         f'{", ".join(self._resolved[n] for n in names)}')

    # ------------------------------------------------------------------ setup
    def _subscribe(self, name: str) -> None:
        qos = _LATCHED_QOS if name in (topics.RUN_DONE, topics.TRAJECTORY, topics.REF_PATH,
                                       topics.TRAJECTORY_MULTIDOF,
                                       topics.FOLLOWED_TRAJECTORY, topics.TUNING) \
            else _DATA_QOS
        sub = self.create_subscription(self._types[name], name, self._make_callback(name),
                                       qos, raw=True)
        self._subs[name] = sub
        self._resolved[name] = sub.topic_name

    def _check_gate(self) -> None:
        """Open the lockstep gate: announce readiness once our subscriptions are matched.

        DDS matching is per side: a publisher counting our subscription (what the plant
        sees) does not mean that our subscription has matched the publisher - until it
        has, its samples are dropped here.  So the recorder says when its own side is
        matched, for every recorded lockstep topic, and the plant waits for that.
        """
        # real time (no sim time): the loop's odometry and commands (nobody publishes /clock,
        # and a reference that publishes a trajectory may publish no samples)
        gated = _GATED if self.get_parameter('use_sim_time').value else \
            _GATED_REALTIME
        waiting = [self._resolved[n] for n, sub in self._subs.items()
                   if n in gated and sub.get_publisher_count() < 1]
        elapsed = (self._steady.now() - self._gate_started).nanoseconds * 1e-9
        if waiting and elapsed < self.config.gate_timeout:
            return
        if waiting:
            self.log('warn', f'gate timeout: no publisher matched yet on '
                             f'{", ".join(waiting)}; announcing readiness anyway')
        if self._gate_timer is not None:
            self._gate_timer.cancel()
        self.ready = True
        if self.pub_ready is not None:
            self.pub_ready.publish(UInt64(data=len(self._subs)))
        self.log('info', 'lockstep gate open: every recorded lockstep topic matched')

    @staticmethod
    def _output_path(output: str) -> Path:
        if output:
            path = Path(output).expanduser()
            if path.exists():
                raise StartupError(f'recorder: output {path} exists already; a bag is never '
                                   'overwritten. Pass a new directory (or leave output empty '
                                   'for a fresh run directory).')
            return path
        return new_run_dir(_RUNS_ROOT) / 'bag'

    # ------------------------------------------------------------------ recording
    def _make_callback(self, name: str) -> Callable[[bytes], None]:
        topic_stamps = self.stamps.get(name)
        is_done = name == topics.RUN_DONE
        skip_repeats = self.config.lockstep_gate and topic_stamps is not None
        latest = self._latest if name in self._latest and self.config.lockstep_gate else None

        def callback(raw: bytes) -> None:
            writer = self.writer
            if writer is None or writer.closed:
                return
            stamp = _header_stamp_ns(raw) if topic_stamps is not None or latest is not None \
                else None
            if latest is not None and stamp is not None and stamp > latest[name]:
                latest[name] = stamp
                self._paced_count += 1
                if self._paced_count % PROGRESS_EVERY == 0:
                    self._publish_progress()
            if skip_repeats and topic_stamps is not None and stamp in topic_stamps:
                self.repeats += 1          # a lockstep step republished: recorded once
                return
            topic = self._resolved[name]
            if not writer.has_connection(topic):
                writer.add_connection(topic, self._msgtypes[name], self._offered_qos(name))
                self.log('info', f'first message on {topic}')
            writer.write(topic, self.get_clock().now().nanoseconds, raw)
            self.counts[name] += 1
            if topic_stamps is not None and stamp is not None:
                topic_stamps.add(stamp)
            if is_done:
                self._on_run_done(deserialize_message(raw, UInt64))
            elif self.final_step is not None and self._drained():
                self._finish()
        return callback

    def _offered_qos(self, name: str) -> list[Qos]:
        try:
            infos = self.get_publishers_info_by_topic(self._resolved[name])
            profiles = [qos_from_rclpy(i.qos_profile) for i in infos]
        except Exception as exc:          # noqa: BLE001 - never lose data over QoS metadata
            if not self.stopping:         # else the shutdown took it: nothing to report
                self.log('warn', f'offered QoS of {self._resolved[name]} unavailable '
                                 f'({exc}); storing the package defaults')
            profiles = []
        return profiles or [default_qos(name)]

    def _flush(self) -> None:
        if self.writer is not None and not self.writer.closed:
            self.writer.flush()

    def _publish_progress(self) -> None:
        """Tell the plant how far every paced topic has been recorded (back-pressure)."""
        if self.pub_progress is None or self.finished:
            return
        progress = min(self._latest.values()) if self._latest else _NO_PACING
        if progress != self._progress_sent and progress >= 0:
            self._progress_sent = progress
            self.pub_progress.publish(UInt64(data=progress))

    # ------------------------------------------------------------------ run_done
    def _received(self, name: str) -> int:
        return len(self.stamps[name]) if name in self.stamps else self.counts.get(name, 0)

    def _needed(self, name: str) -> int:
        """Samples of ``name`` the run produced: S+1 per step; odom/cmd_vel as announced."""
        assert self.final_step is not None
        if name in _PER_ODOM and self.odom_count is not None:
            return self.odom_count
        return self.final_step + 1

    def _shortfalls(self) -> dict[str, int]:
        if self.final_step is None:
            return {}
        short = {n: self._needed(n) - self._received(n) for n in LOCKSTEP_TOPICS
                 if n in self.counts and self._received(n) < self._needed(n)}
        # a lean bag (no per-step samples) is only readable with the trajectory that was
        # followed: a transient-local message, which arrives once discovery has matched its
        # publisher - possibly after a short run's last step
        traj = [n for n in (topics.TRAJECTORY, topics.TRAJECTORY_MULTIDOF) if n in self.counts]
        if traj and topics.REF_POSE not in self.counts and not any(
                self._received(n) for n in traj):
            short[traj[-1]] = 1
        return short

    def _on_odom_count(self, msg: UInt64) -> None:
        self.odom_count = int(msg.data)
        if self.final_step is not None and not self.finished and self._drained():
            self._finish()

    def _drained(self) -> bool:
        return not self._shortfalls()

    def _on_run_done(self, msg: UInt64) -> None:
        if self.final_step is not None or self.finished:
            return
        self.final_step = int(msg.data)
        timeout = self.config.drain_timeout
        self._drain_deadline = time.monotonic() + timeout
        odom = '' if self.odom_count is None else f' ({self.odom_count} odom/cmd_vel)'
        self.log('info', f'run_done: last step {self.final_step}; waiting up to {timeout} s '
                         f'for {self.final_step + 1} samples per lockstep topic{odom}')
        if self._drained():
            self._finish()
        else:
            self._drain_timer = self.create_timer(0.05, self._check_drain, clock=self._steady)

    def _check_drain(self) -> None:
        if self.finished:
            return
        deadline = self._drain_deadline
        if self._drained() or (deadline is not None and time.monotonic() >= deadline):
            self._finish()

    def _finish(self) -> None:
        if self.finished:
            return
        short = self._shortfalls()
        got = ', '.join(f'{self._resolved[n]} {self._received(n)}' for n in self.counts)
        if short:
            miss = ', '.join(f'{self._resolved[n]} short by {k}' for n, k in short.items())
            self.log('warn', f'run_done {self.final_step}: drain timeout '
                             f'({self.config.drain_timeout} s) with {miss}; got {got}')
        else:
            self.log('info', f'run_done {self.final_step}: all samples received ({got}; '
                             f'{self.repeats} republished samples not written again)')
        self.close()

    # ------------------------------------------------------------------ closing
    def close(self) -> None:
        """Close the bag (MCAP summary + metadata.yaml) and complete ``done``.  Idempotent."""
        if self.finished:
            return
        self.finished = True
        for timer in (self._flush_timer, self._drain_timer,
                      getattr(self, '_progress_timer', None)):
            if timer is not None:
                timer.cancel()
        writer, self.writer = self.writer, None
        if writer is not None:
            try:
                writer.close()
                self.log('info', f'bag closed: {writer.path} ({writer.message_count} messages)')
            except BagError as exc:
                self.exit_code = 1
                self.log('error', str(exc))
            if not self.done.done():
                self.done.set_result(dict(self.counts))


#: Console entry point of the recorder node: ``main(args)`` is ``run(Recorder, args)``
#: (:func:`~nonfragile_tracker.nodes.common.run`: the exit code).
main = partial(run, Recorder)


if __name__ == '__main__':
    # `python -m nonfragile_tracker.nodes.recorder` is the console script's process: the
    # entry's signal handling, stack dumps on SIGUSR1 and tear-down deadline
    from nonfragile_tracker.nodes.entry import main as node_main
    sys.exit(node_main('recorder', sys.argv))
