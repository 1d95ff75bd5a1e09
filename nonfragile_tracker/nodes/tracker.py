"""``tracker``: the non-fragile tracking law with K from parameters, as a managed node.

A lifecycle node (``autostart`` configures and activates it at start; else a lifecycle
manager does): configure validates the parameters (:func:`tracker_settings`) and makes the
publishers, activate subscribes odometry and the trajectories, deactivate and errors send
a zero command.  Each odometry message gets at most one command (``cmd_vel``) from
:class:`.control.simulation.tracker.Tracker`, following the trajectory it samples itself
(:class:`.control.simulation.follow.Follower`); which inputs it takes, and when a command is
due, are the ROS-free rules of :mod:`.tracker_inputs`, shared with the bag replay.  It also
publishes its errors, path, marker, the followed trajectory and ``/diagnostics`` (timing,
refusals, the certificate monitor: :mod:`.control.identification.monitor`).

See doc/ros-interface.md, section "tracker" (its "Input rules" and "Certificate monitor"),
and doc/nav2.md, section "The lifecycle".
"""
from __future__ import annotations

import math
import os
import traceback
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, replace
from functools import partial
from typing import Any, cast

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import AccelStamped, PoseStamped, Twist, TwistStamped, Vector3Stamped
from nav_msgs.msg import Odometry
from nav_msgs.msg import Path as PathMsg
from rcl_interfaces.msg import ParameterType
from rclpy.node import Node
from rclpy.lifecycle import LifecycleNodeMixin, LifecycleState, TransitionCallbackReturn
from rclpy.serialization import deserialize_message
from rclpy.subscription import Subscription
from trajectory_msgs.msg import MultiDOFJointTrajectory
from visualization_msgs.msg import Marker

from ..interface import topics
from ..control.simulation.follow import Follower, path_errors
from ..control.simulation.interfaces import DEFAULT_CONTROLLER, Controller
from ..control.simulation.tracker import Command, Tracker, TrackerConfig
from ..control.simulation.predictor import LatencyPredictor
from ..control.identification.tuning import Tuned
from ..control.identification.monitor import (Certificate, LatencyEstimate, MonitorSettings,
                                              MonitorWorker, adapted_prediction,
                                              certificate_from_parameters, evaluate)
from ..control.simulation.limits import MIN_ACCEL_FRACTION
from ..control.simulation.reference import RefSample
from ..control.simulation.replan import Nearest
from ..control.simulation.timing import period_disagreement
from ..control.simulation.trajectory import Trajectory, TrajectoryError
from ..control.simulation.wrappers import clamp_command
from ..interface.msgconv import MultiDOFArrays, multidof_from_cdr, tracker_config
from ..interface.robot import check_topic_name
from ..interface.tracker_inputs import (INPUT_DEFAULTS, MONITOR_DEFAULTS, InputRules, Rejection,
                                        Step, TrackerInputs, input_rules, monitor_settings,
                                        stale_inputs)
from .common import (DATA_QOS, LATCHED_QOS, AdapterNode, Param, StartupError, check_mode,
                     fill_pose, ns_to_stamp, require_at_least, run, settings_from)
from .trajectory_io import followed_to_multidof

#: The input rules' parameters take their defaults from the rules' module (the replay's too).
_RULES = INPUT_DEFAULTS
PARAMS = [
    Param('K', None, 'gain K, row-major doubles (see K_shape); from a gain file written by '
          '`nonfragile_tracker synthesize`', type=ParameterType.PARAMETER_DOUBLE_ARRAY),
    Param('mode', 'lockstep', 'lockstep (one command per stamp, sim time) or realtime',
          read_only=True),
    Param('controller', DEFAULT_CONTROLLER, 'the tracking law, "package.module:factory" (a '
          'factory of the tracker\'s settings making a Controller, as Nav2 names its plugins); '
          'default our certified law', read_only=True),
    Param('K_shape', [2, 4], 'shape [rows, cols] of K', read_only=True),
    Param('dt', 0.0, 'step of the compensator v\' = a (s): 0 = from the odometry stamps (the '
          'interval that passed, the measured period); > 0 = an override used whatever the '
          'stamps say (reported on /diagnostics when it disagrees with the odometry)',
          low=0.0, high=10.0, read_only=True),
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
    Param('retime', _RULES['retime'], 'check each trajectory against max_linear_speed, '
          'max_linear_accel, max_angular_speed, max_angular_accel and min_turning_radius and '
          're-time one that exceeds them along its path (logged); false: follow as sent',
          read_only=True),
    Param('trajectory_accel_fraction', _RULES['trajectory_accel_fraction'], 'share of '
          'max_linear_accel and max_angular_accel a trajectory may use (checked and re-timed '
          'against it); the rest is left to the feedback, which a reference at the whole '
          'limit leaves no acceleration to correct an error with; 1 = all of it',
          low=MIN_ACCEL_FRACTION, high=1.0, read_only=True),
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
    Param('gain_v', 1.0, 'the base\'s static speed gain (speed reached per commanded unit, '
          'identify\'s gain_v): the command sent is the law\'s speed over it; 1 = none',
          low=0.05, high=20.0, read_only=True),
    Param('gain_w', 1.0, 'the base\'s static turn-rate gain (identify\'s gain_w; a '
          'skid-steer turns at about 0.6-0.7 of its command): the command sent is the law\'s '
          'turn rate over it; 1 = none', low=0.05, high=20.0, read_only=True),
    Param('side_slip_rates', [0.0], 'turn rates |w| (rad/s, increasing from 0) of the base\'s '
          'side-slip table (identify --truth\'s side_slip_rates)', read_only=True),
    Param('side_slip', [0.0], 'side-slip coefficient c (s) at each of side_slip_rates: the '
          'base slides outward at c(|w|) v w, which its odometry does not see; the tracker '
          'adds that slide to the odometry\'s position; all 0 = none', read_only=True),
    Param('lockstep_subscribers', 0, 'lockstep: answer an odometry step only once cmd_vel has '
          'this many matched subscribers (plant and recorder: 2); until then the step is left '
          'for the plant to republish; real time: adopt a trajectory re-timed in the '
          'background only then (a recorder gets its first command); 0 = at once',
          read_only=True),
    Param('max_stamp_jump', _RULES['max_stamp_jump'], 'an odom stamp further ahead than this '
          '(s) is a jump: the compensator is re-initialised from the measured speed',
          low=1e-6, high=1e9),
    Param('odom_frame', _RULES['odom_frame'], 'frame of odometry, reference samples and '
          'trajectories (REP-105); inputs in another frame are refused',
          read_only=True),
    Param('cruise_speed', _RULES['cruise_speed'], 'time law for a Path with zero stamps: '
          'cruise speed (m/s)', low=1e-6, high=1e3),
    Param('max_accel', _RULES['max_accel'], 'time law for a Path with zero stamps: '
          'acceleration limit (m/s^2)', low=1e-6, high=1e3),
    Param('wait_for_trajectory', _RULES['wait_for_trajectory'], 'command only from a '
          'trajectory received on the trajectory topics and do not subscribe the per-step '
          'samples reference/pose|twist|accel; set it when the reference publishes a file or '
          'relayed trajectory, and in lockstep (the reference publishes the built-in paths as '
          'a trajectory there; `nonfragile_tracker run` and tracking.launch.py set it)',
          read_only=True),
    Param('odom_topic', topics.ODOM, 'odometry topic to subscribe (nav_msgs/Odometry; robot '
          'file); a remapping of it still applies', read_only=True),
    Param('cmd_vel_topic', topics.CMD_VEL, 'velocity command topic to publish (robot file); a '
          'remapping of it still applies', read_only=True),
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
    Param('rest_speed', _RULES['rest_speed'], 'after the trajectory end, |v| below this (m/s) '
          'is at rest: the tracker commands zero', low=1e-9, high=1e3, read_only=True),
    Param('start_tolerance', _RULES['start_tolerance'], 'a trajectory that starts at rest '
          'and is first followed more than this (s) after its start stamp is re-based to start '
          'at that step (no chase after a reference or planner that started earlier); a start '
          'stamp in the future is waited for at rest', low=0.0, high=1e9, read_only=True),
    Param('replan', _RULES['replan'], 'an untimed Path (a planner\'s plan, Nav2\'s /plan) that '
          'arrives while a trajectory is driven continues the motion: cut at its point '
          'nearest the reference, timed from the current reference speed, no new run (no stop '
          'between plans); false: every trajectory starts a new run', read_only=True),
    Param('replan_search_distance', _RULES['replan_search_distance'], 'replan: the nearest '
          'point of a new plan is looked for within this arc length (m) of its start (Nav2: '
          'max_robot_pose_search_dist)', low=1e-3, high=1e6, read_only=True),
    Param('override_tolerance', _RULES['override_tolerance'], 'commands overridden downstream '
          '(Nav2\'s collision_monitor between cmd_vel_nav and the base, scaling or zeroing '
          'them): a measured speed more than this (m/s) below the last command for '
          'override_time re-anchors the reference at the robot from its measured speed and '
          'restarts the compensator there (no wind-up, no leap when released; reported on '
          '/diagnostics); 0 = not watched', low=0.0, high=1e3, read_only=True),
    Param('override_time', _RULES['override_time'], 'override_tolerance: how long (s) the '
          'shortfall must last, and the period of re-anchoring while it does', low=1e-3,
          high=1e3, read_only=True),
    Param('max_start_distance', _RULES['max_start_distance'], 'refuse a trajectory whose '
          'reference is further than this (m) from the robot when it starts; 0 = no check', low=0.0,
          high=1e9, read_only=True),
    # the managed node (the nav2_util::LifecycleNode / nav2_lifecycle_manager pattern)
    Param('autostart', True, 'configure and activate at start (ros2 run, the launch files; a '
          'refused configure ends the process with exit 2); false: stay unconfigured until a '
          'lifecycle manager (nav2_lifecycle_manager, lifecycle_msgs/srv/ChangeState) '
          'configures and activates it', read_only=True),
]
#: The certificate monitor's parameters (:mod:`.control.identification.monitor`).
MONITOR_PARAMS = [
    Param('monitor', INPUT_DEFAULTS['monitor'], 'estimate the command-to-motion latency '
          'and lags online (a worker thread; with monitor_tune on the odometry stamps) and '
          'report them against the gain\'s certificate on /diagnostics and '
          f'{topics.CERTIFICATE}; false: no estimates, so no monitor_tune', read_only=True),
    Param('monitor_window', MONITOR_DEFAULTS['monitor_window'],
          'certificate monitor: sliding window of odometry (s)', low=0.5, high=600.0),
    Param('monitor_period', MONITOR_DEFAULTS['monitor_period'], 'certificate monitor: wall '
          'seconds between estimates (with monitor_tune: seconds of odometry-stamp time)',
          low=0.05, high=3600.0, read_only=True),
    Param('monitor_max_latency', MONITOR_DEFAULTS['monitor_max_latency'],
          'certificate monitor: largest latency searched (s)', low=0.05, high=2.0),
    Param('monitor_warn_margin', MONITOR_DEFAULTS['monitor_warn_margin'], 'certificate '
          'monitor: WARN when the latency is within this of the certified upper end (s)',
          low=0.0, high=10.0),
    Param('monitor_tolerance', MONITOR_DEFAULTS['monitor_tolerance'], 'certificate monitor: '
          'an estimate this far below the '
          'certified lower end still counts as inside (estimator precision, s)', low=0.0,
          high=1.0),
    Param('monitor_adapt', False, 'certificate monitor: set the predictor\'s latency to the '
          'estimate (minus its uncertainty), clamped to certified_adapt_range; needs the '
          'predictor (predict_latency > 0); off: the monitor\'s worker never sets the '
          'predictor (monitor_tune does, on the stamps)'),
    Param('monitor_tune', INPUT_DEFAULTS['monitor_tune'], 'tune the predictor to the '
          'monitor\'s estimate: every monitor_period of odometry-stamp time, in the odometry '
          'callback (deterministic, also in lockstep), the predicted latency becomes the '
          'estimate less its uncertainty and the lags the estimated ones within certified_lag; '
          'a tracker on a base it was not told about compensates what it measures (the '
          'monitor then reports these estimates; on by default; monitor false: no tuning); '
          f'each retune is published on {topics.TUNING}', read_only=True),
    Param('tuning_schedule', INPUT_DEFAULTS['tuning_schedule'], 'with monitor_tune: retunes '
          'to apply instead of estimating, "stamp_ns latency lag_v lag_w" (ns, s) separated '
          f'by ";", each at the first odometry stamped at or after it (a replay applies the '
          f'ones a tracker published on {topics.TUNING}); empty: estimate', read_only=True),
    Param('certified_residual', None, 'certificate: the delay range [h_min, H] (s) the gain '
          'is certified for (latency - predict_latency + the hold of a command; written by '
          'latency-design); unset: the monitor reports the certificate as unknown',
          type=ParameterType.PARAMETER_DOUBLE_ARRAY),
    Param('certified_lag', 0.0, 'certificate: actuator time constant the certificate '
          'includes (s; 0 = none)', low=0.0, high=10.0),
    Param('certified_adapt_range', None, 'certificate: the identified latency interval '
          '[lo, hi] (s) the predictor latency may be adapted within',
          type=ParameterType.PARAMETER_DOUBLE_ARRAY),
]


@dataclass(frozen=True)
class TrackerSettings:
    """The tracker node's validated parameters (see ``PARAMS``)."""

    mode: str
    tracker: TrackerConfig
    rules: InputRules              #: the input rules (:mod:`.interface.tracker_inputs`)
    input_timeout: float
    lockstep_subscribers: int
    stamped_cmd_vel: bool
    base_frame: str
    odom_topic: str
    cmd_vel_topic: str
    viz_period: float
    max_path_poses: int
    diagnostics_period: float
    monitor: MonitorConfig


def tracker_settings(values: dict[str, Any]) -> TrackerSettings:
    """Validate the tracker's parameter values (start-up and runtime sets); InputError if bad.

    The law's configuration is :func:`nonfragile_tracker.interface.msgconv.tracker_config` and
    the input rules :func:`nonfragile_tracker.interface.tracker_inputs.input_rules` (both shared
    with bag replay); the rest are the node's own settings.

    Parameters
    ----------
    values : dict
        The tracker's parameter values by name (``PARAMS``, :data:`MONITOR_PARAMS`).

    Returns
    -------
    TrackerSettings
    """
    if values['K'] is None:
        raise StartupError('parameter K is not set; pass a gain file, e.g. '
                           '--ros-args --params-file config/tracker_gains.yaml')
    require_at_least(values, 'lockstep_subscribers', 0)
    require_at_least(values, 'max_path_poses', 1)
    for name in ('odom_topic', 'cmd_vel_topic'):
        check_topic_name(values[name], name)
    return settings_from(TrackerSettings, values, mode=check_mode(values['mode']),
                         tracker=tracker_config(values), rules=input_rules(values),
                         stamped_cmd_vel=values['enable_stamped_cmd_vel'],
                         monitor=monitor_config(values))


@dataclass(frozen=True)
class MonitorConfig:
    """The certificate monitor's validated settings (see :data:`MONITOR_PARAMS`)."""

    enabled: bool
    period: float
    adapt: bool
    settings: MonitorSettings
    certificate: Certificate | None
    tune: bool = False             #: ``monitor_tune`` as set (in effect only with the monitor)


def monitor_config(values: dict[str, Any]) -> MonitorConfig:
    """Validate the monitor's parameters; InputError (MonitorError) if bad.

    The saturation limits are the tracker's; the acceleration limits are its
    ``max_linear_accel`` / ``max_angular_accel`` parameters when it has them (0 = unknown).

    Parameters
    ----------
    values : dict
        Parameter values by name: :data:`MONITOR_PARAMS` and the tracker's limits and ``dt``.

    Returns
    -------
    MonitorConfig
    """
    settings = monitor_settings(values)
    cert = certificate_from_parameters(values['certified_residual'], values['certified_lag'],
                                       values['certified_adapt_range'], hold=values['dt'])
    return MonitorConfig(enabled=values['monitor'], period=values['monitor_period'],
                         adapt=values['monitor_adapt'], settings=settings, certificate=cert,
                         tune=bool(values.get('monitor_tune')))


#: Lockstep: a trajectory of more points is built and re-timed in the worker thread, its
#: callback waiting for it with a look for a stop signal every 50 ms (``_stoppable``).
SYNC_POINTS = 2000


def _points(msg: Any) -> int:
    """Points of a trajectory message (nav_msgs/Path, MultiDOFJointTrajectory, arrays)."""
    if isinstance(msg, MultiDOFArrays):
        return int(msg.t_ns.size)
    return len(getattr(msg, 'points', None) or getattr(msg, 'poses', None) or ())


def _where(exc: BaseException) -> str:
    """Where ``exc`` was raised: ``file:line in function`` of its innermost frame."""
    tb = traceback.extract_tb(exc.__traceback__)
    if not tb:
        return 'no traceback'
    f = tb[-1]
    return f'{os.path.basename(f.filename)}:{f.lineno} in {f.name}'


def guard_transitions(node: LifecycleNodeMixin) -> None:
    """Make ``node``'s ChangeState service refuse a transition its state does not offer.

    rclpy 7.1.6 raises ``RCLError`` out of the service callback for one (``ros2 lifecycle
    set tracker activate`` on an unconfigured node), which ends the executor's spin with a
    traceback; refused here instead (``success: false``, logged).

    Parameters
    ----------
    node : rclpy.lifecycle.LifecycleNodeMixin
        A lifecycle node with its communication interface.
    """
    service = node._service_change_state   # noqa: SLF001 - rclpy's own service object
    change = service.callback

    def checked(req: Any, resp: Any) -> Any:
        sm = node._state_machine            # noqa: SLF001
        ids = {t[0]: t[1] for t in sm.available_transitions}
        tid = req.transition.id
        if req.transition.label:
            tid = next((i for i, lab in ids.items() if lab == req.transition.label), -1)
        if tid not in ids:
            label = req.transition.label or str(req.transition.id)
            Node.get_logger(cast(Node, node)).error(    # (rclpy's, untyped)
                f'refused lifecycle transition {label!r} in state '
                f'{sm.current_state[1]!r}; available: {sorted(ids.values())}')
            resp.success = False
            return resp
        return change(req, resp)
    service.callback = checked


class TrackerNode(LifecycleNodeMixin, AdapterNode[TrackerSettings]):
    """ROS adapter around the tracking law and the trajectory follower.

    :class:`.control.simulation.tracker.Tracker` and :class:`.control.simulation.follow.Follower`.

    Its inputs go through the rules of :mod:`nonfragile_tracker.interface.tracker_inputs`
    (``inputs``, a :class:`.TrackerInputs`, which holds the law and the input state).

    Parameters
    ----------
    node_name : str, optional
        ``tracker``: parameter files address it as ``/**/tracker`` (``run``, the launch
        files), so a node of another name needs a section of its own.
    **node_kwargs
        rclpy ``Node`` keyword arguments (:class:`~nonfragile_tracker.nodes.common.AdapterNode`).
    """

    def __init__(self, node_name: str = 'tracker', **node_kwargs: Any):
        AdapterNode.__init__(self, node_name, **node_kwargs)
        LifecycleNodeMixin.__init__(self)
        guard_transitions(self)
        self._configured = self._active = False
        self._starting = True              # the constructor: a refusal is a StartupError
        self._refusal = ''                 # why the last configure was refused
        self._error: str | None = None     # an error while active (-> ErrorProcessing)
        self._error_timer: Any = None
        self._entities: list[Any] = []     # what activation made (subscriptions, timers)
        self.declare_bound(PARAMS + MONITOR_PARAMS, tracker_settings)
        self.autostart = bool(self.get_parameter('autostart').value)
        if self.autostart:                 # ros2 run, the launch files: at once, as before
            if self.trigger('configure') != TransitionCallbackReturn.SUCCESS:
                raise StartupError(self._refusal or f'{self.get_name()}: configure failed')
            if self.trigger('activate') != TransitionCallbackReturn.SUCCESS:
                raise StartupError(self._refusal or f'{self.get_name()}: activate failed')
        self._starting = False

    # ------------------------------------------------------------------ lifecycle
    @property
    def configured(self) -> bool:
        """Whether the node is configured (inactive or active): its configuration in force."""
        return self._configured

    @property
    def active(self) -> bool:
        """Whether the node is active: it subscribes its inputs and commands."""
        return self._active

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Configure: validate the parameters, gain and robot file, make the outputs.

        A refusal names the key (the validators' messages), is logged and leaves the node
        unconfigured (``FAILURE``).

        Parameters
        ----------
        state : rclpy.lifecycle.LifecycleState
            The state the transition starts from.

        Returns
        -------
        rclpy.lifecycle.TransitionCallbackReturn
        """
        try:
            cfg = self.configure_from_parameters()
        except StartupError as exc:
            self._refusal = str(exc)
            if not self._starting:         # the constructor's refusal is the [FATAL] line
                self.log('error', f'configure refused: {exc}; staying unconfigured')
            return TransitionCallbackReturn.FAILURE
        return self._transition('configure', partial(self._make_outputs, cfg))

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Activate: subscribe the inputs; commands from the next odometry on.

        Parameters
        ----------
        state : rclpy.lifecycle.LifecycleState
            The state the transition starts from.

        Returns
        -------
        rclpy.lifecycle.TransitionCallbackReturn
        """
        return self._transition('activate', self._subscribe)

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Deactivate: command zero, unsubscribe, forget the trajectory (stays configured).

        After an error while active (``_fail``) the same, then ``ERROR``: the state
        machine goes on to ErrorProcessing (:meth:`on_error`).

        Parameters
        ----------
        state : rclpy.lifecycle.LifecycleState
            The state the transition starts from.

        Returns
        -------
        rclpy.lifecycle.TransitionCallbackReturn
        """
        ret = self._transition('deactivate', self._unsubscribe)
        return TransitionCallbackReturn.ERROR if self._error is not None else ret

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Clean up: release the outputs, workers and state (back to unconfigured).

        Parameters
        ----------
        state : rclpy.lifecycle.LifecycleState
            The state the transition starts from.

        Returns
        -------
        rclpy.lifecycle.TransitionCallbackReturn
        """
        return self._transition('cleanup', self._release)

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Shut down from any state: zero if active, release everything; the process ends.

        Parameters
        ----------
        state : rclpy.lifecycle.LifecycleState
            The state the transition starts from.

        Returns
        -------
        rclpy.lifecycle.TransitionCallbackReturn
        """
        self.finished = True               # run(): the spin ends, exit code 0
        return self._transition('shutdown', self._finalize)

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        """ErrorProcessing: command zero, release everything; back to unconfigured.

        Parameters
        ----------
        state : rclpy.lifecycle.LifecycleState
            The state whose transition failed.

        Returns
        -------
        rclpy.lifecycle.TransitionCallbackReturn
        """
        self.log('error', f'error processing ({self._error or "a transition failed"}): '
                          'zero commanded, everything released; unconfigured (configure '
                          'again to resume)')
        ret = self._transition('error processing', self._finalize)
        self._error = None
        return ret

    def _transition(self, name: str, work: Any) -> TransitionCallbackReturn:
        """Run a transition's ``work``; an unexpected error is logged and is ``ERROR``.

        rclpy turns an exception in a transition callback into ``ERROR`` without a word.
        """
        try:
            work()
        except Exception as exc:  # noqa: BLE001 - said here, then ErrorProcessing
            if self._starting:
                raise
            self.log('error', f'{name} failed: {type(exc).__name__}: {exc} '
                              f'({_where(exc)})')
            return TransitionCallbackReturn.ERROR
        if not self._starting:
            self.log('info', f'{name}: {self.lifecycle_state()}')
        return TransitionCallbackReturn.SUCCESS

    def trigger(self, transition: str) -> TransitionCallbackReturn:
        """Run a lifecycle transition as a manager's ChangeState would.

        Parameters
        ----------
        transition : str
            ``configure``, ``activate``, ``deactivate``, ``cleanup`` or ``shutdown``.

        Returns
        -------
        rclpy.lifecycle.TransitionCallbackReturn
        """
        ret: TransitionCallbackReturn = getattr(self, f'trigger_{transition}')()
        return ret

    def lifecycle_state(self) -> str:
        """The lifecycle state's label after the running transition (or now).

        Returns
        -------
        str
        """
        if self.finished:
            return 'finalized'
        return 'active' if self._active else 'inactive' if self._configured else \
            'unconfigured'

    def _make_outputs(self, cfg: TrackerSettings) -> None:
        """Configure's work: the rules and the law, the publishers, the monitor."""
        if self._error_timer is not None:
            self.destroy_timer(self._error_timer)
            self._error_timer = None
        self.config = cfg
        self.mode = cfg.mode
        # the input rules and the law: one ROS-free object, shared with bag replay
        self.inputs = TrackerInputs(cfg.tracker, cfg.rules, on_reject=self._on_reject,
                                    on_jump=self._on_jump, on_splice=self._on_splice,
                                    on_override=self._on_override)
        self.tracker: Controller = self.inputs.tracker
        self.frame = cfg.rules.frame
        self.wait_for_trajectory = cfg.rules.wait_for_trajectory
        self.last_retime = ''              # what re-timing the last trajectory changed
        self._pool: ThreadPoolExecutor | None = None    # real time: the re-timing thread
        # (future, origin, source) ready to adopt
        self._retimed: list[tuple[Future[tuple[Trajectory, str]], int, str]] = []
        self._announce = False             # tracker/trajectory due at the next step
        self.pub_followed = self.create_publisher(MultiDOFJointTrajectory,
                                                  topics.FOLLOWED_TRAJECTORY, LATCHED_QOS)
        # lockstep needs no clock: a command answers an odom stamp, and the time law of an
        # untimed Path starts at the latest odom stamp (no /clock subscription per step)
        self.commands = 0
        self.saturated = self.stale_stops = self.deadline_misses = 0
        self._rejected_reported = 0
        self._odom_intervals, self._odom_interval_sum = 0, 0.0
        self._dt_disagreement = False      # a dt override disagreeing with the odometry (said)
        self._last_odom_rx = self._last_ref_rx = 0
        self.base_frame = cfg.base_frame
        if cfg.stamped_cmd_vel:
            self._cmd_msg = TwistStamped()
            self._cmd_msg.header.frame_id = self.base_frame
            self._cmd = self._cmd_msg.twist
        else:
            self._cmd = self._cmd_msg = Twist()
        self.pub_cmd = self.create_publisher(type(self._cmd_msg), cfg.cmd_vel_topic, DATA_QOS)
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
        self._outputs_made = [self.pub_followed, self.pub_cmd, self.pub_error, self.pub_path,
                              self.pub_marker, self.pub_diag]
        self._monitor_start()
        if self.monitor is not None:
            self._outputs_made.append(self.pub_cert)
        self._configured = True

    def _subscribe(self) -> None:
        """Activate's work: the inputs' subscriptions and the real-time timers."""
        cfg = self.config
        guarded = self._guarded
        add = self._entities.append
        add(self.create_subscription(Odometry, cfg.odom_topic, guarded(self._on_odom),
                                     DATA_QOS))
        if not self.wait_for_trajectory:     # only then are the per-step samples read
            add(self.create_subscription(PoseStamped, topics.REF_POSE,
                                         guarded(self._on_ref_pose), DATA_QOS))
            add(self.create_subscription(TwistStamped, topics.REF_TWIST,
                                         guarded(self._on_ref_twist), DATA_QOS))
            add(self.create_subscription(AccelStamped, topics.REF_ACCEL,
                                         guarded(self._on_ref_accel), DATA_QOS))
        add(self.create_subscription(PathMsg, topics.TRAJECTORY, guarded(self._on_path),
                                     LATCHED_QOS))
        # raw: the CDR bytes, read with numpy (multidof_from_cdr) - rclpy's deserialization
        # of an hour's 48,000 knots is one C call of about 2 s in which no signal is acted on
        add(self.create_subscription(MultiDOFJointTrajectory, topics.TRAJECTORY_MULTIDOF,
                                     guarded(self._on_multidof), LATCHED_QOS, raw=True))
        if self.mode == 'realtime':
            self._last_odom_wall: int | None = None     # wall ns of the last input
            self._last_ref_wall: int | None = None
            add(self.create_timer(cfg.diagnostics_period, guarded(self._diagnostics)))
            add(self.create_timer(0.05, guarded(self._watchdog)))
        self._active = True

    def _unsubscribe(self) -> None:
        """Deactivate's work: a zero command, the subscriptions and timers destroyed."""
        was_active, self._active = self._active, False
        if was_active:
            self._publish(0.0, 0.0)
        for entity in self._entities:
            if isinstance(entity, Subscription):
                self.destroy_subscription(entity)
            else:
                self.destroy_timer(entity)
        self._entities.clear()
        self._retimed.clear()
        if self._configured:
            self.inputs.release()          # the next activation starts a new run

    def _release(self) -> None:
        """Cleanup's work: the workers stopped, the publishers destroyed (unconfigured)."""
        self._unsubscribe()
        if not self._configured:
            return
        self._stop_workers()
        for pub in self._outputs_made:
            self.destroy_publisher(pub)
        self._outputs_made = []
        self._configured = False

    def _finalize(self) -> None:
        """Shutdown's and error processing's work: everything released, whatever the state."""
        self._release()

    def _guarded(self, callback: Any) -> Any:
        """``callback``, an unexpected error in it going to ErrorProcessing (``_fail``)."""
        def run(*args: Any) -> None:
            if not self._active:
                return                     # a message taken before the deactivation
            try:
                callback(*args)
            except Exception as exc:  # noqa: BLE001 - zero, then ErrorProcessing
                if self.stopping:
                    raise                  # the shutdown race (guard_shutdown_race)
                self._fail(exc)
        return run

    def _fail(self, exc: BaseException) -> None:
        """An error while active: zero now, then deactivate -> ErrorProcessing -> unconfigured.

        The transition runs from a one-shot timer, outside the callback that failed (whose
        subscription it destroys).
        """
        if self._error is not None:
            return
        self._error = f'{type(exc).__name__}: {exc}'
        self.log('error', f'error while active: {self._error} ({_where(exc)}); commanding '
                          'zero, going to ErrorProcessing')
        self._publish(0.0, 0.0)
        self._active = False               # nothing more is commanded

        def to_error() -> None:
            if self._error_timer is not None:
                self._error_timer.cancel()
            if self._state_machine.current_state[1] != 'active':
                self._error = None         # a manager took it down meanwhile: done
                return
            self._active = True            # the deactivation's zero and clean-up run
            self.trigger('deactivate')
        self._error_timer = self.create_timer(0.001, to_error)

    def apply_config(self, old: TrackerSettings, new: TrackerSettings) -> None:
        """An accepted runtime set (post-set callback): the new gains, limits and rules.

        Parameters
        ----------
        old, new : TrackerSettings
            The settings before and after the change.
        """
        law = self._law
        if law is not None:                        # another law keeps its own settings
            c = law.config                         # a tuned prediction stays as tuned
            law.config = new.tracker if self._tuned is None else replace(
                new.tracker, predict_latency=c.predict_latency, predict_lag_v=c.predict_lag_v,
                predict_lag_w=c.predict_lag_w)
        self.inputs.rules = new.rules
        self.max_path_poses = new.max_path_poses
        if self.monitor is not None:
            self.monitor.settings = new.monitor.settings

    @property
    def _tuned(self) -> Tuned | None:
        """The tuning around our law (``monitor_tune``), if any."""
        return self.tracker if isinstance(self.tracker, Tuned) else None

    @property
    def _law(self) -> Tracker | None:
        """Our law (inside the tuning, if any); None for another controller."""
        law = self.tracker.tracker if isinstance(self.tracker, Tuned) else self.tracker
        return law if isinstance(law, Tracker) else None

    @property
    def _predictor(self) -> LatencyPredictor | None:
        """Our law's latency predictor (None without one, or for another controller)."""
        law = self._law
        return None if law is None else law.predictor

    # ------------------------------------------------------------------ certificate monitor
    def _monitor_start(self) -> None:
        """Start the monitor's worker (:class:`control.identification.monitor.MonitorWorker`)."""
        m = self.config.monitor
        self.monitor: MonitorWorker | None = None
        self._monitor_last_level = -1
        if not m.enabled:
            if m.tune:
                self.log('info', 'monitor off: the predictor is not tuned online (monitor_tune '
                                 'needs the monitor\'s estimates)')
            return
        tuned = self.inputs.tracker
        # with monitor_tune the law's own estimator is the monitor: estimates on the stamps,
        # in the odometry callback; the node neither feeds it nor runs a thread for it
        self.monitor = tuned.worker if isinstance(tuned, Tuned) else MonitorWorker(m.settings,
                                                                                 m.period)
        self.pub_cert = self.create_publisher(DiagnosticArray, topics.CERTIFICATE, DATA_QOS)
        if isinstance(tuned, Tuned):
            self._tunings = tuned.changes
            self.pub_tuning = self.create_publisher(Vector3Stamped, topics.TUNING, LATCHED_QOS)
        if m.certificate is None:
            self.log('info', 'certificate monitor: no certified_residual given (the gain '
                             'file records no certificate): latency is estimated and '
                             'reported, the certificate as unknown')
        if m.adapt and self._predictor is None:
            self.log('warn', 'monitor_adapt needs the predictor (predict_latency > 0 or a '
                             'predict_* parameter): not adapting')
        if not isinstance(tuned, Tuned):
            self.monitor.start()

    def _publish_tuning(self) -> None:
        """Publish a retune of the step just taken (``monitor_tune``) on tracker/tuning."""
        tuned = self._tuned
        if tuned is None or tuned.changes == self._tunings or tuned.last_change is None:
            return
        self._tunings = tuned.changes
        stamp, latency, lag_v, lag_w = tuned.last_change
        msg = Vector3Stamped()
        ns_to_stamp(stamp, msg.header.stamp)       # (no frame: times, not a spatial vector)
        msg.vector.x, msg.vector.y, msg.vector.z = latency, lag_v, lag_w
        self.pub_tuning.publish(msg)
        self.log('info', f'predictor tuned: latency {latency:.4f} s, lags {lag_v:.4f} / '
                         f'{lag_w:.4f} s (from the odometry stamped {stamp * 1e-9:.6f} s)')

    def _monitor_command(self, stamp: int | None, v: float, w: float) -> None:
        """Record a command sent: at the tracker's *now* (lockstep) or the clock (real time)."""
        if self.monitor is None or isinstance(self.inputs.tracker, Tuned):
            return
        if stamp is None or self.mode == 'realtime':
            t = self.get_clock().now().nanoseconds * 1e-9
        else:
            t = stamp * 1e-9 + self.config.tracker.predict_odom_latency
        self.monitor.window.add_command(t, v, w)

    def _monitor_odom(self, stamp: int, msg: Odometry) -> None:
        """Record the odometry twist measured at ``stamp`` (ns)."""
        if self.monitor is None or isinstance(self.inputs.tracker, Tuned):
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
        pred = self._predictor
        adapting = m.adapt and pred is not None
        P = pred.cmd_latency if pred is not None else 0.0
        est = mon.latest
        if adapting and pred is not None and est is not None and m.certificate is not None:
            new_p = adapted_prediction(est, m.certificate, P, m.settings)
            if new_p != P:
                self.log('info', f'certificate monitor: predict_latency {P:.4f} -> {new_p:.4f} s '
                                 f'(latency estimate {est.latency:.4f} s)')
                pred.cmd_latency = P = new_p
        if self.inputs.stopped:
            est = LatencyEstimate(False, 'inputs stale: the tracker has stopped the robot')
        f = self.inputs.follower
        if f is not None and (f.finished or f.refused or not f.started):
            # data without excitation says nothing about the latency: STALE, never WARN
            est = LatencyEstimate(False, 'at rest (' + ('trajectory finished' if f.finished
                                  else 'waiting for the trajectory\'s start' if not f.refused
                                  else 'trajectory refused') + '): no excitation')
        cert = m.certificate
        hold = self.config.tracker.dt or (self.tracker.timing.period or 0.0)
        if cert is not None and not self.config.tracker.dt and hold:
            cert = replace(cert, hold=hold)     # the measured command period
        verdict = evaluate(est, cert, P, m.settings, adapting=adapting)
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
        self._stop_workers()
        super().close()

    def _stop_workers(self) -> None:
        """The monitor's and the re-timing's threads stopped (idempotent)."""
        mon = getattr(self, 'monitor', None)
        if mon is not None:
            # not waited for long: the node ends within a second of a stop signal (an
            # estimate importing scipy.signal took seconds under load); the thread only
            # computes, and the process ends without waiting for daemon threads
            mon.stop(timeout=0.1)
        pool = getattr(self, '_pool', None)
        if pool is not None:
            pool.shutdown(wait=False, cancel_futures=True)
            self._pool = None
        self.monitor = None

    # ------------------------------------------------------------------ inputs
    def _on_reject(self, r: Rejection) -> None:
        """Say that the rules refused an input (messages: the first 10, then every 1000th)."""
        if r.kind == 'trajectory':
            keep = 'the previous trajectory' if self.inputs.follower else 'the reference topics'
            self.log('error', f'refused trajectory: {r.reason}; keeping {keep}')
        elif r.kind == 'start':
            self.log('error', f'refused trajectory: {r.reason}; waiting at rest for a new '
                              'trajectory')
            self._diagnostics()
        elif self.inputs.rejected <= 10 or self.inputs.rejected % 1000 == 0:
            self.log('warn', f'ignored {r} (rejected so far: {self.inputs.rejected})')

    def _on_splice(self, near: Nearest, speed: float) -> None:
        """Say that a plan was spliced onto the motion (the first 3, then every 100th)."""
        n = self.inputs.splices
        if n <= 3 or n % 100 == 0:
            self.log('info', f'plan {n} spliced onto the motion at {near.s:.3f} m along it '
                             f'({near.distance * 1e3:.1f} mm from the reference), from '
                             f'{speed:.3f} m/s: no new run')

    def _on_override(self, event: str, commanded: float, measured: float) -> None:
        """Say that the commands are overridden downstream, or no longer."""
        if event == 'held':
            self.log('warn', f'commands overridden downstream (a collision monitor?): '
                             f'{measured:.3f} m/s measured for {commanded:.3f} m/s commanded '
                             f'for {self.inputs.rules.override_time:g} s; holding the reference '
                             'at the robot, the compensator at its speed')
        elif event == 'released':
            self.log('info', f'commands no longer overridden ({measured:.3f} m/s measured): '
                             'resuming from where the robot is')

    def _on_jump(self, gap: float) -> None:
        self.log('warn', f'odom stamp jumped {gap:.3f} s ahead: re-initialising the '
                         'compensator from odom')

    def _new_trajectory(self, msg: Any, kind: str, topic: str) -> None:
        """A trajectory message: built, re-timed (real time: in a worker thread), adopted."""
        source = f'topic {self.resolve_topic_name(topic)}'
        inputs = self.inputs
        try:
            if self.mode == 'lockstep':
                # a long trajectory is built and re-timed in the worker thread, waited for
                # here: a stop signal ends the wait at once (an hour's trajectory takes
                # about a second to check and re-time, several under load, and a callback
                # is never interrupted); the result is the same as built here.  A short
                # one (milliseconds) is built right here: with a worker thread busy during
                # a callback, rclpy 7.1.6's EventsExecutor lost every other message in a
                # test that makes a new executor per spin (test_trajectory_nodes)
                long = _points(msg) > SYNC_POINTS
                got = self._stoppable(self._build_and_retime, msg, kind, source) if long \
                    else self._build_and_retime(msg, kind, source)
                if got is None:
                    return                      # stopping: the spin ends next
                traj, origin, note = got
            else:
                traj, origin = inputs.build(msg, kind, source, now_ns=self._now_ns())
                if inputs.rules.retime and not traj.is_analytic:
                    # real time: check and re-time in a worker thread (a second or two for
                    # a lap); odometry keeps being answered meanwhile, and the new
                    # trajectory starts at the first odometry after it is ready (re-based
                    # if late)
                    if self._pool is None:
                        self._pool = ThreadPoolExecutor(1, thread_name_prefix='retime')
                    fut = self._pool.submit(inputs.retime, traj)
                    fut.add_done_callback(
                        lambda f: self._retimed.append((f, origin, source)))
                    return
                traj, note = inputs.retime(traj)
            self._note_retime(note, source)
        except TrajectoryError as exc:
            return inputs.refuse(str(exc))
        self._adopt(traj, origin, source)
        self._answer(inputs.compute())     # a pose not yet answered gets its command now

    def _build_and_retime(self, msg: Any, kind: str, source: str
                          ) -> tuple[Trajectory, int, str]:
        """Lockstep: the trajectory of a message, re-timed, its origin and the note."""
        traj, origin = self.inputs.build(msg, kind, source, now_ns=self._now_ns())
        traj, note = self.inputs.retime(traj)
        return traj, origin, note

    def _stoppable(self, work: Any, *args: Any) -> Any:
        """``work(*args)`` in the worker thread; None if a stop signal comes first.

        Waited for in slices of 50 ms, each followed by a look at :attr:`stopping`; an
        exception of ``work`` is raised here.  An abandoned ``work`` finishes on its own
        (it only computes) and its result is dropped.
        """
        if self._pool is None:
            self._pool = ThreadPoolExecutor(1, thread_name_prefix='retime')
        fut = self._pool.submit(work, *args)
        while True:
            try:
                return fut.result(timeout=0.05)
            except TimeoutError:
                if self.stopping:
                    return None

    def _note_retime(self, note: str, source: str) -> None:
        if note:
            self.last_retime = note
            self.log('warn', f'trajectory from {source}: {note}')

    def _take_retimed(self) -> None:
        """Adopt a trajectory re-timed in the background (real time), or refuse it."""
        while self._retimed:
            fut, origin, source = self._retimed.pop(0)
            try:
                traj, note = fut.result()
            except TrajectoryError as exc:
                self.inputs.refuse(str(exc))
                continue
            self._note_retime(note, source)
            self._adopt(traj, origin, source)

    def _adopt(self, traj: Trajectory, origin: int, source: str) -> None:
        self.inputs.adopt(traj, origin)
        self._announce = True                 # at the step that first follows it
        if traj.spliced:
            return                            # said by _on_splice (the first ones)
        self.log('info', f'new trajectory from {source}: {len(traj.knots)} points '
                         f'({traj.kind}), {traj.duration:.3f} s from stamp '
                         f'{origin * 1e-9:.3f} s: starting a new run')

    def _on_path(self, msg: PathMsg) -> None:
        self._new_trajectory(msg, 'path', topics.TRAJECTORY)

    def _now_ns(self) -> int | None:
        """Now (ns) for an untimed Path: the clock in real time, None in lockstep.

        None: the rules' default, the latest odom stamp (lockstep needs no clock).
        """
        if self.mode == 'lockstep':
            return None
        return int(self.get_clock().now().nanoseconds)

    def _on_multidof(self, raw: bytes) -> None:
        # the compact form (one transform, velocity, acceleration per point: the
        # reference's, a planner's of one base) as arrays; any other layout deserialized
        msg = multidof_from_cdr(raw)
        self._new_trajectory(msg if msg is not None else
                             deserialize_message(raw, MultiDOFJointTrajectory),
                             'multidof', topics.TRAJECTORY_MULTIDOF)

    def _on_odom(self, msg: Odometry) -> None:
        if self.mode == 'lockstep' and \
                self.pub_cmd.get_subscription_count() < self.config.lockstep_subscribers:
            return                         # not every cmd_vel subscriber matched: the plant
                                           # republishes the step (its lockstep_retry)
        inputs = self.inputs
        last = inputs.last_odom_stamp
        s = inputs.accept_odom(msg)
        if s is None:
            return                         # refused (said), or a repeat of the current step
        if last >= 0:
            gap = (s - last) * 1e-9
            self._odom_intervals += 1
            self._odom_interval_sum += gap
            period = self.tracker.timing.period       # measured, whatever dt says
            if period and gap > 1.5 * period:
                self.deadline_misses += 1
        if self._retimed and self.pub_cmd.get_subscription_count() >= \
                self.config.lockstep_subscribers:
            self._take_retimed()           # real time: a trajectory re-timed meanwhile
        self._answer(inputs.compute())     # cmd_vel first: the clock read is bookkeeping
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

    def _on_ref(self, i: int, msg: Any) -> None:
        if not self.inputs.accept_reference(i, msg):
            return
        self._last_ref_rx = now = self.get_clock().now().nanoseconds
        if self.mode == 'realtime':
            self._last_ref_wall = now       # one clock read: it delays an odom arriving now
        elif self.inputs.samples_stepped:
            self._answer(self.inputs.compute())

    def _on_ref_pose(self, msg: PoseStamped) -> None:
        self._on_ref(0, msg)

    def _on_ref_twist(self, msg: TwistStamped) -> None:
        self._on_ref(1, msg)

    def _on_ref_accel(self, msg: AccelStamped) -> None:
        self._on_ref(2, msg)

    # ------------------------------------------------------------------ the law's answers
    def _answer(self, step: Step | None) -> None:
        """Publish the command of a step the rules made due, and what goes with it."""
        if step is None:
            return
        f = self.inputs.follower
        if f is not None:                  # a step on the own trajectory
            announce, self._announce = self._announce, False
            if step.started:
                self._started(f, step.stamp, announce)
            elif announce:
                self._announce_followed(f, step.stamp)
            if step.finished:
                e = math.hypot(step.command.error[0], step.command.error[2])
                self.log('info',
                    f'trajectory finished: at rest at t = {f.finished_at:.3f} s (trajectory '
                    f'end {f.trajectory.t_end:.3f} s), position error {e:.4f} m; waiting for '
                    'a new trajectory')
                self._diagnostics()
        self._publish(step.command.v, step.command.w, step.stamp)
        self._publish_tuning()
        self._outputs(step.stamp, step.pose, step.ref, step.command)

    def _started(self, f: Follower, stamp: int, announce: bool) -> None:
        """Say how the trajectory started: re-based or on its stamps.

        A refusal at its start is said by :meth:`_on_reject`.  ``stamp`` is the odometry
        stamp of this step; ``announce``: the trajectory was adopted at it
        (:meth:`_announce_followed`).
        """
        if f.refused:
            return
        if f.offset:
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
                f.trajectory, self.inputs.origin_ns + int(round(f.offset * 1e9)), self.frame,
                header_ns=stamp))

    def _publish(self, v: float, w: float, stamp: int | None = None) -> None:
        """cmd_vel as Twist or, with enable_stamped_cmd_vel, TwistStamped.

        The stamped header carries the command time - the odometry stamp it answers in
        lockstep, the node clock's now in real time (what diff_drive_controller checks
        against its cmd_vel_timeout) - and the body frame.
        """
        c = self.config.tracker          # the input rules' law is within them already
        self._cmd.linear.x, self._cmd.angular.z, _ = clamp_command(
            v, w, c.max_linear_speed, c.max_angular_speed)
        if self._cmd_msg is not self._cmd:
            if stamp is None or self.mode == 'realtime':
                stamp = self.get_clock().now().nanoseconds
            ns_to_stamp(stamp, self._cmd_msg.header.stamp)
        self.pub_cmd.publish(self._cmd_msg)
        self.commands += 1
        self._monitor_command(stamp, self._cmd.linear.x, self._cmd.angular.z)

    # ------------------------------------------------------------------ outputs
    def _outputs(self, stamp: int, pose: tuple[float, float, float], ref: RefSample | None,
                 cmd: Command) -> None:
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
        f = self.inputs.follower
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
        if self.inputs.stopped:
            level = DiagnosticStatus.WARN
            msgs.append('inputs stale: stopped')
        if self.inputs.override.overridden:
            level = DiagnosticStatus.WARN
            msgs.append('commands overridden downstream: holding the reference at the robot')
        if self.inputs.rejected > self._rejected_reported:
            level = max(level, DiagnosticStatus.WARN)
            msgs.append(f'{self.inputs.rejected - self._rejected_reported} input(s) rejected')
        self._rejected_reported = self.inputs.rejected
        timing = self._timing_report()
        if timing:
            level = max(level, DiagnosticStatus.WARN)
            msgs.extend(timing)
        st = DiagnosticStatus(level=level, name=f'{self.get_name()}: tracking',
                              message='; '.join(msgs),
                              hardware_id=self.get_fully_qualified_name())
        measured = self.tracker.timing.period
        dt = self.config.tracker.dt
        vals = {'loop period (s)': f'{period:.6f}',
                'odometry period (s)': f'{measured:.6f}' if measured else 'unknown',
                'tracker step (s)': f'{dt:g} (dt override)' if dt else
                'from the odometry stamps (dt 0)',
                'deadline misses': self.deadline_misses,
                'odom age (s)': f'{odom_age:.3f}',
                'reference age (s)': 'not used (own trajectory)' if f else f'{ref_age:.3f}',
                'commands': self.commands,
                'rejected inputs': self.inputs.rejected, 'stale stops': self.stale_stops,
                'saturated commands': self.saturated, 'stamp jumps': self.inputs.jumps,
                'trajectory': state,
                'trajectory end (s)': f'{f.trajectory.t_end:.3f}' if f else 'none',
                'trajectory re-based by (s)': f'{f.offset:.6f}' if f else 'none',
                'last refused trajectory': self.inputs.last_refusal or 'none',
                'last re-timed trajectory': self.last_retime or 'none',
                'plans spliced': self.inputs.splices,
                'overridden downstream': self.inputs.override.count}
        st.values = [KeyValue(key=k, value=str(v)) for k, v in vals.items()]
        arr = DiagnosticArray()
        arr.header.stamp = self.get_clock().now().to_msg()
        arr.status = [st, *self._monitor_diagnostics()]
        self.pub_diag.publish(arr)

    def _timing_report(self) -> list[str]:
        """What is wrong with the timing: a changed odometry rate, a disagreeing dt override.

        Each is logged once when it starts (:mod:`control.simulation.timing`); a changed rate
        is reported in the diagnostics that follow it, a disagreement while it lasts.
        """
        timing, notes = self.tracker.timing, []
        change = timing.rate_change()
        if change is not None:
            before, now = change
            msg = (f'odometry period changed from {before:.4f} s ({1 / before:.1f} Hz) to '
                   f'{now:.4f} s ({1 / now:.1f} Hz)')
            self.log('warn', msg)
            notes.append(msg)
        wrong = period_disagreement(self.config.tracker.dt, timing.period)
        if wrong is not None:
            if not self._dt_disagreement:
                self.log('warn', wrong)
            notes.append(wrong)
        self._dt_disagreement = wrong is not None
        return notes

    def _watchdog(self) -> None:
        """Real time: stop while an input is stale (:func:`tracker_inputs.stale_inputs`)."""
        inputs = self.inputs
        stale = stale_inputs(int(self.get_clock().now().nanoseconds), self._last_odom_wall,
                             self._last_ref_wall, self.config.input_timeout,
                             own_trajectory=inputs.follower is not None)
        if stale is None:
            return                          # not started yet: nothing has been commanded
        if stale:
            if not inputs.stopped:
                self.log('warn', f'no {" or ".join(stale)} for more than '
                                 f'{self.config.input_timeout} s: publishing stop')
                inputs.stopped = True
                self.stale_stops += 1
                self.tracker.reset()
            self._publish(0.0, 0.0)
        elif inputs.stopped:
            self.log('info', 'inputs fresh again: resuming')
            inputs.stopped = False


#: Console entry point of the tracker node: ``main(args)`` is ``run(TrackerNode, args)``
#: (:func:`~nonfragile_tracker.nodes.common.run`: the exit code).
main = partial(run, TrackerNode)


if __name__ == '__main__':
    # `python -m nonfragile_tracker.nodes.tracker` is the console script's process: the
    # entry's signal handling, stack dumps on SIGUSR1 and tear-down deadline
    import sys

    from nonfragile_tracker.nodes.entry import main as node_main
    sys.exit(node_main('tracker', sys.argv))
