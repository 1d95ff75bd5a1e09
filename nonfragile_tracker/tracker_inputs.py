"""The tracker's input rules, ROS-free: which messages it takes and when a command is due.

One home for the rules the tracker node (:mod:`nonfragile_tracker.nodes.tracker`) applies
to its inputs, which a bag replay (:mod:`nonfragile_tracker.bag.replay`) must apply the
same way to reproduce the node's commands.  Both build a :class:`TrackerInputs` from the
tracker's parameters (:func:`input_rules`) and feed it the messages:

* **odometry** is taken in the odometry frame (parameter ``odom_frame``) only; a stamp
  equal to the last one is the same step (ignored, not counted), an earlier one is
  refused; a stamp further ahead than ``max_stamp_jump`` re-initialises the compensator
  (counted in ``jumps``).  Its pose must be finite with a unit quaternion (else refused,
  and the odometry is dropped until the next one).
* **reference samples** (pose, twist, accel) are taken in the odometry frame only and
  must be finite.  Real time: each odometry is answered with the latest parts.
  Lockstep: parts are kept by stamp (at most :data:`REF_BUFFER` stamps) until the
  odometry of that stamp is in, and each stamp is answered once.
* **trajectories** (nav_msgs/Path, trajectory_msgs/MultiDOFJointTrajectory) are
  converted in the odometry frame (:func:`msgconv.path_to_trajectory`: an untimed Path
  gets the ``cruise_speed``/``max_accel`` time law), re-timed within the base's limits
  unless ``retime`` is off, and adopted as a new run of
  :class:`~nonfragile_tracker.control.follow.Follower`; an invalid one is refused and the
  previous one stays.  Once a trajectory is adopted every odometry stamp is answered
  from it (the reference samples are no longer used; with ``wait_for_trajectory`` they
  never are).  A trajectory refused at its start (too far from the robot) is counted as
  refused too.
* **staleness** (real time): while :attr:`TrackerInputs.stopped` is set no command is
  computed; :func:`stale_inputs` says which inputs are older than ``input_timeout``.

Refused inputs are counted (``rejected``; ``ignored`` by reason) and handed to
``on_reject`` (the node logs them).  The node decides what is ROS-only: when to answer
in lockstep (cmd_vel's matched subscribers), the clock, the re-timing thread, logs and
outputs.

Messages are duck-typed (the fields are read by name), so rclpy messages (the node) and
rosbags' deserialized ones (the replay) are taken alike.  No rclpy or rosbags import.

Layer: ``conversions`` (test/test_architecture.py), next to :mod:`msgconv`, whose message
readers it applies: it reads messages, so it cannot live in ``control`` (which knows no
messages), and both ``bag`` (the replay) and ``nodes`` (the tracker) sit above it, so
neither imports the other for it.
"""
from __future__ import annotations

import copy
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, NamedTuple

from . import topics
from .control.simulation.follow import (MAX_START_DISTANCE, REST_SPEED, START_TOLERANCE, Follower,
                             trajectory_time)
from .control.simulation.limits import (ACCEL_FRACTION, MIN_ACCEL_FRACTION, Limits,
                                        valid_accel_fraction, within_limits)
from .control.simulation.loop import Command, Tracker, TrackerConfig
from .control.simulation.reference import RefSample
from .control.simulation.trajectory import Trajectory, TrajectoryError
from .errors import InputError
from .msgconv import (multidof_to_trajectory, path_to_trajectory, pose_from_odom,
                      reference_from_msgs, stamp_ns)

__all__ = ['MODES', 'REF_BUFFER', 'INPUT_DEFAULTS', 'TRAJECTORY_KINDS', 'InputRules',
           'input_rules', 'Rejection', 'Step', 'TrackerInputs', 'stale_inputs']

#: The tracker's modes: one command per odometry stamp (lockstep) or per odometry message.
MODES = ('lockstep', 'realtime')
#: Lockstep: reference samples kept by stamp while waiting for the odometry of that time.
REF_BUFFER = 1000
#: The tracker parameters the rules read, with the node's defaults (the node declares
#: them with these values; the replay uses them where a parameter file is silent).
INPUT_DEFAULTS: dict[str, Any] = {
    'odom_frame': topics.ODOM_FRAME, 'max_stamp_jump': 1.0, 'wait_for_trajectory': False,
    'cruise_speed': 0.5, 'max_accel': 0.5, 'retime': True, 'rest_speed': REST_SPEED,
    'start_tolerance': START_TOLERANCE, 'max_start_distance': MAX_START_DISTANCE,
    'trajectory_accel_fraction': ACCEL_FRACTION,
}
#: Trajectory messages, by kind: ``path`` (nav_msgs/Path), ``multidof``
#: (trajectory_msgs/MultiDOFJointTrajectory).
TRAJECTORY_KINDS = ('path', 'multidof')


@dataclass(frozen=True)
class InputRules:
    """The settings of the input rules (the tracker's parameters of the same meaning).

    Parameters
    ----------
    mode : str
        ``lockstep`` or ``realtime``.
    frame : str
        The odometry frame (``odom_frame``): odometry, reference samples and trajectories
        in another frame are refused.
    max_stamp_jump : float
        An odometry stamp further ahead than this (s) re-initialises the compensator.
    wait_for_trajectory : bool
        Answer only from a trajectory (never from reference samples).
    cruise_speed, max_accel : float
        Time law of an untimed nav_msgs/Path (m/s, m/s^2).
    retime : bool
        Re-time a trajectory that exceeds ``limits`` (else follow it as sent).
    limits : Limits
        The base's limits trajectories are re-timed within.
    accel_fraction : float
        The share of the acceleration limits a trajectory may use, in [0.05, 1]
        (``trajectory_accel_fraction``).
    rest_speed, start_tolerance, max_start_distance : float
        The :class:`~nonfragile_tracker.control.follow.Follower`'s end and start rules.
    """

    mode: str = 'realtime'
    frame: str = INPUT_DEFAULTS['odom_frame']
    max_stamp_jump: float = INPUT_DEFAULTS['max_stamp_jump']
    wait_for_trajectory: bool = INPUT_DEFAULTS['wait_for_trajectory']
    cruise_speed: float = INPUT_DEFAULTS['cruise_speed']
    max_accel: float = INPUT_DEFAULTS['max_accel']
    retime: bool = INPUT_DEFAULTS['retime']
    limits: Limits = field(default_factory=Limits)
    accel_fraction: float = INPUT_DEFAULTS['trajectory_accel_fraction']
    rest_speed: float = INPUT_DEFAULTS['rest_speed']
    start_tolerance: float = INPUT_DEFAULTS['start_tolerance']
    max_start_distance: float = INPUT_DEFAULTS['max_start_distance']

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise InputError(f'mode must be one of {MODES}, got {self.mode!r}')
        if not (math.isfinite(self.max_stamp_jump) and self.max_stamp_jump > 0):
            raise InputError(f'max_stamp_jump must be a finite number > 0 s, got '
                             f'{self.max_stamp_jump!r}')
        if not valid_accel_fraction(self.accel_fraction):
            raise InputError(f'trajectory_accel_fraction must be in [{MIN_ACCEL_FRACTION:g}, 1], '
                             f'got {self.accel_fraction!r}')


def input_rules(values: Mapping[str, Any], mode: str | None = None) -> InputRules:
    """The input rules of a tracker with the parameter ``values``.

    Parameters
    ----------
    values : mapping
        Tracker parameter values by name (a node's, or a parameter file's tracker
        section); names it lacks take :data:`INPUT_DEFAULTS`, the limits 0 (none).
    mode : str, optional
        ``lockstep`` or ``realtime``; default ``values['mode']``, else ``realtime``.

    Returns
    -------
    InputRules

    Raises
    ------
    InputError
        For a mode that is neither, a ``max_stamp_jump`` that is not > 0 or a
        ``trajectory_accel_fraction`` outside [0.05, 1].
    """
    v = {**INPUT_DEFAULTS, **values}
    return InputRules(
        mode=str(mode if mode is not None else v.get('mode', 'realtime')),
        frame=str(v['odom_frame']), max_stamp_jump=float(v['max_stamp_jump']),
        wait_for_trajectory=bool(v['wait_for_trajectory']),
        cruise_speed=float(v['cruise_speed']), max_accel=float(v['max_accel']),
        retime=bool(v['retime']), limits=Limits.from_values(v),
        accel_fraction=float(v['trajectory_accel_fraction']),
        rest_speed=float(v['rest_speed']), start_tolerance=float(v['start_tolerance']),
        max_start_distance=float(v['max_start_distance']))


class Rejection(NamedTuple):
    """An input the rules refused.

    ``kind`` is ``odom``, ``reference``, ``trajectory`` (refused on arrival) or ``start``
    (a followed trajectory refused at its start); ``reason`` says what was wrong (the same
    text for every message refused for the same reason; a trajectory's is the
    :class:`TrajectoryError`'s); ``detail`` this message's particulars (stamps).
    """

    kind: str
    reason: str
    detail: str = ''

    @property
    def key(self) -> str:
        """The text it is counted under in :attr:`TrackerInputs.ignored`."""
        if self.kind in ('trajectory', 'start'):
            return f'trajectory refused: {self.reason}'
        return self.reason

    def __str__(self) -> str:
        return f'{self.key} ({self.detail})' if self.detail else self.key


class Step(NamedTuple):
    """A command the rules say is due, with what it was computed from."""

    stamp: int                             #: odometry stamp answered (ns)
    pose: tuple[float, float, float]       #: measured pose (x, y, yaw)
    ref: RefSample | None                  #: reference it followed (None before a start)
    command: Command                       #: the law's output
    started: bool = False                  #: the followed trajectory started at this step
    finished: bool = False                 #: ... came to rest at its end at this step


class TrackerInputs:
    """The tracker's inputs through its rules, around its step functions (module docstring).

    :meth:`odom`, :meth:`reference` and :meth:`trajectory` take a message and return the
    :class:`Step` it makes due, if any (a refused message is counted and handed to
    ``on_reject``).  The node uses the parts - :meth:`accept_odom`,
    :meth:`accept_reference`, :meth:`build`, :meth:`retime`, :meth:`adopt`,
    :meth:`refuse`, :meth:`compute` - between which it does its ROS-only work.

    Parameters
    ----------
    config : TrackerConfig
        The law (a :class:`~nonfragile_tracker.control.loop.Tracker` is made from it:
        :attr:`tracker`).
    rules : InputRules, optional
        Default: ``InputRules()`` (real time, frame ``odom``, the node's defaults).
    on_reject : callable, optional
        Called with each :class:`Rejection` after it is counted.
    on_jump : callable, optional
        Called with the size (s) of each odometry stamp jump, before the reset.
    """

    def __init__(self, config: TrackerConfig, rules: InputRules | None = None, *,
                 on_reject: Callable[[Rejection], None] | None = None,
                 on_jump: Callable[[float], None] | None = None):
        self.rules = rules if rules is not None else InputRules()
        self.tracker = Tracker(config)
        self.on_reject = on_reject
        self.on_jump = on_jump
        self.odom_msg: Any = None             # the odometry to answer (None: dropped)
        self.latest: list[Any] = [None, None, None]     # latest reference parts
        self.by_stamp: dict[int, list[Any]] = {}        # lockstep: stamp -> parts
        self.last_stamp = -1                  # the odometry stamp last answered (ns)
        self.last_odom_stamp = -1             # the odometry stamp last accepted (ns)
        self.follower: Follower | None = None
        self.origin_ns = 0                    # the followed trajectory's origin stamp
        self.stopped = False                  # real time: inputs stale, no command
        self.rejected = 0
        self.ignored: dict[str, int] = {}     # Rejection.key -> count
        self.jumps = 0
        self.last_refusal = ''                # why the last trajectory was refused
        #: trajectories built, by ``id`` of the message (a replay feeding the same messages
        #: several times sets it; None: no cache)
        self.cache: dict[int, tuple[Trajectory, int] | TrajectoryError] | None = None

    # ------------------------------------------------------------------ refusals
    def _reject(self, rejection: Rejection) -> None:
        self.rejected += 1
        key = rejection.key
        self.ignored[key] = self.ignored.get(key, 0) + 1
        if self.on_reject is not None:
            self.on_reject(rejection)

    def refuse(self, reason: str, kind: str = 'trajectory') -> None:
        """Count a refused trajectory (``kind`` ``trajectory`` or ``start``).

        Parameters
        ----------
        reason : str
            Why (the :class:`TrajectoryError`'s text); kept in :attr:`last_refusal`.
        kind : str, optional
            ``trajectory`` (refused on arrival) or ``start`` (refused at its start).
        """
        self.last_refusal = reason
        self._reject(Rejection(kind, reason))

    # ------------------------------------------------------------------ odometry
    def accept_odom(self, msg: Any) -> int | None:
        """Take an odometry message if the rules accept it; its stamp (ns), else None.

        None for a refused message (counted) and for a repeat of the current step.

        Parameters
        ----------
        msg : nav_msgs/Odometry
            rclpy or rosbags message.

        Returns
        -------
        int or None
        """
        frame = msg.header.frame_id
        if frame != self.rules.frame:
            self._reject(Rejection('odom', f'odom in frame {frame!r} (expected '
                                           f'{self.rules.frame!r})'))
            return None
        s = stamp_ns(msg.header.stamp)
        last = self.last_odom_stamp
        if s <= last:
            if s < last:
                self._reject(Rejection('odom', 'odom stamp going backwards',
                                       f'{s} < {last} ns'))
            return None                    # a repeat of the current step: already handled
        if last >= 0 and s - last > self.rules.max_stamp_jump * 1e9:
            self.jumps += 1
            if self.on_jump is not None:
                self.on_jump((s - last) * 1e-9)
            self.tracker.reset()
        self.odom_msg = msg
        self.last_odom_stamp = s
        return s

    def odom(self, msg: Any) -> Step | None:
        """Take an odometry message; the step it makes due, if any.

        :meth:`accept_odom`, then :meth:`compute` if it was accepted.

        Parameters
        ----------
        msg : nav_msgs/Odometry
            As for :meth:`accept_odom`.

        Returns
        -------
        Step or None
            The command due at its stamp, None if none is (yet).
        """
        if self.accept_odom(msg) is None:
            return None
        return self.compute()

    # ------------------------------------------------------------------ reference samples
    def accept_reference(self, i: int, msg: Any) -> bool:
        """Take reference part ``i`` if the rules accept it (its frame); whether they did.

        Lockstep, while the samples are followed: kept by stamp (a stamp older than the
        last answered is dropped, never needed).

        Parameters
        ----------
        i : int
            0 pose (PoseStamped), 1 twist (TwistStamped), 2 accel (AccelStamped).
        msg : message
            rclpy or rosbags message.

        Returns
        -------
        bool
        """
        frame = msg.header.frame_id
        if frame != self.rules.frame:
            self._reject(Rejection('reference', f'reference in frame {frame!r} (expected '
                                                f'{self.rules.frame!r})'))
            return False
        self.latest[i] = msg
        if self.samples_stepped:
            s = stamp_ns(msg.header.stamp)
            if s >= self.last_stamp:
                parts = self.by_stamp.get(s)
                if parts is None:
                    if len(self.by_stamp) >= REF_BUFFER:
                        del self.by_stamp[min(self.by_stamp)]
                    parts = self.by_stamp[s] = [None, None, None]
                parts[i] = msg
        return True

    @property
    def samples_stepped(self) -> bool:
        """Whether a reference sample can make a step due: lockstep, samples followed."""
        return (self.rules.mode == 'lockstep' and self.follower is None
                and not self.rules.wait_for_trajectory)

    def reference(self, i: int, msg: Any) -> Step | None:
        """Take reference part ``i`` (pose, twist, accel); the step it makes due, if any.

        Parameters
        ----------
        i : int
            0 pose, 1 twist, 2 accel.
        msg : message
            rclpy or rosbags PoseStamped, TwistStamped or AccelStamped.

        Returns
        -------
        Step or None
        """
        if not self.accept_reference(i, msg) or not self.samples_stepped:
            return None
        return self.compute()

    # ------------------------------------------------------------------ trajectories
    def build(self, msg: Any, kind: str, source: str, now_ns: int | None = None
              ) -> tuple[Trajectory, int]:
        """The trajectory of a trajectory message and its origin stamp (ns), as received.

        Parameters
        ----------
        msg : message
            nav_msgs/Path (``kind`` ``path``) or MultiDOFJointTrajectory (``multidof``).
        kind : str
            One of :data:`TRAJECTORY_KINDS`.
        source : str
            Where it came from (error messages, the trajectory's source).
        now_ns : int, optional
            Start of an untimed Path without header stamp; default: the last odometry
            stamp (the lockstep node's *now*; a real-time node passes its clock).

        Returns
        -------
        (Trajectory, int)

        Raises
        ------
        TrajectoryError
            If the message is no valid trajectory in the odometry frame.
        """
        r = self.rules
        if kind == 'path':
            return path_to_trajectory(
                msg, frame=r.frame, source=source, cruise_speed=r.cruise_speed,
                max_accel=r.max_accel,
                now_ns=max(self.last_odom_stamp, 0) if now_ns is None else now_ns)
        if kind != 'multidof':
            raise InputError(f'trajectory kind must be one of {TRAJECTORY_KINDS}, got {kind!r}')
        return multidof_to_trajectory(msg, frame=r.frame, source=source)

    def retime(self, traj: Trajectory) -> tuple[Trajectory, str]:
        """``traj`` re-timed within the limits (``retime``), and a note of what changed.

        Parameters
        ----------
        traj : Trajectory
            As built (:meth:`build`).

        Returns
        -------
        (Trajectory, str)
            The note is empty when nothing changed (or ``retime`` is off).
        """
        if not self.rules.retime:
            return traj, ''
        return within_limits(traj, self.rules.limits, self.rules.accel_fraction)

    def adopt(self, traj: Trajectory, origin_ns: int) -> None:
        """Start a new run on ``traj`` (the previous trajectory, if any, is replaced).

        Parameters
        ----------
        traj : Trajectory
            Re-timed (:meth:`retime`).
        origin_ns : int
            Its origin stamp (ns): trajectory time 0.
        """
        r = self.rules
        if self.follower is None:
            self.follower = Follower(self.tracker, traj, r.rest_speed,
                                     start_tolerance=r.start_tolerance,
                                     max_start_distance=r.max_start_distance)
        else:
            self.follower.set_trajectory(traj)
        self.origin_ns = origin_ns

    def trajectory(self, msg: Any, kind: str, source: str, *, now_ns: int | None = None,
                   defer: bool = False) -> Step | None:
        """Take a trajectory message: build, re-time and adopt it, or refuse it.

        Parameters
        ----------
        msg : message
            nav_msgs/Path or trajectory_msgs/MultiDOFJointTrajectory.
        kind : str
            ``path`` or ``multidof``.
        source : str
            Where it came from.
        now_ns : int, optional
            See :meth:`build`.
        defer : bool, optional
            Adopt without answering a waiting odometry (a real-time node adopts a
            trajectory re-timed in the background right before the next odometry).

        Returns
        -------
        Step or None
            The step for an odometry not yet answered, if any.
        """
        built = self.cache.get(id(msg)) if self.cache is not None else None
        if built is None:
            try:
                traj, origin = self.build(msg, kind, source, now_ns)
                built = (self.retime(traj)[0], origin)
            except TrajectoryError as exc:
                built = exc
            if self.cache is not None:
                self.cache[id(msg)] = built
        if isinstance(built, TrajectoryError):
            self.refuse(str(built))
            return None
        self.adopt(*built)
        return None if defer else self.compute()

    # ------------------------------------------------------------------ the law
    def compute(self) -> Step | None:
        """The step the inputs taken so far make due, if any (at most one per stamp).

        While no step is due and no trajectory is followed (before the first reference or
        trajectory, at rest waiting for one) the odometry stamps still go to the law's
        period estimate (:attr:`control.simulation.loop.Tracker.timing`): the first command
        already knows the odometry rate, and a replay that joins a run primes it with the
        odometry before its first command.

        Returns
        -------
        Step or None
        """
        step = self._compute()
        s = self.last_odom_stamp
        if step is None and self.follower is None and s >= 0 \
                and self.tracker.timing.last_ns != s:
            self.tracker.timing.observe_ns(s)
        return step

    def _compute(self) -> Step | None:
        f = self.follower
        if f is not None:
            return self._follow(f)
        if self.rules.wait_for_trajectory:
            return None
        odom, latest = self.odom_msg, self.latest
        if odom is None or latest[0] is None or latest[1] is None or latest[2] is None \
                or self.stopped:
            return None
        s = stamp_ns(odom.header.stamp)
        parts: list[Any] | None = latest
        lockstep = self.rules.mode == 'lockstep'
        if lockstep:
            parts = self.by_stamp.get(s)
            if s <= self.last_stamp or parts is None or any(r is None for r in parts):
                return None
        assert parts is not None
        pose = self._pose(odom)
        if pose is None:
            return None
        ref = reference_from_msgs(stamp_ns(parts[0].header.stamp) * 1e-9, *parts)
        if isinstance(ref, str):
            self._reject(Rejection('reference', ref))
            return None
        self.last_stamp = s
        if lockstep:
            for old in [k for k in self.by_stamp if k <= s]:
                del self.by_stamp[old]
        speed = odom.twist.twist.linear.x
        # the odometry stamp is the latency predictor's time
        cmd = self.tracker.step(pose[0], pose[1], pose[2], ref,
                                measured_speed=speed if math.isfinite(speed) else 0.0,
                                stamp=s * 1e-9, stamp_ns=s)
        return Step(s, pose, ref, cmd)

    def _pose(self, odom: Any) -> tuple[float, float, float] | None:
        """The pose of ``odom``; None (the odometry dropped, refusal counted) if unusable."""
        pose = pose_from_odom(odom.pose.pose)
        if isinstance(pose, str):
            self.odom_msg = None
            self._reject(Rejection('odom', f'odom: {pose}'))
            return None
        return pose

    def _follow(self, f: Follower) -> Step | None:
        """One step on the adopted trajectory, sampled at the odometry stamp."""
        odom = self.odom_msg
        if odom is None or self.stopped:
            return None
        s = stamp_ns(odom.header.stamp)
        if s <= self.last_stamp:
            return None
        pose = self._pose(odom)
        if pose is None:
            return None
        self.last_stamp = s
        speed = odom.twist.twist.linear.x
        was_started, was_finished = f.started, f.finished
        cmd = f.step(pose[0], pose[1], pose[2], trajectory_time(s, self.origin_ns),
                     measured_speed=speed if math.isfinite(speed) else 0.0)
        started = f.started and not was_started
        if started and f.refused:
            self.refuse(f.refused, 'start')
        return Step(s, pose, f.last_ref, cmd, started, f.finished and not was_finished)

    # ------------------------------------------------------------------ replay helpers
    def fork(self) -> TrackerInputs:
        """A copy whose state can diverge (for trials; messages are shared, never mutated).

        Returns
        -------
        TrackerInputs
        """
        trial = copy.copy(self)
        trial.tracker, trial.follower = copy.deepcopy((self.tracker, self.follower))
        trial.latest = list(self.latest)
        trial.by_stamp = {k: list(v) for k, v in self.by_stamp.items()}
        trial.ignored = dict(self.ignored)
        return trial


def stale_inputs(now_ns: int, odom_ns: int | None, ref_ns: int | None, timeout: float, *,
                 own_trajectory: bool) -> list[str] | None:
    """The inputs older than ``timeout`` (real time); None before anything was commanded.

    Parameters
    ----------
    now_ns : int
        The clock now (ns).
    odom_ns, ref_ns : int or None
        When the last odometry / reference sample was received (ns; None: never).
    timeout : float
        ``input_timeout`` (s).
    own_trajectory : bool
        A trajectory is followed: reference samples are not needed.

    Returns
    -------
    list of str or None
        ``odom`` and/or ``reference``, empty when all are fresh.
    """
    if odom_ns is None or (ref_ns is None and not own_trajectory):
        return None
    inputs = [('odom', odom_ns)]
    if not own_trajectory and ref_ns is not None:
        inputs.append(('reference', ref_ns))
    limit = timeout * 1e9
    return [name for name, t in inputs if now_ns - t > limit]
