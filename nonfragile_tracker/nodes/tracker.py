"""``tracker``: the non-fragile tracking law with K from parameters.

Subscribes ``odom`` (nav_msgs/Odometry; its twist.linear.x initialises the
compensator speed) and the trajectory topics (below; with ``wait_for_trajectory: false``
also ``reference/pose``, ``reference/twist``, ``reference/accel``); publishes
``cmd_vel`` (geometry_msgs/Twist, or TwistStamped with
``enable_stamped_cmd_vel``: stamp = command time, frame = ``base_frame``),
``tracker/error`` (geometry_msgs/Vector3Stamped: x along-track, y cross-track in m,
z heading error in rad, in the reference point's frame; every step, when subscribed),
``tracker/path`` (nav_msgs/Path, the travelled path) and ``tracker/reference_marker``
(visualization_msgs/Marker, arrow at the current reference) every ``viz_period`` s of
stamp time, and the status on ``/diagnostics`` (diagnostic_msgs/DiagnosticArray:
loop period, deadline misses, odom age, rejected inputs, stale stops, saturated
commands, trajectory state and end) every ``diagnostics_period`` s (stamp time in
lockstep, which needs no clock: the tracker has no ``/clock`` subscription there).  The law is
:class:`control.loop.Tracker`; the gain check is :func:`control.gains.gain_from_parameters`.

Lockstep: a command is computed once per odom stamp, from the trajectory sampled at that
stamp (repeats are ignored; an odometry message that arrives before the first trajectory
is answered when it arrives).  With ``wait_for_trajectory: false`` and no trajectory yet,
a command waits until the three reference parts with the odom stamp have arrived
(reference samples are kept by stamp until the odometry measured at that time arrives,
so a plant with odometry latency pairs each measurement with the reference of its
measurement time).  With ``predict_latency`` / ``predict_odom_latency`` /
``predict_lag_v`` / ``predict_lag_w`` the law is evaluated on the state predicted at
the time the command acts (:mod:`control.predictor`; the tracker's *now* is the odom
stamp plus ``predict_odom_latency``, never a clock, so lockstep stays deterministic).
With ``max_linear_accel`` / ``max_angular_accel`` (the base's acceleration limits, 0 =
unknown) each command differs from the previous by at most the limit times ``dt`` and the
predictor models the limits (:class:`control.loop.Tracker`).  Real
time: a command per pose with the latest reference; if pose or reference is
older than ``input_timeout`` the tracker publishes a stop (zero Twist), says so
once, and re-initialises its compensator when fresh data returns.

Trajectories (:mod:`control.trajectory`): a nav_msgs/Path on ``trajectory``
(transient-local; stamps give the times, all zero: a trapezoidal time law with
``cruise_speed``/``max_accel``) or a trajectory_msgs/MultiDOFJointTrajectory on
``trajectory_multidof`` is turned into a trajectory that the tracker samples itself at
each odometry stamp (:class:`control.follow.Follower`): no reference samples are needed
then.  Each new valid trajectory starts a new run; an invalid one is refused with the
reason (logged, counted in ``rejected``) and the previous trajectory stays.  After the
trajectory's end the robot is brought to rest and the tracker says so.  In lockstep the
reference publishes the built-in analytic paths as MultiDOFJointTrajectory knots (exact
to about 1e-14 m) and lockstep runs set ``wait_for_trajectory`` (no sample subscriptions:
a step is odom in, cmd_vel out); without a trajectory and with ``wait_for_trajectory:
false`` the three reference topics are followed (real time: the built-in paths).

Bad samples (non-finite values, non-unit quaternions, wrong frame, stamps that
go backwards) are ignored and counted in ``rejected``; an odom stamp that jumps
ahead by more than ``max_stamp_jump`` re-initialises the compensator (``jumps``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import AccelStamped, PoseStamped, Twist, TwistStamped, Vector3Stamped
from nav_msgs.msg import Odometry
from nav_msgs.msg import Path as PathMsg
from rcl_interfaces.msg import ParameterType
from trajectory_msgs.msg import MultiDOFJointTrajectory
from visualization_msgs.msg import Marker

from .. import topics
from ..control.simulation.follow import (MAX_START_DISTANCE, REST_SPEED, START_TOLERANCE, Follower,
                                         path_errors, trajectory_time)
from ..control.simulation.limits import Limits, within_limits
from ..control.simulation.loop import Tracker, TrackerConfig
from ..control.identification.monitor import (Certificate, LatencyEstimate, MonitorSettings,
                                              MonitorWorker, adapted_prediction,
                                              certificate_from_parameters, evaluate)
from ..control.simulation.trajectory import TrajectoryError
from ..msgconv import tracker_config
from .common import (DATA_QOS, LATCHED_QOS, AdapterNode, Param, StartupError, check_mode,
                     fill_pose, ns_to_stamp, pose_from_odom, reference_from_msgs, run, stamp_ns)
from .trajectory_io import followed_to_multidof, multidof_to_trajectory, path_to_trajectory

PARAMS = [
    Param('K', None, 'gain K, row-major doubles (see K_shape); from a gain file written by '
          '`nonfragile_tracker synthesize`', type=ParameterType.PARAMETER_DOUBLE_ARRAY),
    Param('mode', 'lockstep', 'lockstep (one command per stamp, sim time) or realtime',
          read_only=True),
    Param('K_shape', [2, 4], 'shape [rows, cols] of K', read_only=True),
    Param('dt', 0.01, 'step of the compensator v\' = a (s); equals the plant step', low=1e-6,
          high=10.0, read_only=True),
    Param('max_linear_speed', 1.0, 'limit on |cmd_vel.linear.x| (m/s)', low=1e-9, high=1e3),
    Param('max_angular_speed', 2.0, 'limit on |cmd_vel.angular.z| (rad/s)', low=1e-9, high=1e3),
    Param('max_linear_accel', 0.0, 'the base\'s limit on |dv/dt| (m/s^2): commands change by '
          'at most this times dt per command, the predictor models it, trajectories are '
          'checked and re-timed against it, the certificate monitor skips where it binds; '
          '0 = unknown (off)', low=0.0, high=1e3, read_only=True),
    Param('max_angular_accel', 0.0, 'the base\'s limit on |dw/dt| (rad/s^2): commands change '
          'by at most this times dt per command, the predictor models it, trajectories are '
          'checked and re-timed against it, the certificate monitor skips where it binds; '
          '0 = unknown (off)', low=0.0, high=1e3, read_only=True),
    Param('min_turning_radius', 0.0, 'smallest radius the base can turn on (m; car-like '
          'bases: wheelbase / tan(max steering angle)); a trajectory tighter than it is '
          'refused; 0 = none', low=0.0, high=1e3),
    Param('retime', True, 'check each trajectory against max_linear_speed, '
          'max_linear_accel, max_angular_speed, max_angular_accel and min_turning_radius and '
          're-time one that exceeds them along its path (logged); false: follow as sent',
          read_only=True),
    Param('min_speed', 1e-3, 'floor on |v| in w = (...)/v near the v = 0 singularity (m/s)',
          low=1e-9, high=1e3),
    Param('E', [1.0, 0.0, 0.0, 1.0], 'perturbation matrix E (2x2 row-major)'),
    Param('F', [0.0] * 8, 'perturbation matrix F (2x4 row-major)'),
    Param('Delta', [0.0, 0.0, 0.0, 0.0], 'injected gain perturbation Delta (2x2 row-major); '
          'the applied gain is K + E Delta F'),
    Param('delay_compensation', False, 'follow the delay-consistent reference (zero '
          'steady-state error); needs A_tau and tau', read_only=True),
    Param('A_tau', [0.0] * 16, 'delay matrix for delay_compensation (16 doubles)',
          read_only=True),
    Param('tau', 0.0, 'delay for delay_compensation (s)', low=0.0, high=1e3, read_only=True),
    Param('input_timeout', 0.5, 'realtime: stop if pose or reference is older than this (s)',
          low=1e-6, high=1e6),
    Param('predict_latency', 0.0, 'assumed command-to-motion latency (s): the law is evaluated '
          'on the state predicted at the time the command acts; 0 = no prediction',
          low=0.0, high=10.0, read_only=True),
    Param('predict_odom_latency', 0.0, 'assumed odometry latency (s): now = odom stamp + this',
          low=0.0, high=10.0, read_only=True),
    Param('predict_lag_v', 0.0, 'assumed time constant of the base\'s linear speed (s); '
          '0 = none', low=0.0, high=10.0, read_only=True),
    Param('predict_lag_w', 0.0, 'assumed time constant of the base\'s angular speed (s); '
          '0 = none', low=0.0, high=10.0, read_only=True),
    Param('lockstep_subscribers', 0, 'lockstep: answer an odometry step only once cmd_vel has '
          'this many matched subscribers (plant and recorder: 2); until then the step is left '
          'for the plant to republish; real time: adopt a trajectory re-timed in the '
          'background only then (a recorder gets its first command); 0 = at once',
          read_only=True),
    Param('max_stamp_jump', 1.0, 'an odom stamp further ahead than this (s) is a jump: the '
          'compensator is re-initialised from the measured speed', low=1e-6, high=1e9),
    Param('odom_frame', topics.ODOM_FRAME, 'frame of odometry and trajectories (REP-105)',
          read_only=True),
    Param('cruise_speed', 0.5, 'time law for a Path with zero stamps: cruise speed (m/s)',
          low=1e-6, high=1e3),
    Param('max_accel', 0.5, 'time law for a Path with zero stamps: acceleration limit '
          '(m/s^2)', low=1e-6, high=1e3),
    Param('wait_for_trajectory', False, 'command only from a trajectory received on the '
          'trajectory topics and do not subscribe the per-step samples reference/pose|twist|'
          'accel; set it when the reference publishes a file or relayed trajectory, and in '
          'lockstep (the reference publishes the built-in paths as a trajectory there; '
          '`nonfragile_tracker run` and tracking.launch.py set it)', read_only=True),
    Param('enable_stamped_cmd_vel', False, 'publish cmd_vel as geometry_msgs/TwistStamped '
          '(stamp = command time, frame = base_frame; Nav2 name, Jazzy diff_drive_controller) '
          'instead of Twist', read_only=True),
    Param('base_frame', topics.BASE_FRAME, 'robot body frame (frame_id of TwistStamped)',
          read_only=True),
    Param('viz_period', 0.2, 'period (s, stamp time) of the travelled path and the reference '
          'marker', low=1e-3, high=1e6, read_only=True),
    Param('max_path_poses', 5000, 'travelled path: keep the last this many poses (>= 1)'),
    Param('diagnostics_period', 1.0, 'period (s; lockstep: stamp time, real time: node clock) '
          'of the status on /diagnostics',
          low=1e-3, high=1e6, read_only=True),
    Param('rest_speed', REST_SPEED, 'after the trajectory end, |v| below this (m/s) is at '
          'rest: the tracker commands zero', low=1e-9, high=1e3, read_only=True),
    Param('start_tolerance', START_TOLERANCE, 'a trajectory that starts at rest and is first '
          'followed more than this (s) after its start stamp is re-based to start at that '
          'step (no chase after a reference or planner that started earlier); a start stamp '
          'in the future is waited for at rest', low=0.0, high=1e9, read_only=True),
    Param('max_start_distance', MAX_START_DISTANCE, 'refuse a trajectory whose reference is '
          'further than this (m) from the robot when it starts; 0 = no check', low=0.0,
          high=1e9, read_only=True),
]
#: The certificate monitor's parameters (:mod:`control.monitor`; README "Certificate monitor").
MONITOR_PARAMS = [
    Param('monitor', True, 'estimate the command-to-motion latency and lags online (a worker '
          'thread) and report them against the gain\'s certificate on /diagnostics and '
          f'{topics.CERTIFICATE}', read_only=True),
    Param('monitor_window', 4.0, 'certificate monitor: sliding window of odometry (s)',
          low=0.5, high=600.0),
    Param('monitor_period', 1.0, 'certificate monitor: wall seconds between estimates',
          low=0.05, high=3600.0, read_only=True),
    Param('monitor_max_latency', 0.5, 'certificate monitor: largest latency searched (s)',
          low=0.05, high=2.0),
    Param('monitor_warn_margin', 0.02, 'certificate monitor: WARN when the latency is within '
          'this of the certified upper end (s)', low=0.0, high=10.0),
    Param('monitor_tolerance', 0.01, 'certificate monitor: an estimate this far below the '
          'certified lower end still counts as inside (estimator precision, s)', low=0.0,
          high=1.0),
    Param('monitor_adapt', False, 'certificate monitor: set the predictor\'s latency to the '
          'estimate (minus its uncertainty), clamped to certified_adapt_range; needs the '
          'predictor (predict_latency > 0); off: the commands never depend on the monitor'),
    Param('certified_residual', None, 'certificate: the delay range [h_min, H] (s) the gain '
          'is certified for (latency - predict_latency + the hold of dt; written by '
          'latency-design); unset: the monitor reports the certificate as unknown',
          type=ParameterType.PARAMETER_DOUBLE_ARRAY),
    Param('certified_lag', 0.0, 'certificate: actuator time constant the certificate '
          'includes (s; 0 = none)', low=0.0, high=10.0),
    Param('certified_adapt_range', None, 'certificate: the identified latency interval '
          '[lo, hi] (s) the predictor latency may be adapted within',
          type=ParameterType.PARAMETER_DOUBLE_ARRAY),
]
#: Lockstep: reference samples kept by stamp while waiting for the odometry of that time.
REF_BUFFER = 1000


@dataclass(frozen=True)
class TrackerSettings:
    """The tracker node's validated parameters (see :data:`PARAMS`)."""

    mode: str
    tracker: TrackerConfig
    input_timeout: float
    max_stamp_jump: float
    lockstep_subscribers: int
    frame: str
    cruise_speed: float
    max_accel: float
    wait_for_trajectory: bool
    stamped_cmd_vel: bool
    base_frame: str
    viz_period: float
    max_path_poses: int
    diagnostics_period: float
    rest_speed: float
    monitor: MonitorConfig
    start_tolerance: float = START_TOLERANCE
    max_start_distance: float = MAX_START_DISTANCE
    limits: Limits = Limits()
    retime: bool = True


def tracker_settings(values: dict) -> TrackerSettings:
    """Validate the tracker's parameter values (start-up and runtime sets); InputError if bad.

    The law's configuration is :func:`nonfragile_tracker.msgconv.tracker_config` (shared
    with bag replay); the rest are the node's own settings.
    """
    if values['K'] is None:
        raise StartupError('parameter K is not set; pass a gain file, e.g. '
                           '--ros-args --params-file config/tracker_gains.yaml')
    if values['lockstep_subscribers'] < 0:
        raise StartupError(f'lockstep_subscribers must be 0 or more, got '
                           f'{values["lockstep_subscribers"]}')
    if values['max_path_poses'] < 1:
        raise StartupError(f'max_path_poses must be at least 1, got {values["max_path_poses"]}')
    return TrackerSettings(mode=check_mode(values['mode']), tracker=tracker_config(values),
                           input_timeout=values['input_timeout'],
                           max_stamp_jump=values['max_stamp_jump'],
                           lockstep_subscribers=values['lockstep_subscribers'],
                           frame=values['odom_frame'],
                           cruise_speed=values['cruise_speed'], max_accel=values['max_accel'],
                           wait_for_trajectory=values['wait_for_trajectory'],
                           stamped_cmd_vel=values['enable_stamped_cmd_vel'],
                           base_frame=values['base_frame'], viz_period=values['viz_period'],
                           max_path_poses=values['max_path_poses'],
                           diagnostics_period=values['diagnostics_period'],
                           rest_speed=values['rest_speed'],
                           monitor=monitor_config(values),
                           start_tolerance=values['start_tolerance'],
                           max_start_distance=values['max_start_distance'],
                           limits=Limits.from_values(values), retime=values['retime'])


@dataclass(frozen=True)
class MonitorConfig:
    """The certificate monitor's validated settings (see :data:`MONITOR_PARAMS`)."""

    enabled: bool
    period: float
    adapt: bool
    settings: MonitorSettings
    certificate: Certificate | None


def monitor_config(values: dict) -> MonitorConfig:
    """Validate the monitor's parameters; InputError (MonitorError) if bad.

    The saturation limits are the tracker's; the acceleration limits are its
    ``max_linear_accel`` / ``max_angular_accel`` parameters when it has them (0 = unknown).
    """
    settings = MonitorSettings(
        window=values['monitor_window'], max_latency=values['monitor_max_latency'],
        max_linear_speed=values['max_linear_speed'],
        max_angular_speed=values['max_angular_speed'],
        max_linear_accel=values.get('max_linear_accel') or 0.0,
        max_angular_accel=values.get('max_angular_accel') or 0.0,
        warn_margin=values['monitor_warn_margin'], tolerance=values['monitor_tolerance'])
    cert = certificate_from_parameters(values['certified_residual'], values['certified_lag'],
                                       values['certified_adapt_range'], hold=values['dt'])
    return MonitorConfig(enabled=values['monitor'], period=values['monitor_period'],
                         adapt=values['monitor_adapt'], settings=settings, certificate=cert)


class TrackerNode(AdapterNode[TrackerSettings]):
    """ROS adapter around :class:`control.loop.Tracker` and :class:`control.follow.Follower`."""

    def __init__(self, node_name: str = 'tracker', **node_kwargs):
        super().__init__(node_name, **node_kwargs)
        self.config = cfg = self.bind_parameters(PARAMS + MONITOR_PARAMS, tracker_settings)
        self.mode = cfg.mode
        self.tracker = Tracker(cfg.tracker)
        self.create_subscription(Odometry, topics.ODOM, self._on_odom, DATA_QOS)
        self.frame = cfg.frame
        self.wait_for_trajectory = cfg.wait_for_trajectory
        if not self.wait_for_trajectory:     # only then are the per-step samples read
            self.create_subscription(PoseStamped, topics.REF_POSE, self._on_ref_pose, DATA_QOS)
            self.create_subscription(TwistStamped, topics.REF_TWIST, self._on_ref_twist,
                                     DATA_QOS)
            self.create_subscription(AccelStamped, topics.REF_ACCEL, self._on_ref_accel,
                                     DATA_QOS)
        self.follower: Follower | None = None
        self.last_refusal = ''
        self.last_retime = ''              # what re-timing the last trajectory changed
        self._pool: Any = None             # real time: the re-timing worker thread
        self._retimed: list = []           # (future, origin, source) ready to adopt
        self.origin_ns = 0
        self._announce = False             # tracker/trajectory due at the next step
        self.pub_followed = self.create_publisher(MultiDOFJointTrajectory,
                                                  topics.FOLLOWED_TRAJECTORY, LATCHED_QOS)
        self.create_subscription(PathMsg, topics.TRAJECTORY, self._on_path, LATCHED_QOS)
        self.create_subscription(MultiDOFJointTrajectory, topics.TRAJECTORY_MULTIDOF,
                                 self._on_multidof, LATCHED_QOS)
        # lockstep needs no clock: a command answers an odom stamp, and the time law of an
        # untimed Path starts at the latest odom stamp (no /clock subscription per step)
        self._odom: Odometry | None = None
        self._ref = [None, None, None]
        self._refs: dict[int, list] = {}      # lockstep: stamp -> [pose, twist, accel]
        self.last_stamp = -1
        self.last_odom_stamp = -1
        self.rejected = 0
        self.jumps = 0
        self.commands = 0
        self._stopped = False
        self.saturated = self.stale_stops = self.deadline_misses = 0
        self._rejected_reported = 0
        self._odom_intervals, self._odom_interval_sum = 0, 0.0
        self._last_odom_rx = self._last_ref_rx = 0
        self.base_frame = cfg.base_frame
        if cfg.stamped_cmd_vel:
            self._cmd_msg = TwistStamped()
            self._cmd_msg.header.frame_id = self.base_frame
            self._cmd = self._cmd_msg.twist
        else:
            self._cmd = self._cmd_msg = Twist()
        self.pub_cmd = self.create_publisher(type(self._cmd_msg), topics.CMD_VEL, DATA_QOS)
        self.pub_error = self.create_publisher(Vector3Stamped, topics.TRACKING_ERROR, DATA_QOS)
        self.pub_path = self.create_publisher(PathMsg, topics.TRAVELLED_PATH, DATA_QOS)
        self.pub_marker = self.create_publisher(Marker, topics.REF_MARKER, DATA_QOS)
        self.pub_diag = self.create_publisher(DiagnosticArray, topics.DIAGNOSTICS, DATA_QOS)
        self._err_msg = Vector3Stamped()
        self._err_msg.header.frame_id = self.frame
        self._travelled = PathMsg()
        self._travelled.header.frame_id = self.frame
        self.viz_period_ns = int(cfg.viz_period * 1e9)
        self.max_path_poses = cfg.max_path_poses
        self._last_viz = -(1 << 62)
        mk = self._marker = Marker()
        mk.header.frame_id = self.frame
        mk.ns, mk.id, mk.type, mk.action = 'reference', 0, Marker.ARROW, Marker.ADD
        mk.scale.x, mk.scale.y, mk.scale.z = 0.25, 0.04, 0.04
        mk.color.r, mk.color.g, mk.color.b, mk.color.a = 1.0, 0.3, 0.0, 1.0
        # diagnostics: every diagnostics_period of stamp time in lockstep (no clock there),
        # of the node clock in real time
        self.diag_period_ns = int(cfg.diagnostics_period * 1e9)
        self._last_diag = -(1 << 62)
        if self.mode == 'realtime':
            self.create_timer(cfg.diagnostics_period, self._diagnostics)
        if self.mode == 'realtime':
            self._last_odom_wall: int | None = None     # wall ns of the last input
            self._last_ref_wall: int | None = None
            self.create_timer(0.05, self._watchdog)
        self._monitor_start()

    def apply_config(self, old: TrackerSettings, new: TrackerSettings) -> None:
        """An accepted runtime set (post-set callback): the law uses the new gains/limits."""
        self.tracker.config = new.tracker
        self.max_path_poses = new.max_path_poses
        if self.monitor is not None:
            self.monitor.settings = new.monitor.settings

    # ------------------------------------------------------------------ certificate monitor
    def _monitor_start(self) -> None:
        """Start the certificate monitor's worker (:class:`control.monitor.MonitorWorker`)."""
        m = self.config.monitor
        self.monitor: MonitorWorker | None = None
        self._monitor_last_level = -1
        if not m.enabled:
            return
        self.monitor = MonitorWorker(m.settings, m.period)
        self.pub_cert = self.create_publisher(DiagnosticArray, topics.CERTIFICATE, DATA_QOS)
        if m.certificate is None:
            self.log('info', 'certificate monitor: no certified_residual given (the gain '
                             'file records no certificate): latency is estimated and '
                             'reported, the certificate as unknown')
        if m.adapt and self.tracker.predictor is None:
            self.log('warn', 'monitor_adapt needs the predictor (predict_latency > 0 or a '
                             'predict_* parameter): not adapting')
        self.monitor.start()

    def _monitor_command(self, stamp: int | None, v: float, w: float) -> None:
        """Record a command sent: at the tracker's *now* (lockstep) or the clock (real time)."""
        if self.monitor is None:
            return
        if stamp is None or self.mode == 'realtime':
            t = self.get_clock().now().nanoseconds * 1e-9
        else:
            t = stamp * 1e-9 + self.tracker.config.predict_odom_latency
        self.monitor.window.add_command(t, v, w)

    def _monitor_odom(self, stamp: int, msg: Odometry) -> None:
        """Record the odometry twist measured at ``stamp`` (ns)."""
        if self.monitor is None:
            return
        v, w = msg.twist.twist.linear.x, msg.twist.twist.angular.z
        if math.isfinite(v) and math.isfinite(w):
            self.monitor.window.add_odometry(stamp * 1e-9, v, w)

    def _monitor_diagnostics(self) -> list[DiagnosticStatus]:
        """The certificate status (and, with monitor_adapt, the predictor's new latency)."""
        mon = self.monitor
        if mon is None:
            return []
        m = self.config.monitor
        pred = self.tracker.predictor
        adapting = m.adapt and pred is not None
        P = pred.cmd_latency if pred is not None else 0.0
        est = mon.latest
        if adapting and pred is not None and est is not None and m.certificate is not None:
            new_p = adapted_prediction(est, m.certificate, P, m.settings)
            if new_p != P:
                self.log('info', f'certificate monitor: predict_latency {P:.4f} -> {new_p:.4f} s '
                                 f'(latency estimate {est.latency:.4f} s)')
                pred.cmd_latency = P = new_p
        if self._stopped:
            est = LatencyEstimate(False, 'inputs stale: the tracker has stopped the robot')
        verdict = evaluate(est, m.certificate, P, m.settings, adapting=adapting)
        if verdict.level != self._monitor_last_level:
            self._monitor_last_level = verdict.level
            self.log({1: 'warn', 2: 'error'}.get(verdict.level, 'info'),
                     f'certificate {verdict.name}: {verdict.message}')
        st = DiagnosticStatus(level=bytes([verdict.level]), name=f'{self.get_name()}: certificate',
                              message=verdict.message,
                              hardware_id=self.get_fully_qualified_name())
        vals = dict(verdict.values)
        vals['adaptation'] = 'on' if adapting else 'off'
        vals['estimates'] = str(mon.estimates)
        st.values = [KeyValue(key=k, value=str(v)) for k, v in vals.items()]
        arr = DiagnosticArray()
        arr.header.stamp = self.get_clock().now().to_msg()
        arr.status = [st]
        self.pub_cert.publish(arr)
        return [st]

    def close(self) -> None:
        """Stop the certificate monitor's and the re-timing's workers (idempotent).

        A re-timing in progress is not waited for.
        """
        mon = getattr(self, 'monitor', None)
        if mon is not None:
            mon.stop()
        pool = getattr(self, '_pool', None)
        if pool is not None:
            pool.shutdown(wait=False, cancel_futures=True)
            self._pool = None
        super().close()

    # ------------------------------------------------------------------ inputs
    def _reject(self, what: str) -> None:
        self.rejected += 1
        if self.rejected <= 10 or self.rejected % 1000 == 0:
            self.log('warn', f'ignored {what} (rejected so far: {self.rejected})')

    def _new_trajectory(self, build, source: str) -> None:
        try:
            traj, origin = build()
            if self.config.retime and self.mode == 'realtime' and not traj.is_analytic:
                # real time: check and re-time in a worker thread (a second or two for a
                # lap); odometry keeps being answered meanwhile, and the new trajectory
                # starts at the first odometry after it is ready (re-based if late)
                if self._pool is None:
                    from concurrent.futures import ThreadPoolExecutor
                    self._pool = ThreadPoolExecutor(1, thread_name_prefix='retime')
                fut = self._pool.submit(within_limits, traj, self.config.limits)
                fut.add_done_callback(lambda f: self._retimed.append((f, origin, source)))
                return
            if self.config.retime:
                traj, note = within_limits(traj, self.config.limits)
                self._note_retime(note, source)
        except TrajectoryError as exc:
            return self._refuse(exc)
        self._adopt(traj, origin, source)
        self._try_compute()                # a pose not yet answered gets its command now

    def _note_retime(self, note: str, source: str) -> None:
        if note:
            self.last_retime = note
            self.log('warn', f'trajectory from {source}: {note}')

    def _refuse(self, exc: Exception) -> None:
        self.rejected += 1
        self.last_refusal = str(exc)
        keep = 'the previous trajectory' if self.follower else 'the reference topics'
        self.log('error', f'refused trajectory: {exc}; keeping {keep}')

    def _take_retimed(self) -> None:
        """Adopt a trajectory re-timed in the background (real time), or refuse it."""
        while self._retimed:
            fut, origin, source = self._retimed.pop(0)
            try:
                traj, note = fut.result()
            except TrajectoryError as exc:
                self._refuse(exc)
                continue
            self._note_retime(note, source)
            self._adopt(traj, origin, source)

    def _adopt(self, traj, origin: int, source: str) -> None:
        if self.follower is None:
            self.follower = Follower(self.tracker, traj, self.config.rest_speed,
                                     start_tolerance=self.config.start_tolerance,
                                     max_start_distance=self.config.max_start_distance)
        else:
            self.follower.set_trajectory(traj)
        self.origin_ns = origin
        self._announce = True                 # at the step that first follows it
        self.log('info', f'new trajectory from {source}: {len(traj.knots)} points '
                         f'({traj.kind}), {traj.duration:.3f} s from stamp '
                         f'{origin * 1e-9:.3f} s: starting a new run')

    def _on_path(self, msg: PathMsg) -> None:
        source = f'topic {self.resolve_topic_name(topics.TRAJECTORY)}'
        self._new_trajectory(lambda: path_to_trajectory(
            msg, frame=self.frame, source=source, cruise_speed=self.config.cruise_speed,
            max_accel=self.config.max_accel, now_ns=self._now_ns()),
            source)

    def _now_ns(self) -> int:
        """Now (ns) for an untimed Path: the latest odom stamp in lockstep, else the clock."""
        if self.mode == 'lockstep':
            return max(self.last_odom_stamp, 0)
        return self.get_clock().now().nanoseconds

    def _on_multidof(self, msg: MultiDOFJointTrajectory) -> None:
        source = f'topic {self.resolve_topic_name(topics.TRAJECTORY_MULTIDOF)}'
        self._new_trajectory(lambda: multidof_to_trajectory(msg, frame=self.frame,
                                                            source=source), source)

    def _on_odom(self, msg: Odometry) -> None:
        if msg.header.frame_id != self.frame:
            return self._reject(f'odom in frame {msg.header.frame_id!r} (expected '
                                f'{self.frame!r})')
        if self.mode == 'lockstep' and \
                self.pub_cmd.get_subscription_count() < self.config.lockstep_subscribers:
            return                         # not every cmd_vel subscriber matched: the plant
                                           # republishes the step (its lockstep_retry)
        s = stamp_ns(msg.header.stamp)
        if s <= self.last_odom_stamp:
            if s < self.last_odom_stamp:
                self._reject(f'odom stamp going backwards ({s} < {self.last_odom_stamp} ns)')
            return                         # repeat of the current step: already handled
        jump = s - self.last_odom_stamp
        if self.last_odom_stamp >= 0 and jump > self.config.max_stamp_jump * 1e9:
            self.jumps += 1
            self.log('warn', f'odom stamp jumped {jump * 1e-9:.3f} s '
                             'ahead: re-initialising the compensator from odom')
            self.tracker.reset()
        if self.last_odom_stamp >= 0:
            gap = (s - self.last_odom_stamp) * 1e-9
            self._odom_intervals += 1
            self._odom_interval_sum += gap
            if gap > 1.5 * self.tracker.config.dt:
                self.deadline_misses += 1
        self._odom = msg
        self.last_odom_stamp = s
        if self._retimed and self.pub_cmd.get_subscription_count() >= \
                self.config.lockstep_subscribers:
            self._take_retimed()           # real time: a trajectory re-timed meanwhile
        self._try_compute()                # cmd_vel first: the clock read is bookkeeping
        self._odom_received()
        self._monitor_odom(s, msg)

    def _odom_received(self) -> None:
        """Receipt time of the odometry just handled (diagnostics' odom age, the watchdog).

        Read after the command is published, once (in real time the node clock is the
        wall clock the watchdog compares with), so it costs nothing on the odom -> cmd_vel
        path; callbacks run one at a time, so the watchdog never sees it half done.
        """
        now = self.get_clock().now().nanoseconds
        self._last_odom_rx = now
        if self.mode == 'realtime':
            self._last_odom_wall = now

    def _on_ref(self, i: int, msg) -> None:
        if msg.header.frame_id != self.frame:
            return self._reject(f'reference in frame {msg.header.frame_id!r}')
        self._ref[i] = msg
        self._last_ref_rx = now = self.get_clock().now().nanoseconds
        if self.mode == 'realtime':
            self._last_ref_wall = now       # one clock read: it delays an odom arriving now
        elif self.follower is None and not self.wait_for_trajectory:
            s = stamp_ns(msg.header.stamp)
            if s < self.last_stamp:
                return                     # older than the last odometry used: never needed
            parts = self._refs.get(s)
            if parts is None:
                if len(self._refs) >= REF_BUFFER:
                    del self._refs[min(self._refs)]
                parts = self._refs[s] = [None, None, None]
            parts[i] = msg
            self._try_compute()

    def _on_ref_pose(self, msg):
        self._on_ref(0, msg)

    def _on_ref_twist(self, msg):
        self._on_ref(1, msg)

    def _on_ref_accel(self, msg):
        self._on_ref(2, msg)

    # ------------------------------------------------------------------ law
    def _try_compute(self) -> None:
        if self.follower is not None:
            return self._follow()
        if self.wait_for_trajectory:
            return
        odom = self._odom
        r_pose, r_twist, r_accel = self._ref
        if odom is None or r_pose is None or r_twist is None or r_accel is None:
            return
        if self.mode == 'realtime' and self._stopped:
            return                         # the watchdog publishes the stop
        s = stamp_ns(odom.header.stamp)
        parts = self._ref
        if self.mode == 'lockstep':
            parts = self._refs.get(s)
            if s <= self.last_stamp or parts is None or any(r is None for r in parts):
                return
        pose = pose_from_odom(odom.pose.pose)
        if isinstance(pose, str):
            self._odom = None
            return self._reject(f'odom: {pose}')
        t_ref = stamp_ns(parts[0].header.stamp) * 1e-9
        ref = reference_from_msgs(t_ref, *parts)
        if isinstance(ref, str):
            return self._reject(ref)
        self.last_stamp = s
        if self.mode == 'lockstep':
            for old in [k for k in self._refs if k <= s]:
                del self._refs[old]
        speed = odom.twist.twist.linear.x
        cmd = self.tracker.step(pose[0], pose[1], pose[2], ref,
                                measured_speed=speed if math.isfinite(speed) else 0.0,
                                stamp=s * 1e-9)
        self._publish(cmd.v, cmd.w, s)
        self._outputs(s, pose, ref, cmd)

    def _follow(self) -> None:
        """One command from the own trajectory, sampled at the odometry stamp."""
        odom, f = self._odom, self.follower
        if odom is None or f is None or (self.mode == 'realtime' and self._stopped):
            return
        s = stamp_ns(odom.header.stamp)
        if s <= self.last_stamp:
            return
        pose = pose_from_odom(odom.pose.pose)
        if isinstance(pose, str):
            self._odom = None
            return self._reject(f'odom: {pose}')
        self.last_stamp = s
        speed = odom.twist.twist.linear.x
        was_finished, was_started = f.finished, f.started
        cmd = f.step(pose[0], pose[1], pose[2], trajectory_time(s, self.origin_ns),
                     measured_speed=speed if math.isfinite(speed) else 0.0)
        announce, self._announce = self._announce, False
        if f.started and not was_started:
            self._started(f, s, announce)
        elif announce:
            self._announce_followed(f, s)
        if f.finished and not was_finished:
            e = math.hypot(cmd.error[0], cmd.error[2])
            self.log('info',
                f'trajectory finished: at rest at t = {f.finished_at:.3f} s (trajectory '
                f'end {f.trajectory.t_end:.3f} s), position error {e:.4f} m; waiting for '
                'a new trajectory')
            self._diagnostics()
        self._publish(cmd.v, cmd.w, s)
        self._outputs(s, pose, f.last_ref, cmd)

    def _started(self, f: Follower, stamp: int, announce: bool) -> None:
        """Say how the trajectory started: re-based, on its stamps, or refused.

        ``stamp`` is the odometry stamp of this step; ``announce``: the trajectory was
        adopted at it (:meth:`_announce_followed`).
        """
        if f.refused:
            self.rejected += 1
            self.last_refusal = f.refused
            self.log('error', f'refused trajectory: {f.refused}; waiting at rest for a new '
                              'trajectory')
            self._diagnostics()
            return
        elif f.offset:
            self.log('info', f'trajectory started {f.offset:.3f} s after its start stamp: '
                             're-based to start now (its own speed profile, no chase)')
        if announce or f.offset:              # re-based after its adoption: again
            self._announce_followed(f, stamp)

    def _announce_followed(self, f: Follower, stamp: int) -> None:
        """Publish what the tracker follows, as it follows it, on tracker/trajectory.

        Stamped with the odometry stamp ``stamp`` of the step that adopted it (its first
        command; or of its re-based start), its points' times counted from there: a bag
        replay adopts it at exactly that odometry, however long a re-timing took.
        """
        if not f.trajectory.is_analytic and not f.refused:
            self.pub_followed.publish(followed_to_multidof(
                f.trajectory, self.origin_ns + int(round(f.offset * 1e9)), self.frame,
                header_ns=stamp))

    def _publish(self, v: float, w: float, stamp: int | None = None) -> None:
        """cmd_vel as Twist or, with enable_stamped_cmd_vel, TwistStamped.

        The stamped header carries the command time - the odometry stamp it answers in
        lockstep, the node clock's now in real time (what diff_drive_controller checks
        against its cmd_vel_timeout) - and the body frame.
        """
        c = self.tracker.config
        if not (math.isfinite(v) and math.isfinite(w)):     # never reached by the law
            v = w = 0.0
        self._cmd.linear.x = max(-c.max_linear_speed, min(c.max_linear_speed, v))
        self._cmd.angular.z = max(-c.max_angular_speed, min(c.max_angular_speed, w))
        if self._cmd_msg is not self._cmd:
            if stamp is None or self.mode == 'realtime':
                stamp = self.get_clock().now().nanoseconds
            ns_to_stamp(stamp, self._cmd_msg.header.stamp)
        self.pub_cmd.publish(self._cmd_msg)
        self.commands += 1
        self._monitor_command(stamp, self._cmd.linear.x, self._cmd.angular.z)

    # ------------------------------------------------------------------ outputs
    def _outputs(self, stamp: int, pose, ref, cmd) -> None:
        """Tracking error every step, travelled path and reference marker at viz_period."""
        if cmd.saturated:
            self.saturated += 1
        if self.mode == 'lockstep' and stamp - self._last_diag >= self.diag_period_ns:
            self._last_diag = stamp
            self._diagnostics()
        if ref is None:
            return
        if self.pub_error.get_subscription_count():
            along, cross, head = path_errors(pose[0], pose[1], pose[2], ref)
            m = self._err_msg
            ns_to_stamp(stamp, m.header.stamp)
            m.vector.x, m.vector.y, m.vector.z = along, cross, head
            self.pub_error.publish(m)
        if stamp - self._last_viz < self.viz_period_ns:
            return
        self._last_viz = stamp
        ps = PoseStamped()
        ps.header.frame_id = self.frame
        ns_to_stamp(stamp, ps.header.stamp)
        fill_pose(ps.pose, pose[0], pose[1], pose[2])
        self._travelled.poses.append(ps)
        if len(self._travelled.poses) > self.max_path_poses:
            del self._travelled.poses[:len(self._travelled.poses) - self.max_path_poses]
        self._travelled.header.stamp = ps.header.stamp
        if self.pub_path.get_subscription_count():
            self.pub_path.publish(self._travelled)
        if self.pub_marker.get_subscription_count():
            mk = self._marker
            mk.header.stamp = ps.header.stamp
            fill_pose(mk.pose, ref.x, ref.y, ref.heading)
            self.pub_marker.publish(mk)

    def _diagnostics(self) -> None:
        """Tracker status on /diagnostics (diagnostic_msgs/DiagnosticArray)."""
        now = self.get_clock().now().nanoseconds
        f = self.follower
        if f is None:
            state = 'waiting for a trajectory' if self.wait_for_trajectory else \
                'following the reference topics'
        elif f.refused:
            state = 'trajectory refused at its start (too far): at rest'
        elif not f.started:
            state = 'waiting at rest for the trajectory\'s start stamp'
        elif f.finished:
            state = f'trajectory finished, at rest since t = {f.finished_at:.3f} s'
        elif f.ended:
            state = 'trajectory ended, coming to rest'
        else:
            state = 'following the trajectory'
        n = self._odom_intervals
        period = self._odom_interval_sum / n if n else 0.0
        odom_age = (now - self._last_odom_rx) * 1e-9 if self._last_odom_rx else math.inf
        ref_age = (now - self._last_ref_rx) * 1e-9 if self._last_ref_rx else math.inf
        level = DiagnosticStatus.OK
        msgs = [state]
        if self._stopped:
            level = DiagnosticStatus.WARN
            msgs.append('inputs stale: stopped')
        if self.rejected > self._rejected_reported:
            level = max(level, DiagnosticStatus.WARN)
            msgs.append(f'{self.rejected - self._rejected_reported} input(s) rejected')
        self._rejected_reported = self.rejected
        st = DiagnosticStatus(level=level, name=f'{self.get_name()}: tracking',
                              message='; '.join(msgs),
                              hardware_id=self.get_fully_qualified_name())
        vals = {'loop period (s)': f'{period:.6f}', 'deadline misses': self.deadline_misses,
                'odom age (s)': f'{odom_age:.3f}',
                'reference age (s)': 'not used (own trajectory)' if f else f'{ref_age:.3f}',
                'commands': self.commands,
                'rejected inputs': self.rejected, 'stale stops': self.stale_stops,
                'saturated commands': self.saturated, 'stamp jumps': self.jumps,
                'trajectory': state,
                'trajectory end (s)': f'{f.trajectory.t_end:.3f}' if f else 'none',
                'trajectory re-based by (s)': f'{f.offset:.6f}' if f else 'none',
                'last refused trajectory': self.last_refusal or 'none',
                'last re-timed trajectory': self.last_retime or 'none'}
        st.values = [KeyValue(key=k, value=str(v)) for k, v in vals.items()]
        arr = DiagnosticArray()
        arr.header.stamp = self.get_clock().now().to_msg()
        arr.status = [st, *self._monitor_diagnostics()]
        self.pub_diag.publish(arr)

    def _watchdog(self) -> None:
        own = self.follower is not None      # own trajectory: reference samples not needed
        odom_t, ref_t = self._last_odom_wall, self._last_ref_wall
        if odom_t is None or (ref_t is None and not own):
            return                          # not started yet: nothing has been commanded
        now = self.get_clock().now().nanoseconds
        limit = self.config.input_timeout * 1e9
        inputs = [('odom', odom_t)]
        if not own and ref_t is not None:
            inputs.append(('reference', ref_t))
        stale = [name for name, t in inputs if now - t > limit]
        if stale:
            if not self._stopped:
                self.log('warn', f'no {" or ".join(stale)} for more than '
                                 f'{self.config.input_timeout} s: publishing stop')
                self._stopped = True
                self.stale_stops += 1
                self.tracker.reset()
            self._publish(0.0, 0.0)
        elif not stale and self._stopped:
            self.log('info', 'inputs fresh again: resuming')
            self._stopped = False


def main(args=None) -> int:
    """Console entry point of the tracker node; returns the exit code (see :func:`common.run`)."""
    return run(TrackerNode, args)


if __name__ == '__main__':
    # `python -m nonfragile_tracker.nodes.tracker` is the console script's process: the
    # entry's signal handling, stack dumps on SIGUSR1 and tear-down deadline
    import sys

    from nonfragile_tracker.nodes.entry import main as node_main
    sys.exit(node_main('tracker', sys.argv))
