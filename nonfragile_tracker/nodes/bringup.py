"""``bringup``: drive a designed excitation, identify, design, verify - and stop safely always.

A thin adapter over :mod:`nonfragile_tracker.control.identification.excitation` (the plan),
:class:`~nonfragile_tracker.control.simulation.follow.Follower` with the tracking law
(closed loop) and :mod:`nonfragile_tracker.workflows.commissioning` (identify, design, files,
report; in a child process).  Phases: ``wait`` -> ``excite`` (recorded to ``<run_dir>/bag``) ->
``analyse`` -> ``trial`` (``<run_dir>/trial_bag``) -> ``report``.  On every exit path it
publishes and records zero velocity and ends within 0.1 s.

See doc/tutorial.md, section "One command (bringup)" (the phases), and doc/safety.md,
section "The bring-up (``bringup``)" (every exit path).
"""
from __future__ import annotations

import json
import math
import subprocess
import sys
import time
import traceback
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import rclpy
from geometry_msgs.msg import AccelStamped, PoseStamped, Twist, TwistStamped
from nav_msgs.msg import Odometry
from rclpy.executors import SingleThreadedExecutor
from rclpy.serialization import serialize_message
from rclpy.signals import SignalHandlerOptions

from ..interface import topics
from ..bag.writer import BagWriter
from ..control.identification.excitation import Plan, plan_excitation, plan_trial
from ..control.simulation.follow import Follower, path_errors
from ..control.simulation.interfaces import Controller, make_controller
from ..control.simulation.tracker import TrackerConfig
from ..control.simulation.model import quaternion_to_yaw
from ..errors import EXIT_BAD_INPUT, EXIT_RUN, InputError
from ..interface.robot import OUTCOME_FILE, REPORT_FILE, RobotConfig, parse_robot_parameters
from .common import DATA_QOS, AdapterNode, Param, fill_pose, ns_to_stamp
from .entry import catch_stop_signals, ignore_stop_signals, stop_requested
from .workarounds import arm_exit_deadline

__all__ = ['BringupNode', 'BringupConfig', 'PARAMS', 'main', 'EXIT_LEFT_BOX', 'EXIT_SILENCE']

#: Exit codes: refused (2, bad input or not informative), left the box, odometry silence.
EXIT_LEFT_BOX = 6
EXIT_SILENCE = 7
#: Period of the watchdog and of the main loop's spin (s).
TICK = 0.02
#: Odometry messages to wait for before the start (start pose, odometry period).
START_SAMPLES = 10
#: Longest wait for the first odometry (s).
START_TIMEOUT = 10.0

PARAMS = [
    Param('run_dir', '', 'the run folder: bags, files and the report go there', read_only=True),
    Param('box_radius', 1.0, 'stop if the odometry is farther than this from the start pose (m)',
          low=0.05, high=1e3, read_only=True),
    Param('max_linear_speed', 0.3, 'limit on |cmd_vel.linear.x| (m/s)', low=1e-3, high=1e3,
          read_only=True),
    Param('max_angular_speed', 1.0, 'limit on |cmd_vel.angular.z| (rad/s)', low=1e-3,
          high=1e3, read_only=True),
    Param('accel_segment', True, 'drive a segment whose steps are faster than the base '
          'follows (its acceleration limits are identified)', read_only=True),
    Param('excitation_duration', 55.0, 'robot time of the excitation (s)', low=5.0, high=600.0,
          read_only=True),
    Param('trial_duration', 20.0, 'robot time of the trial (s); 0 = no trial', low=0.0,
          high=600.0, read_only=True),
    Param('odom_timeout', 0.5, 'stop if no odometry arrives for this long (s, wall)', low=0.05,
          high=60.0, read_only=True),
    Param('gains', '', 'the gain of the excitation (the shipped certified one)', read_only=True),
    Param('problem', '', 'the problem file of the design', read_only=True),
    Param('robot', '{}', 'the robot settings as JSON (the keys of '
          'nonfragile_tracker.interface.robot.RobotConfig)',
          read_only=True),
    Param('truth_topic', '', 'an external pose of the base (geometry_msgs/PoseStamped: motion '
          'capture, a simulator\'s true pose) recorded beside the odometry: the side slip the '
          'odometry does not see is identified from it; empty = none', read_only=True),
    Param('dry_plan_only', False, 'plan, print the extent and end without moving (tests)',
          read_only=True),
]


@dataclass(frozen=True)
class BringupConfig:
    """The node's validated parameters."""

    run_dir: Path
    box_radius: float
    max_linear_speed: float
    max_angular_speed: float
    accel_segment: bool
    excitation_duration: float
    trial_duration: float
    odom_timeout: float
    gains: Path
    problem: Path
    robot: RobotConfig
    dry_plan_only: bool
    truth_topic: str = ''


def bringup_config(values: dict[str, Any]) -> BringupConfig:
    """Validate the parameter values (an ``InputError`` names what is wrong).

    Parameters
    ----------
    values : dict
        The parameter values by name.

    Returns
    -------
    BringupConfig
    """
    if not values['run_dir']:
        raise InputError('run_dir must name the run folder')
    try:
        fields = json.loads(values['robot'])
    except json.JSONDecodeError as exc:
        raise InputError(f'robot must be JSON: {exc}') from None
    if not isinstance(fields, dict):
        raise InputError(f'robot must be a JSON object of robot-file keys, got {fields!r}')
    source = str(fields.pop('source', ''))
    robot = parse_robot_parameters(fields, source)
    for key in ('gains', 'problem'):
        if not values[key] or not Path(values[key]).is_file():
            raise InputError(f'{key}: no such file {values[key]!r}')
    return BringupConfig(run_dir=Path(values['run_dir']), box_radius=values['box_radius'],
                         max_linear_speed=values['max_linear_speed'],
                         max_angular_speed=values['max_angular_speed'],
                         accel_segment=values['accel_segment'],
                         excitation_duration=values['excitation_duration'],
                         trial_duration=values['trial_duration'],
                         odom_timeout=values['odom_timeout'], gains=Path(values['gains']),
                         problem=Path(values['problem']), robot=robot,
                         dry_plan_only=values['dry_plan_only'],
                         truth_topic=str(values['truth_topic']))


def _say(text: str) -> None:
    print(f'[bringup] {text}', flush=True)


def _tracker_values(path: Path) -> dict[str, Any]:
    """The tracker section of a gain file."""
    import yaml
    data = yaml.safe_load(path.read_text()) or {}
    for key in ('/**/tracker', 'tracker', '/tracker'):
        if isinstance(data.get(key), dict):
            return dict(data[key].get('ros__parameters') or {})
    raise InputError(f'{path}: no tracker section')


class _Recording:
    """One bag of a driven phase: odometry, commands and the reference samples."""

    def __init__(self, path: Path, cmd_topic: str, cmd_type: str, odom_topic: str,
                 truth_topic: str = ''):
        self.cmd_topic, self.odom_topic = cmd_topic, odom_topic
        connections = {
            odom_topic: topics.TYPES[topics.ODOM], cmd_topic: cmd_type,
            topics.REF_POSE: topics.TYPES[topics.REF_POSE],
            topics.REF_TWIST: topics.TYPES[topics.REF_TWIST],
            topics.REF_ACCEL: topics.TYPES[topics.REF_ACCEL]}
        if truth_topic:
            connections[truth_topic] = topics.TYPES[topics.POSE]
        self.writer = BagWriter(path, connections=connections)
        self.path = path

    def write(self, topic: str, msg: Any) -> None:
        if not self.writer.closed:
            self.writer.write(topic, time.time_ns(), serialize_message(msg))

    def close(self) -> None:
        if not self.writer.closed:
            self.writer.close()


class BringupNode(AdapterNode[BringupConfig]):
    """The bring-up: phases, the closed loop, the recording and the watchdog."""

    def __init__(self, node_name: str = 'bringup', **node_kwargs: Any):
        """Declare and validate the parameters, make the publisher and the subscription.

        Parameters
        ----------
        node_name : str
            The node's name.
        **node_kwargs
            rclpy ``Node`` keyword arguments.
        """
        super().__init__(node_name, **node_kwargs)
        self.config = cfg = self.bind_parameters(PARAMS, bringup_config)
        robot = cfg.robot
        self.stamped = robot.enable_stamped_cmd_vel
        self.cmd_type = topics.CMD_VEL_STAMPED_TYPE if self.stamped else topics.TYPES[
            topics.CMD_VEL]
        self.pub = self.create_publisher(TwistStamped if self.stamped else Twist,
                                         robot.cmd_vel_topic, DATA_QOS)
        self.create_subscription(Odometry, robot.odom_topic, self._on_odom, DATA_QOS)
        if cfg.truth_topic:
            self.create_subscription(PoseStamped, cfg.truth_topic, self._on_truth, DATA_QOS)
        self.phase = 'wait'
        self.phase_start = time.monotonic()
        self.started_wall = time.monotonic()
        self.last_odom = math.nan
        self.silence_said = False
        self.last_tick = time.monotonic()
        self.grace_until = -math.inf        # after a stall of this node: judge no silence
                                            # before this (monotonic s)
        self.last_stamp = 0
        self.stamps: list[int] = []
        self.start: tuple[float, float, float] | None = None
        self.odom_period = 0.02
        self.farthest = 0.0
        self.recording: _Recording | None = None
        self.follower: Follower | None = None
        self.plan: Plan | None = None
        self.trial_plan: Plan | None = None
        self.origin_ns = 0
        self.stopped = False
        self.child: Any = None
        self.outcome: dict[str, Any] | None = None
        self.trial_err: list[tuple[float, float, float]] = []
        self.last_progress = 0.0
        self.last_cmd = (0.0, 0.0)
        self.rejected = 0
        self.robot_time = 0.0
        self.excitation_figs: dict[str, Any] = {}
        self.trial_figs: dict[str, Any] | None = None
        self.create_timer(TICK, self._tick)

    # ------------------------------------------------------------------ commands
    def _command(self, v: float, w: float) -> None:
        """Publish (and record) a command clamped to the limits."""
        cfg = self.config
        v = max(-cfg.max_linear_speed, min(cfg.max_linear_speed, float(v)))
        w = max(-cfg.max_angular_speed, min(cfg.max_angular_speed, float(w)))
        if not (math.isfinite(v) and math.isfinite(w)):
            v = w = 0.0
        if self.stamped:
            msg: Any = TwistStamped()
            ns_to_stamp(time.time_ns(), msg.header.stamp)
            msg.header.frame_id = cfg.robot.base_frame
            msg.twist.linear.x, msg.twist.angular.z = v, w
        else:
            msg = Twist()
            msg.linear.x, msg.angular.z = v, w
        self.pub.publish(msg)
        self.last_cmd = (v, w)
        if self.recording is not None:
            self.recording.write(self.config.robot.cmd_vel_topic, msg)

    def stop(self, reason: str, code: int = 0) -> None:
        """Command zero (three times, recorded), close the bags, end with ``code``.

        Parameters
        ----------
        reason : str
            Said on stdout (and why the run ended).
        code : int
            The process exit code.
        """
        if self.stopped:
            return
        self.stopped = True
        try:
            for _ in range(3):
                self._command(0.0, 0.0)
        except Exception:  # noqa: BLE001 - the context may be gone; nothing else to do
            pass
        if self.child is not None and self.child.poll() is None:
            self.child.kill()
            self.child.wait()
        if self.recording is not None:
            self.recording.close()
            self.recording = None
        _say(f'stopped ({reason}); zero velocity commanded')
        if self.start is not None:
            if self.phase in ('excite', 'trial'):
                self.robot_time += time.monotonic() - self.phase_start
            _say(f'robot time {self.robot_time:.1f} s; farthest {self.farthest:.3f} m from the '
                 f'start pose (box {self.config.box_radius:g} m)')
        self.finished = True
        self.exit_code = code

    def close(self) -> None:
        """Stop (zero command) if not stopped yet, release the bag and the child."""
        if not self.stopped:
            self.stop('closing', self.exit_code)

    # ------------------------------------------------------------------ odometry
    def _on_odom(self, msg: Odometry) -> None:
        if self.stopped:
            return
        now = time.monotonic()
        q = msg.pose.pose.orientation
        x, y = msg.pose.pose.position.x, msg.pose.pose.position.y
        norm = math.sqrt(q.x ** 2 + q.y ** 2 + q.z ** 2 + q.w ** 2)
        if not all(map(math.isfinite, (x, y, norm))) or abs(norm - 1.0) > 1e-3:
            self.rejected += 1
            return
        self.last_odom = now
        th = quaternion_to_yaw(q.x, q.y, q.z, q.w)
        stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
        self.last_stamp = stamp
        if self.recording is not None:
            self.recording.write(self.config.robot.odom_topic, msg)
        if self.phase == 'wait':
            self.stamps.append(stamp)
            if len(self.stamps) >= START_SAMPLES:
                self._begin(x, y, th)
            return
        assert self.start is not None
        # where the robot is: the odometry, plus the slide the trial's tracker reckons when it
        # compensates a side slip (the odometry of a skid-steer drifts outward of its turns)
        slide = getattr(self.follower.tracker, 'slide', None) \
            if self.phase == 'trial' and self.follower is not None else None
        bx, by = (x, y) if slide is None else (x + slide.offset[0], y + slide.offset[1])
        d = math.hypot(bx - self.start[0], by - self.start[1])
        self.farthest = max(self.farthest, d)
        if d > self.config.box_radius:
            self.stop(f'left the box: {d:.3f} m from the start pose > box '
                      f'{self.config.box_radius:g} m', EXIT_LEFT_BOX)
            return
        if self.phase in ('excite', 'trial') and self.follower is not None:
            t = (stamp - self.origin_ns) * 1e-9
            cmd = self.follower.step(x, y, th, t, float(msg.twist.twist.linear.x),
                                     float(msg.twist.twist.angular.z))
            ref = self.follower.last_ref
            if ref is not None and self.recording is not None:
                self._record_reference(stamp, ref)
            if self.phase == 'trial' and ref is not None and t > 0:
                if slide is not None:           # the tracker's estimate of the true pose
                    x, y = x + slide.offset[0], y + slide.offset[1]
                along, cross, _ = path_errors(x, y, th, ref)
                self.trial_err.append((t, along, cross))
            self._command(cmd.v, cmd.w)
            if self.follower.finished:
                self._end_drive()

    def _on_truth(self, msg: PoseStamped) -> None:
        """Record the external pose (the side slip is identified from it, not driven by)."""
        if not self.stopped and self.recording is not None:
            self.recording.write(self.config.truth_topic, msg)

    def _record_reference(self, stamp: int, ref: Any) -> None:
        assert self.recording is not None
        pose, twist, accel = PoseStamped(), TwistStamped(), AccelStamped()
        for m in (pose, twist, accel):
            ns_to_stamp(stamp, m.header.stamp)
            m.header.frame_id = self.config.robot.odom_frame
        fill_pose(pose.pose, ref.x, ref.y, ref.heading)
        twist.twist.linear.x, twist.twist.linear.y = ref.vx, ref.vy
        accel.accel.linear.x, accel.accel.linear.y = ref.ax, ref.ay
        self.recording.write(topics.REF_POSE, pose)
        self.recording.write(topics.REF_TWIST, twist)
        self.recording.write(topics.REF_ACCEL, accel)

    # ------------------------------------------------------------------ phases
    def _set_phase(self, phase: str) -> None:
        self.phase = phase
        self.phase_start = time.monotonic()
        # planning took this process away from its queue: odometry waiting there is not silence
        self.last_odom = self.phase_start
        _say(f'phase {phase}')

    def _tracker(self, values: dict[str, Any]) -> Controller:
        """The tracking law with the gain file's values, the odometry period, the limits."""
        from ..interface.msgconv import tracker_config
        from .tracker import PARAMS as TRACKER_PARAMS
        cfg = self.config
        full = {p.name: p.default for p in TRACKER_PARAMS}
        full.update(values)
        robot = cfg.robot
        full.update(dt=self.odom_period, max_linear_speed=cfg.max_linear_speed,
                    max_angular_speed=cfg.max_angular_speed)
        for key in ('max_linear_accel', 'max_angular_accel'):
            if getattr(robot, key) > 0:
                full[key] = getattr(robot, key)
        tc: TrackerConfig = tracker_config(full)
        return make_controller(tc)

    def _begin(self, x: float, y: float, th: float) -> None:
        cfg = self.config
        diffs = np.diff(np.array(self.stamps, dtype=np.int64)) * 1e-9
        diffs = diffs[diffs > 0]
        self.odom_period = float(np.median(diffs)) if diffs.size else 0.02
        self.start = (x, y, th)
        robot = cfg.robot
        self.plan = plan_excitation(cfg.box_radius, cfg.max_linear_speed, cfg.max_angular_speed,
                                    accel_segment=cfg.accel_segment,
                                    odom_rate=1.0 / self.odom_period,
                                    max_linear_accel=robot.max_linear_accel,
                                    max_angular_accel=robot.max_angular_accel,
                                    duration=cfg.excitation_duration)
        ext = self.plan.extent()
        _say(f'start pose ({x:.3f}, {y:.3f}, {th:.3f}); odometry every {self.odom_period:.4f} s; '
             f'excitation: {ext.describe()}')
        self.excitation_figs = {'planned_' + k: v for k, v in
                                ext.__dict__.items()}
        self.recording = _Recording(cfg.run_dir / 'bag', robot.cmd_vel_topic, self.cmd_type,
                                    robot.odom_topic, cfg.truth_topic)
        tracker = self._tracker(_tracker_values(cfg.gains))
        self.follower = Follower(tracker, self.plan.trajectory(self.start), max_start_distance=0.0)
        self.origin_ns = self.stamps[-1] + int(0.2e9)
        self._set_phase('excite')

    def _end_drive(self) -> None:
        self._command(0.0, 0.0)
        self.robot_time += time.monotonic() - self.phase_start
        if self.recording is not None:
            self.recording.close()
            self.recording = None
        self.follower = None
        if self.phase == 'excite':
            self.excitation_figs.update(farthest_distance=self.farthest,
                                        robot_time=self.robot_time)
            self._start_child('analyse', {
                'task': 'analyse', 'bag': str(self.config.run_dir / 'bag'),
                'run_dir': str(self.config.run_dir),
                'settings': {'robot': self.config.robot.__dict__,
                             'problem': str(self.config.problem),
                             'odom_period': self.odom_period,
                             'accel_segment': self.config.accel_segment,
                             'truth_topic': self.config.truth_topic},
                'excitation': self.excitation_figs})
        elif self.phase == 'trial':
            self._trial_figures()
            self._start_child('report', {
                'task': 'report', 'run_dir': str(self.config.run_dir),
                'outcome': self.outcome or {}, 'trial': self.trial_figs,
                'excitation': self.excitation_figs})

    def _start_child(self, phase: str, spec: dict[str, Any]) -> None:
        """Run ``spec`` in a child process (the analysis or the report).

        The child runs :func:`nonfragile_tracker.workflows.commissioning.run_child`, a layer
        above the nodes: called by its name, never imported; the run folder's files
        (:mod:`nonfragile_tracker.interface.robot`'s names) are the contract.
        """
        out = self.config.run_dir / OUTCOME_FILE
        if phase == 'analyse' and out.exists():
            out.unlink()
        path = self.config.run_dir / f'{phase}_task.json'
        path.write_text(json.dumps(spec, default=float))
        # a session of its own: a terminal's Ctrl-C reaches this node, which kills the child
        self.child = subprocess.Popen(
            [sys.executable, '-c', 'import sys; from nonfragile_tracker.workflows.commissioning '
             'import run_child; sys.exit(run_child(sys.argv[1]))', str(path)],
            start_new_session=True)
        self._set_phase(phase)

    def _trial_figures(self) -> None:
        e = np.array(self.trial_err) if self.trial_err else np.zeros((0, 3))
        settled = e[e[:, 0] > 5.0] if e.size else e
        if settled.size:
            pos = np.hypot(settled[:, 1], settled[:, 2])
            self.trial_figs = {'rms_error_after_5s': float(np.sqrt(np.mean(pos ** 2))),
                               'max_error_after_5s': float(np.max(pos)),
                               'rms_cross_track_after_5s': float(
                                   np.sqrt(np.mean(settled[:, 2] ** 2))),
                               'samples': int(settled.shape[0])}
        else:
            self.trial_figs = {'samples': 0}
        self.trial_figs['farthest_distance'] = self.farthest
        self.trial_figs['robot_time_total'] = self.robot_time

    def _after_analysis(self) -> None:
        out = self.config.run_dir / OUTCOME_FILE
        try:
            self.outcome = json.loads(out.read_text())
        except (OSError, ValueError):
            self.stop(f'the analysis ended without a result (exit code {self.child.returncode})',
                      EXIT_RUN)
            return
        assert self.outcome is not None
        if not self.outcome.get('ok'):
            _say(f'REFUSED ({self.outcome.get("phase")}): {self.outcome.get("refusal")}')
            if self.outcome.get('traceback'):
                print(self.outcome['traceback'], file=sys.stderr)
            self.stop('refused: no gain written', EXIT_BAD_INPUT)
            return
        o = self.outcome
        _say(f'identified: latency {o["latency_s"]:.4f} s, lags {o["tau_v_s"]:.4f} / '
             f'{o["tau_w_s"]:.4f} s, accel limits {o["max_linear_accel"]:.3g} m/s^2 / '
             f'{o["max_angular_accel"]:.3g} rad/s^2 (0 = not seen)')
        if self.config.truth_topic:
            _say(str(o.get('side_slip', '')))
        _say(f'designed: ||K|| = {o["gain_norm"]:.3f}, certified residual up to '
             f'{o["certified_h_max"]:.4f} s with the lag {o["lag"]:.4f} s; wrote '
             f'{o["gain_file"]}')
        cfg = self.config
        if cfg.trial_duration <= 0:
            self._start_child('report', {
                'task': 'report', 'run_dir': str(cfg.run_dir), 'outcome': self.outcome,
                'trial': None, 'excitation': self.excitation_figs})
            return
        assert self.plan is not None and self.start is not None
        silent = time.monotonic() - self.last_odom
        if silent > cfg.odom_timeout:
            self.stop(f'odometry silent for {silent:.2f} s at the start of the trial (> '
                      f'odom_timeout {cfg.odom_timeout:g} s)', EXIT_SILENCE)
            return
        values = _tracker_values(Path(o['gain_file']))
        self.trial_plan = plan_trial(self.plan, duration=cfg.trial_duration,
                                     max_linear_accel=cfg.robot.max_linear_accel)
        self.recording = _Recording(cfg.run_dir / 'trial_bag', cfg.robot.cmd_vel_topic,
                                    self.cmd_type, cfg.robot.odom_topic, cfg.truth_topic)
        self.follower = Follower(self._tracker(values), self.trial_plan.trajectory(self.start),
                                 max_start_distance=0.0)
        self.origin_ns = self.last_stamp + int(0.3e9)
        self.trial_err = []
        self._set_phase('trial')

    # ------------------------------------------------------------------ watchdog, progress
    def _tick(self) -> None:
        if self.stopped:
            return
        if stop_requested():                 # a signal during this spin: it comes first
            self.stop('stop signal', 0)
            return
        now = time.monotonic()
        cfg = self.config
        if self.phase == 'wait':
            if now - self.started_wall > START_TIMEOUT:
                self.stop(f'no odometry on {cfg.robot.odom_topic} within {START_TIMEOUT:g} s: '
                          'check the topic name and that the robot publishes it',
                          EXIT_SILENCE)
            return
        silent = now - self.last_odom
        own_gap, self.last_tick = now - self.last_tick, now
        if silent > cfg.odom_timeout and own_gap > cfg.odom_timeout / 2 \
                and now >= self.grace_until:
            # this node itself stalled (a loaded machine): the odometry may be waiting unread
            # in its queue (or in the middleware's threads, stopped with this process), so
            # it gets odom_timeout of this node's running time to be taken before a silence
            # is judged (once: a node starved again within that time judges at its end)
            self.grace_until = now + cfg.odom_timeout
            _say(f'warning: this node did not run for {own_gap:.2f} s (a loaded machine); '
                 f'the odometry silence is judged after {cfg.odom_timeout:g} s more')
        if silent > cfg.odom_timeout and now >= self.grace_until:
            if self.phase in ('excite', 'trial'):
                self.stop(f'odometry silent for {silent:.2f} s (> odom_timeout '
                          f'{cfg.odom_timeout:g} s)', EXIT_SILENCE)
                return
            if not self.silence_said:        # at rest, commanded zero: say it, go on
                self.silence_said = True
                _say(f'warning: odometry silent for {silent:.2f} s while the robot is at '
                     'rest; zero is still commanded, and the trial starts only with fresh '
                     'odometry')
        elif silent <= cfg.odom_timeout:
            self.silence_said = False
        if self.phase in ('analyse', 'report'):
            if now - self.last_progress > 0.5:
                self._command(0.0, 0.0)       # at rest; keeps a base's cmd watchdog fed
            if self.child is not None and self.child.poll() is not None:
                if self.phase == 'analyse':
                    self._after_analysis()
                else:
                    self._finish()
                return
        if now - self.last_progress >= 1.0:
            self.last_progress = now
            self._progress(now)

    def _progress(self, now: float) -> None:
        elapsed = now - self.phase_start
        left = ''
        plan = self.plan if self.phase == 'excite' else self.trial_plan \
            if self.phase == 'trial' else None
        if plan is not None:
            left = f', {max(plan.duration + 0.2 - elapsed, 0.0):.0f} s left'
        elif self.phase == 'analyse':
            left = ' (identify, then design: SDPs, about 10-60 s; the robot is at rest)'
        _say(f'phase {self.phase}: {elapsed:.0f} s{left}; farthest {self.farthest:.3f} m of '
             f'{self.config.box_radius:g} m; last command v {self.last_cmd[0]:+.3f} m/s, '
             f'w {self.last_cmd[1]:+.3f} rad/s')

    def _finish(self) -> None:
        cfg = self.config
        o = self.outcome or {}
        report = cfg.run_dir / REPORT_FILE
        try:
            res = json.loads((cfg.run_dir / 'report.json').read_text())
            status = res.get('certificate', '')
        except (OSError, ValueError):
            status = 'unknown (no report result)'
        if self.trial_figs and self.trial_figs.get('samples'):
            f = self.trial_figs
            _say(f'trial: RMS error {f["rms_error_after_5s"] * 1e3:.2f} mm, cross-track RMS '
                 f'{f["rms_cross_track_after_5s"] * 1e3:.2f} mm, max '
                 f'{f["max_error_after_5s"] * 1e3:.2f} mm (after 5 s); certificate monitor: '
                 f'{status}')
        _say(f'wrote {o.get("robot_file")}, {o.get("gain_file")}, {report}')
        _say('next: run the tracker with the designed gain and the robot file, e.g.\n'
             f'  ros2 launch nonfragile_tracker robot.launch.py robot:={o.get("robot_file")} '
             f'gains:={o.get("gain_file")} trajectory:=lap.csv')
        self.stop('done', 0)


def main(args: list[str] | None = None) -> int:
    """Process main of the bring-up node: spin, watch, and stop safely on every path.

    Parameters
    ----------
    args : list of str, optional
        Command-line arguments for ``rclpy.init`` (``--ros-args ...``).

    Returns
    -------
    int
        0 when done (or stopped by a signal), 2 refused (bad input, data not informative,
        latency not certifiable), 5 an error, 6 left the box, 7 odometry silence.
    """
    catch_stop_signals()
    if stop_requested():
        ignore_stop_signals()
        return 0
    try:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except Exception as exc:  # noqa: BLE001 - rcl reports bad arguments
        print(f'[FATAL] cannot start: {exc}', file=sys.stderr)
        return EXIT_BAD_INPUT
    node: BringupNode | None = None
    code = 0
    executor = None
    try:
        try:
            node = BringupNode()
        except InputError as exc:
            print(f'[FATAL] {exc}', file=sys.stderr)
            return EXIT_BAD_INPUT
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        _say(f'started; box {node.config.box_radius:g} m, |v| <= {node.config.max_linear_speed:g}'
             f' m/s, |w| <= {node.config.max_angular_speed:g} rad/s; Ctrl-C stops the robot')
        while not node.finished:
            if stop_requested():
                node.stop('stop signal', 0)
                break
            executor.spin_once(timeout_sec=TICK)
        code = node.exit_code
    except Exception:  # noqa: BLE001 - any error: zero command, then the traceback
        if node is not None:
            node.stop('error', EXIT_RUN)
        traceback.print_exc()
        code = EXIT_RUN
    finally:
        ignore_stop_signals()
        if node is not None:
            node.stop('ending', code)
            code = node.exit_code if code == 0 else code
        arm_exit_deadline(code)
        if executor is not None:
            executor.shutdown()
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return code
