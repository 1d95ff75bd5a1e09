"""The tracker's input rules, ROS-free: which messages it takes and when a command is due.

One home for the rules the tracker node (:mod:`.nodes.tracker`) applies to its odometry,
reference samples and trajectories, which a bag replay (:mod:`.bag.replay`) must apply the
same way to reproduce the node's commands: both build a :class:`TrackerInputs` from the
tracker's parameters (:func:`input_rules`) and feed it the messages; refusals are counted
and handed to ``on_reject``.  Messages are duck-typed (rclpy's and rosbags' alike); no
rclpy or rosbags import (layer: ROS-free conversions, next to :mod:`.msgconv`).

See doc/ros-interface.md, section "Input rules".
"""
from __future__ import annotations

import copy
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, NamedTuple

from . import topics
from ..control.simulation.follow import (MAX_START_DISTANCE, REST_SPEED, START_TOLERANCE, Follower,
                             trajectory_time)
from ..control.simulation.limits import (ACCEL_FRACTION, MIN_ACCEL_FRACTION, Limits,
                                        valid_accel_fraction, within_limits)
from ..control.simulation.interfaces import Controller, ControllerFactory, make_controller
from ..control.identification.monitor import MonitorSettings
from ..control.identification.tuning import Tuned, TuningSettings, parse_script
from ..control.simulation.tracker import Command, Tracker, TrackerConfig
from ..control.simulation.wrappers import Clamped
from ..control.simulation.reference import RefSample
from ..control.simulation.replan import (OVERRIDE_TIME, SEARCH_DISTANCE, Nearest, OverrideWatch,
                                        reanchor, splice_path)
from ..control.simulation.trajectory import Trajectory, TrajectoryError
from ..errors import InputError
from .msgconv import (multidof_to_trajectory, path_arrays, path_to_trajectory, pose_from_odom,
                      reference_from_msgs, stamp_ns)

__all__ = ['MODES', 'REF_BUFFER', 'INPUT_DEFAULTS', 'MONITOR_DEFAULTS', 'monitor_settings',
           'TRAJECTORY_KINDS', 'InputRules', 'input_rules', 'Rejection', 'Step', 'TrackerInputs',
           'stale_inputs']

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
    'trajectory_accel_fraction': ACCEL_FRACTION, 'replan': True,
    'replan_search_distance': SEARCH_DISTANCE, 'override_tolerance': 0.0,
    'override_time': OVERRIDE_TIME, 'monitor': True, 'monitor_tune': True,
    'tuning_schedule': '',
}
#: The certificate monitor's parameters with the node's defaults (:func:`monitor_settings`).
MONITOR_DEFAULTS: dict[str, Any] = {
    'monitor_window': 4.0, 'monitor_period': 1.0, 'monitor_max_latency': 0.5,
    'monitor_warn_margin': 0.02, 'monitor_tolerance': 0.01,
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
        The limits trajectories are re-timed within: the motion's, the command's limits
        times the channel gains ``gain_v``, ``gain_w`` (:meth:`.Limits.of_motion`).
    accel_fraction : float
        The share of the acceleration limits a trajectory may use, in [0.05, 1]
        (``trajectory_accel_fraction``).
    rest_speed, start_tolerance, max_start_distance : float
        The :class:`~.control.simulation.follow.Follower`'s end and start rules.
    replan : bool
        An untimed Path that arrives while a trajectory is driven continues the motion
        (:func:`~nonfragile_tracker.control.simulation.replan.splice_path`) instead of
        starting a new run from rest.
    replan_search_distance : float
        Arc length (m) from such a Path's start within which its point nearest the
        reference is looked for.
    override_tolerance, override_time : float
        Commands overridden downstream (a collision monitor): a measured speed more than
        ``override_tolerance`` (m/s; 0 = not watched) below the last command for
        ``override_time`` (s) re-anchors the reference at the robot
        (:class:`~nonfragile_tracker.control.simulation.replan.OverrideWatch`).
    tune : (MonitorSettings, TuningSettings) or None
        With ``monitor_tune`` and ``monitor`` (:func:`input_rules`): our law's predictor
        follows the latency and lags the monitor measures
        (:class:`~nonfragile_tracker.control.identification.tuning.Tuned`, made around the
        law by :class:`TrackerInputs`); None (the default here): it does not.
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
    replan: bool = INPUT_DEFAULTS['replan']
    replan_search_distance: float = INPUT_DEFAULTS['replan_search_distance']
    override_tolerance: float = INPUT_DEFAULTS['override_tolerance']
    override_time: float = INPUT_DEFAULTS['override_time']
    tune: tuple[MonitorSettings, TuningSettings] | None = None

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise InputError(f'mode must be one of {MODES}, got {self.mode!r}')
        if not (math.isfinite(self.max_stamp_jump) and self.max_stamp_jump > 0):
            raise InputError(f'max_stamp_jump must be a finite number > 0 s, got '
                             f'{self.max_stamp_jump!r}')
        if not (math.isfinite(self.replan_search_distance) and self.replan_search_distance > 0):
            raise InputError(f'replan_search_distance must be a finite number > 0 m, got '
                             f'{self.replan_search_distance!r}')
        OverrideWatch(self.override_tolerance, self.override_time)    # (checks them)
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
        retime=bool(v['retime']), limits=Limits.from_values(v).of_motion(*_gains(v)),
        accel_fraction=float(v['trajectory_accel_fraction']),
        rest_speed=float(v['rest_speed']), start_tolerance=float(v['start_tolerance']),
        max_start_distance=float(v['max_start_distance']), replan=bool(v['replan']),
        replan_search_distance=float(v['replan_search_distance']),
        override_tolerance=float(v['override_tolerance']),
        override_time=float(v['override_time']),
        tune=_tuning(values) if v['monitor_tune'] and v['monitor'] else None)


def _gains(values: Mapping[str, Any]) -> tuple[float, float]:
    """``gain_v``, ``gain_w`` among the tracker's values (1 where missing or not > 0).

    The law's configuration refuses a gain that is not > 0; the re-timer takes it as 1.
    """
    out = []
    for name in ('gain_v', 'gain_w'):
        try:
            g = float(values.get(name, 1.0))
        except (TypeError, ValueError):
            g = 1.0
        out.append(g if math.isfinite(g) and g > 0 else 1.0)
    return out[0], out[1]


def monitor_settings(values: Mapping[str, Any]) -> MonitorSettings:
    """The certificate monitor's estimator settings from the tracker's parameter values.

    The one mapping (the node's monitor, the tuning, ``bag certificate``): the monitor's
    parameters (:data:`MONITOR_DEFAULTS` where absent) and the tracker's speed and
    acceleration limits (the saturation and limit gates; 0 = unknown).

    Parameters
    ----------
    values : mapping
        Tracker parameter values by name.

    Returns
    -------
    MonitorSettings

    Raises
    ------
    MonitorError
        For a setting out of range (an ``InputError``).
    """
    v = {**MONITOR_DEFAULTS, 'max_linear_speed': 1.0, 'max_angular_speed': 2.0, **values}
    return MonitorSettings(
        window=float(v['monitor_window']), max_latency=float(v['monitor_max_latency']),
        max_linear_speed=float(v['max_linear_speed']),
        max_angular_speed=float(v['max_angular_speed']),
        max_linear_accel=float(v.get('max_linear_accel') or 0.0),
        max_angular_accel=float(v.get('max_angular_accel') or 0.0),
        warn_margin=float(v['monitor_warn_margin']), tolerance=float(v['monitor_tolerance']))


def _tuning(values: Mapping[str, Any]) -> tuple[MonitorSettings, TuningSettings]:
    """The tuning of ``monitor_tune``: an estimate every ``monitor_period`` of stamp time.

    With a ``tuning_schedule`` (a replay's) its retunes instead of estimates.  The lags
    stay within the gain's ``certified_lag`` (none certified: no lag inverted).
    """
    v = {**MONITOR_DEFAULTS, **values}
    settings = monitor_settings(values)
    return settings, TuningSettings(period=float(v['monitor_period']),
                                    max_latency=settings.max_latency,
                                    max_lag=float(v.get('certified_lag') or 0.0),
                                    script=parse_script(v.get('tuning_schedule') or ''))


class Rejection(NamedTuple):
    """An input the rules refused.

    ``kind`` is ``odom``, ``reference``, ``trajectory`` (refused on arrival) or ``start``
    (a followed trajectory refused at its start); ``reason`` says what was wrong (the same
    text for every message refused for the same reason; a trajectory's is the
    :class:`.TrajectoryError`'s); ``detail`` this message's particulars (stamps).
    """

    kind: str
    reason: str
    detail: str = ''

    @property
    def key(self) -> str:
        """The text it is counted under in ``TrackerInputs.ignored``."""
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
        The tracker's settings; the controller is made from them (``tracker``).
    rules : InputRules, optional
        Default: ``InputRules()`` (real time, frame ``odom``, the node's defaults but no
        tuning; ``input_rules({})`` for the node's, ``monitor_tune`` on).
    on_reject : callable, optional
        Called with each :class:`Rejection` after it is counted.
    on_jump : callable, optional
        Called with the size (s) of each odometry stamp jump, before the reset.
    controller : str or callable, optional
        The law (:func:`~nonfragile_tracker.control.simulation.interfaces.make_controller`:
        ``module:name`` or a factory of ``config``); default our
        :class:`~nonfragile_tracker.control.simulation.tracker.Tracker`.
    on_splice : callable, optional
        Called with the splice point and the start speed (m/s) of each untimed Path
        spliced onto the motion (:meth:`build`, rule ``replan``).
    on_override : callable, optional
        Called with ``held``, ``anchor`` or ``released``, the last command's and the measured
        speed (m/s) when the commands are overridden downstream (``override_tolerance``).
    """

    def __init__(self, config: TrackerConfig, rules: InputRules | None = None, *,
                 on_reject: Callable[[Rejection], None] | None = None,
                 on_jump: Callable[[float], None] | None = None,
                 controller: str | ControllerFactory | None = None,
                 on_splice: Callable[[Nearest, float], None] | None = None,
                 on_override: Callable[[str, float, float], None] | None = None):
        self.rules = rules if rules is not None else InputRules()
        self.tracker: Controller = make_controller(config, controller)
        if self.rules.tune is not None and isinstance(self.tracker, Tracker):
            self.tracker = Tuned(self.tracker, *self.rules.tune)
        elif not isinstance(self.tracker, Tracker):     # ours clamps itself; any other law
            self.tracker = Clamped(self.tracker, config.max_linear_speed,
                                   config.max_angular_speed)
        self.on_reject = on_reject
        self.on_jump = on_jump
        self.on_splice = on_splice
        self.on_override = on_override
        self.splices = 0                      # untimed Paths spliced onto the motion
        self.override = OverrideWatch(self.rules.override_tolerance, self.rules.override_time)
        self.last_v = 0.0                     # the last command's speed (m/s)
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
            Why (the :class:`.TrajectoryError`'s text); kept in ``last_refusal``.
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
            motion = self.motion() if r.replan else None
            if motion is not None:
                stamps, x, y, yaw = path_arrays(msg, frame=r.frame, source=source)
                if x.size and not stamps.any():
                    return self._splice(x, y, yaw, motion, source), self.origin_ns
            return path_to_trajectory(
                msg, frame=r.frame, source=source, cruise_speed=r.cruise_speed,
                max_accel=r.max_accel,
                now_ns=max(self.last_odom_stamp, 0) if now_ns is None else now_ns)
        if kind != 'multidof':
            raise InputError(f'trajectory kind must be one of {TRAJECTORY_KINDS}, got {kind!r}')
        return multidof_to_trajectory(msg, frame=r.frame, source=source)

    def motion(self) -> tuple[float, RefSample] | None:
        """The motion an untimed Path would continue: follower time and reference now.

        None unless a trajectory is being driven: adopted, started, not refused, not yet at
        rest after its end (a robot held at rest by an override is still driving it).

        Returns
        -------
        (float, RefSample) or None
        """
        f = self.follower
        if f is None or not f.started or f.refused or f.finished or self.last_odom_stamp < 0:
            return None
        t = trajectory_time(self.last_odom_stamp, self.origin_ns) - f.offset
        return t, f.trajectory.sample(t)

    def _splice(self, x: Any, y: Any, yaw: Any, motion: tuple[float, RefSample],
                source: str) -> Trajectory:
        """An untimed Path's trajectory, continuing ``motion`` (rule ``replan``)."""
        t, ref = motion
        r = self.rules
        speed = math.hypot(ref.vx, ref.vy)
        traj, near = splice_path(x, y, yaw, anchor=(ref.x, ref.y), t0=t, start_speed=speed,
                                 cruise_speed=r.cruise_speed, max_accel=r.max_accel,
                                 search_distance=r.replan_search_distance,
                                 direction=(ref.vx, ref.vy),
                                 current=self.follower.trajectory if self.follower else None,
                                 source=source)
        self.splices += 1
        if self.on_splice is not None:
            self.on_splice(near, speed)
        return traj

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
        new, note = within_limits(traj, self.rules.limits, self.rules.accel_fraction)
        new.spliced = traj.spliced
        return new, note

    def adopt(self, traj: Trajectory, origin_ns: int) -> None:
        """Start a new run on ``traj`` (the previous trajectory, if any, is replaced).

        A spliced trajectory (:attr:`.Trajectory.spliced`, from :meth:`build`) continues the
        run instead (:meth:`.follow.Follower.splice`; ``origin_ns`` is the run's).

        Parameters
        ----------
        traj : Trajectory
            Re-timed (:meth:`retime`).
        origin_ns : int
            Its origin stamp (ns): trajectory time 0.
        """
        r = self.rules
        if traj.spliced and self.follower is not None:
            self.follower.splice(traj)        # the motion goes on: same origin, no new run
            return
        self.override.reset()
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
        # a splice depends on the motion when it comes, not on the message alone
        cache = self.cache if not (kind == 'path' and self.rules.replan
                                   and self.motion() is not None) else None
        built = cache.get(id(msg)) if cache is not None else None
        if built is None:
            try:
                traj, origin = self.build(msg, kind, source, now_ns)
                built = (self.retime(traj)[0], origin)
            except TrajectoryError as exc:
                built = exc
            if cache is not None:
                cache[id(msg)] = built
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
        period estimate (:attr:`.control.simulation.tracker.Tracker.timing`): the first command
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
        speed, rate = _twist(odom)
        # the odometry stamp is the latency predictor's time
        cmd = self.tracker.step(pose[0], pose[1], pose[2], ref, measured_speed=speed,
                                stamp=s * 1e-9, stamp_ns=s, measured_rate=rate)
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
        speed, rate = _twist(odom)
        was_started, was_finished = f.started, f.finished
        if f.started and not (f.finished or f.refused):
            self._watch(f, s, pose, speed)
        cmd = f.step(pose[0], pose[1], pose[2], trajectory_time(s, self.origin_ns),
                     measured_speed=speed, measured_rate=rate)
        self.last_v = cmd.v
        started = f.started and not was_started
        if started and f.refused:
            self.refuse(f.refused, 'start')
        return Step(s, pose, f.last_ref, cmd, started, f.finished and not was_finished)

    def _watch(self, f: Follower, s: int, pose: tuple[float, float, float],
               speed: float) -> None:
        """Commands overridden downstream: re-anchor at the robot, restart the compensator."""
        event = self.override.update(s * 1e-9, self.last_v, speed)
        if event is None:
            return
        if event != 'released':
            t = trajectory_time(s, self.origin_ns) - f.offset
            if not f.trajectory.is_analytic:
                try:
                    f.splice(reanchor(f.trajectory, t, pose[0], pose[1], speed,
                                      cruise_speed=self.rules.cruise_speed,
                                      max_accel=self.rules.max_accel))
                except TrajectoryError:
                    pass                      # at the end of the path: the law brings it there
            self.tracker.reset(speed)
        if self.on_override is not None:
            self.on_override(event, self.last_v, speed)

    def release(self) -> None:
        """Forget the followed trajectory and the pending inputs (a managed node deactivated).

        The counters stay; the law is reset and the odometry stamps forgotten, so the next
        activation starts a new run at its first odometry, from the measured speed (a
        latched trajectory taken again is re-based there: ``Follower.offset``).
        """
        self.last_stamp = self.last_odom_stamp = -1
        self.last_v = 0.0
        self.override.reset()
        self.follower = None
        self.origin_ns = 0
        self.odom_msg = None
        self.latest = [None, None, None]
        self.by_stamp.clear()
        self.stopped = False
        self.tracker.reset()

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


def _twist(odom: Any) -> tuple[float, float]:
    """The measured speed and yaw rate of an odometry message (non-finite: 0)."""
    v, w = odom.twist.twist.linear.x, odom.twist.twist.angular.z
    return (v if math.isfinite(v) else 0.0), (w if math.isfinite(w) else 0.0)


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
