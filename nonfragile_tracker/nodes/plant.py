"""``plant``: kinematic unicycle with the paper's delayed-state term; the run's clock.

Subscribes ``cmd_vel`` (Twist or TwistStamped), publishes ``odom``, ``pose`` and, in
lockstep, ``/clock`` and ``run_done``.  Lockstep (default): each step publishes the clock
and the odometry due, then waits for the tracker's command (with retries, a timeout, and a
recorder's start gate and back-pressure); real time: a wall timer steps with the latest
command.  The physics (latency, lag, limits, odometry latency, rate and noise) is the
in-process model, :class:`~nonfragile_tracker.control.simulation.plant.UnicyclePlant`.

See doc/ros-interface.md, sections "plant" (parameters, what it does) and "Time and
lockstep".
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from functools import partial
from typing import Any

from geometry_msgs.msg import PoseStamped, Twist, TwistStamped
from nav_msgs.msg import Odometry
from rcl_interfaces.msg import ParameterType
from rclpy.duration import Duration
from rclpy.parameter import Parameter
from rosgraph_msgs.msg import Clock
from std_msgs.msg import UInt64

from ..interface import topics
from ..errors import EXIT_RUN
from ..control.simulation.interfaces import DEFAULT_PLANT, Plant, load_factory, make_plant
from ..control.simulation.plant import PlantConfig, delay_steps, odometry_period_steps
from ..control.simulation.timing import step_time_ns
from ..interface.scenario import plant_config
from .common import (DATA_QOS, LATCHED_QOS, AdapterNode, Param, StartupError, check_mode,
                     fill_pose, ns_to_stamp, require_at_least, run, settings_from)

PARAMS = [
    Param('mode', 'lockstep', 'lockstep (deterministic, sim time) or realtime (wall timer)',
          read_only=True),
    Param('model', DEFAULT_PLANT, 'the simulated base, "package.module:factory" (a factory of '
          'the plant settings making a Plant); default the kinematic unicycle with the latency, '
          'lag and odometry models below', read_only=True),
    Param('dt', 0.01, 'integration step (s)', low=1e-6, high=10.0, read_only=True),
    Param('tau', 0.0, 'state delay (s); rounded to a whole number of steps', low=0.0,
          high=1e3, read_only=True),
    Param('A_tau', [0.0] * 16, 'delay matrix A_tau acting on xi = [x, vx, y, vy], 16 doubles '
          'row-major', read_only=True),
    Param('initial_pose', [0.0, 0.0, 0.0], 'initial [x (m), y (m), yaw (rad)] in odom',
          read_only=True),
    Param('initial_speed', 0.0, 'speed in force before the first command (m/s)',
          read_only=True),
    Param('duration', 60.0, 'run length (s); lockstep stops after it, realtime: 0 = forever',
          low=0.0, high=1e9, read_only=True),
    Param('lockstep_timeout', 10.0, 'lockstep: abort if no command arrives for this long (s, wall)',
          low=0.01, high=1e6),
    Param('startup_timeout', 60.0, 'lockstep: abort if the peers are not discovered within this '
          'long (s, wall)', low=0.01, high=1e6),
    Param('lockstep_retry', 0.25, 'lockstep: republish the current step after this long (s, wall)',
          low=0.001, high=1e6),
    Param('lockstep_subscribers', 1, 'lockstep: wait until odom has this many subscribers'),
    Param('lockstep_recorder', False, 'lockstep: also wait until a recorder (lockstep_gate) '
          'has announced on recorder/ready that its subscriptions are matched (and pose has a '
          'matched subscriber if the graph shows one)', read_only=True),
    Param('realtime_recorder', False, 'real time: start stepping (the run\'s clock) only once '
          'a recorder (lockstep_gate) has announced on recorder/ready that its odom and '
          'cmd_vel subscriptions are matched and odom has lockstep_subscribers matched '
          'subscribers, so the bag has every odometry message', read_only=True),
    Param('lockstep_lead', 30, 'lockstep with lockstep_recorder: run at most this many steps '
          '(plus the odometry latency and period) ahead of the recorder\'s progress, so its '
          'queues (depth 100) never overflow under load; 0 = do not wait for the recorder',
          read_only=True),
    Param('enable_stamped_cmd_vel', False, 'subscribe cmd_vel as geometry_msgs/TwistStamped '
          '(Nav2 name) instead of Twist', read_only=True),
    Param('odom_frame', topics.ODOM_FRAME, 'frame of odom and pose (REP-105)', read_only=True),
    Param('base_frame', topics.BASE_FRAME, 'robot body frame (odom child_frame_id)',
          read_only=True),
    Param('cmd_timeout', 0.5, 'realtime: command older than this (s) is replaced by a stop',
          low=0.0, high=1e6),
    Param('cmd_latency', 0.0, 'command-to-motion latency (s): a command received at step k '
          'acts from step k + round(cmd_latency/dt); 0 = none', low=0.0, high=1e3,
          read_only=True),
    Param('lag_v', 0.0, 'first-order time constant of the linear speed (s); 0 = none',
          low=0.0, high=1e3, read_only=True),
    Param('lag_w', 0.0, 'first-order time constant of the angular speed (s); 0 = none',
          low=0.0, high=1e3, read_only=True),
    Param('max_linear_accel', 0.0, 'limit on |dv/dt| of the base (m/s^2); 0 = unlimited',
          low=0.0, high=1e6, read_only=True),
    Param('max_angular_accel', 0.0, 'limit on |dw/dt| of the base (rad/s^2); 0 = unlimited',
          low=0.0, high=1e6, read_only=True),
    Param('odom_latency', 0.0, 'odometry latency (s): the measurement of step k is published '
          'at step k + round(odom_latency/dt) with the stamp of step k; 0 = none', low=0.0,
          high=1e3, read_only=True),
    Param('odom_rate', 0.0, 'odometry rate (Hz), at most 1/dt: published every '
          'round(1/(odom_rate dt)) steps; 0 = every step', low=0.0, high=1e9, read_only=True),
    Param('odom_noise', [0.0, 0.0, 0.0], 'standard deviation of the odometry noise '
          '[x (m), y (m), yaw (rad)], Gaussian; 0 = exact', read_only=True),
    Param('odom_jitter', 0.0, 'odometry jitter (s): each measurement is taken up to this '
          'early or late (uniform over whole steps) and stamped with its true time; below '
          'half the odometry period; 0 = none', low=0.0, high=1e3, read_only=True),
    Param('noise_seed', 0, 'seed of the odometry noise (numpy Generator); same seed, same '
          'noise', read_only=True),
    Param('cmd_latency_schedule', None, 'command latency that changes during the run: flat '
          '[t_1, L_1, t_2, L_2, ...] (s, times increasing, multiples of dt): from t_1 on a '
          'command acts L_1 after it is received, ...; cmd_latency before t_1; unset = '
          'cmd_latency throughout', type=ParameterType.PARAMETER_DOUBLE_ARRAY, read_only=True),
]
#: Lockstep: at most this many steps without waiting (QoS keep-last depth headroom).
MAX_FREE_STEPS = 50
#: Real time: a tick that comes later than this many steps (the machine stalled) integrates
#: every missed step but publishes the odometry of the last ones only: a driver reports
#: where the robot is, not seconds of history at once into a subscriber's keep-last queue.
MAX_BURST = 10


@dataclass(frozen=True)
class PlantSettings:
    """The plant node's validated parameters (see ``PARAMS``)."""

    mode: str
    plant: PlantConfig
    model: str                   #: the plant's factory, ``module:name``
    final_step: int
    lockstep_timeout: float
    startup_timeout: float
    lockstep_retry: float
    lockstep_subscribers: int
    lockstep_recorder: bool
    lockstep_lead: int
    cmd_timeout: float
    stamped: bool
    odom_frame: str
    base_frame: str
    realtime_recorder: bool = False


def plant_settings(values: dict[str, Any]) -> PlantSettings:
    """Validate the plant's parameter values (start-up and runtime sets); InputError if bad.

    Parameters
    ----------
    values : dict
        ``PARAMS`` by name (at start-up, or with a runtime set's proposed values).

    Returns
    -------
    PlantSettings

    Raises
    ------
    StartupError
        An ``initial_pose`` that is not [x, y, yaw], a ``lockstep_lead`` beyond half the
        topics' depth, ``lockstep_subscribers`` below 1, or an odometry latency or period
        the lockstep handshake cannot wait for.
    LoopConfigError
        A bad plant model (``A_tau``, latencies, lags).
    """
    mode = check_mode(values['mode'])
    pose0 = list(values['initial_pose'])
    if len(pose0) != 3:
        raise StartupError(f'initial_pose needs [x, y, yaw], got {pose0}')
    if not 0 <= values['lockstep_lead'] <= topics.DEPTH // 2:
        raise StartupError(f'lockstep_lead must be 0 .. {topics.DEPTH // 2} steps (the topics '
                           f'keep the last {topics.DEPTH} messages), got '
                           f'{values["lockstep_lead"]}')
    require_at_least(values, 'lockstep_subscribers', 1)
    cfg = plant_config(values)
    load_factory(values['model'], 'plant')     # a name that cannot be loaded: refused here
    odo = cfg.odometry
    if mode == 'lockstep' and max(odo.latency_steps, odo.period_steps) > MAX_FREE_STEPS:
        raise StartupError(
            f'odom_latency ({odo.latency_steps} steps) and the odometry period '
            f'({odo.period_steps} steps) must each be at most {MAX_FREE_STEPS} plant steps '
            'in lockstep (the plant steps on without waiting in between and the topics '
            'keep the last 100 messages); use a larger dt, a smaller odom_latency or a higher '
            'odom_rate')
    return settings_from(PlantSettings, values, mode=mode, plant=cfg,
                         final_step=int(round(values['duration'] / cfg.dt)),
                         stamped=values['enable_stamped_cmd_vel'])


class PlantNode(AdapterNode[PlantSettings]):
    """ROS adapter around a :class:`~nonfragile_tracker.control.simulation.interfaces.Plant`.

    Parameters
    ----------
    node_name : str, optional
        ``plant``; two plants in one graph need their own namespaces.
    **node_kwargs
        rclpy ``Node`` keyword arguments (:class:`~nonfragile_tracker.nodes.common.AdapterNode`).
    """

    def __init__(self, node_name: str = 'plant', **node_kwargs: Any):
        super().__init__(node_name, **node_kwargs)
        self.config = self.bind_parameters(PARAMS, plant_settings)
        self.mode = self.config.mode
        cfg = self.config.plant
        for name in ('tau', 'cmd_latency', 'odom_latency'):
            value = getattr(cfg, name)
            n = delay_steps(value, cfg.dt)[0]
            if abs(n * cfg.dt - value) > 1e-9:
                self.log('warn',
                    f'{name} = {value} s is not a multiple of dt = {cfg.dt} s: using '
                    f'{n} steps = {n * cfg.dt:.6g} s')
        period, rate = odometry_period_steps(cfg.odom_rate, cfg.dt)
        if cfg.odom_rate and abs(rate - cfg.odom_rate) > 1e-9 * rate:
            self.log('warn', f'odom_rate = {cfg.odom_rate} Hz does not divide the plant '
                             f'rate {1 / cfg.dt:g} Hz: odometry every {period} steps '
                             f'= {rate:.6g} Hz')
        self.plant: Plant = make_plant(cfg, self.config.model)
        self.dt = cfg.dt
        self.dt_ns = step_time_ns(1, cfg.dt)
        self.final_step = self.config.final_step
        self.progress_every = max(1, self.final_step // 10)

        self.pub_odom = self.create_publisher(Odometry, topics.ODOM, DATA_QOS)
        self.pub_pose = self.create_publisher(PoseStamped, topics.POSE, DATA_QOS)
        self.stamped = self.config.stamped
        self.last_cmd_header = None
        self.sub_cmd = self.create_subscription(
            TwistStamped if self.stamped else Twist, topics.CMD_VEL,
            self._on_stamped_cmd if self.stamped else self._on_cmd, DATA_QOS)
        self._odom, self._pose = Odometry(), PoseStamped()
        self._odom.header.frame_id = self._pose.header.frame_id = self.config.odom_frame
        self._odom.child_frame_id = self.config.base_frame
        self.cmd = (cfg.v0, 0.0)
        self.commands = 0
        if self.mode == 'lockstep':
            self.set_parameters([Parameter('use_sim_time', value=False)])
            self.pub_clock = self.create_publisher(Clock, topics.CLOCK, DATA_QOS)
            self.pub_done = self.create_publisher(UInt64, topics.RUN_DONE, LATCHED_QOS)
            self._clock_msg = Clock()
            self.pub_odom_count = self.create_publisher(UInt64, topics.ODOM_COUNT, LATCHED_QOS)
            self.odom_sent = 0                   # odometry messages (distinct stamps) so far
            self._last_odom_ns = -1
            self.recorder_ready = not self.config.lockstep_recorder
            # back-pressure: the recorder's progress (stamp ns) and how far ahead we may run
            odo = cfg.odometry
            self.lead_ns = ((self.config.lockstep_lead + odo.latency_steps + odo.period_steps)
                            * self.dt_ns)
            self.paced = self.config.lockstep_recorder and self.config.lockstep_lead > 0
            self.recorder_progress = 0
            self.holding = False                 # step published only when the recorder caught up
            self.holds = 0
            if self.config.lockstep_recorder:
                self.create_subscription(UInt64, topics.RECORDER_READY, self._on_recorder_ready,
                                         LATCHED_QOS)
            if self.paced:
                self.create_subscription(UInt64, topics.RECORDER_PROGRESS,
                                         self._on_recorder_progress, DATA_QOS)
            self.started = False
            self.waiting_since = time.monotonic()
            self.last_publish = 0.0
            self.watchdog = self.create_timer(0.02, self._lockstep_watchdog)
        else:
            self.last_cmd_time: float | None = None
            self._rt_origin_ns: int | None = None     # clock at step 0 (_realtime_step)
            self.timer = None
            self.recorder_ready = False
            if self.config.realtime_recorder:      # step once the recorder is subscribed
                self.create_subscription(UInt64, topics.RECORDER_READY, self._on_recorder_ready,
                                         LATCHED_QOS)
                self._gate = self.create_timer(0.02, self._realtime_gate)
            else:
                self.timer = self.create_timer(cfg.dt, self._realtime_step)

    # ------------------------------------------------------------------ publishing
    def _publish_state(self, stamp_ns: int, publish: bool = True) -> bool:
        """Publish the current step (clock, true pose, odometry if due); True if odom went out.

        ``publish`` False takes the odometry measurement (the model's state moves on) but
        publishes nothing (a step skipped after a stall, :data:`MAX_BURST`).
        """
        p = self.plant
        if not publish:
            p.odometry()
            return False
        if self.mode == 'lockstep' and self.pub_clock.get_subscription_count():
            ns_to_stamp(stamp_ns, self._clock_msg.clock)     # nobody on sim time: skip it
            self.pub_clock.publish(self._clock_msg)
        ns_to_stamp(stamp_ns, self._pose.header.stamp)
        fill_pose(self._pose.pose, p.x, p.y, p.th)
        meas = p.odometry()
        if meas is not None:
            odom_ns = stamp_ns - (p.k - meas.step) * self.dt_ns     # measurement time
            ns_to_stamp(odom_ns, self._odom.header.stamp)
            fill_pose(self._odom.pose.pose, meas.x, meas.y, meas.th)
            self._odom.twist.twist.linear.x = meas.v
            self._odom.twist.twist.angular.z = meas.w
            self.pub_odom.publish(self._odom)
            if self.mode == 'lockstep' and odom_ns != self._last_odom_ns:
                self.odom_sent += 1                  # a republished step counts once
                self._last_odom_ns = odom_ns
        if self.pub_pose.get_subscription_count():       # nobody listening: skip it
            self.pub_pose.publish(self._pose)
        self.last_publish = time.monotonic()
        return meas is not None

    # ------------------------------------------------------------------ lockstep
    def _realtime_gate(self) -> None:
        """Real time with ``realtime_recorder``: start stepping once both sides matched.

        The recorder says its side (recorder/ready); odom counts ``lockstep_subscribers``
        matched subscriptions on ours (tracker and recorder).
        """
        if self.timer is None and self.recorder_ready and \
                self.pub_odom.get_subscription_count() >= self.config.lockstep_subscribers:
            self._gate.cancel()
            self.log('info', 'recorder ready and odom matched: stepping')
            self.timer = self.create_timer(self.dt, self._realtime_step)

    def _on_recorder_ready(self, msg: UInt64) -> None:
        if not self.recorder_ready:
            self.log('info', 'recorder ready: its subscriptions are matched')
        self.recorder_ready = True

    def _on_recorder_progress(self, msg: UInt64) -> None:
        self.recorder_progress = max(self.recorder_progress, int(msg.data))
        if self.holding and not self.finished:
            self.waiting_since = time.monotonic()     # the recorder is alive: no abort
            if not self._ahead():
                self.holding = False
                self._publish_step()

    def _ahead(self) -> bool:
        """True if step k is more than the allowed lead past the recorder's progress."""
        return step_time_ns(self.plant.k, self.dt) - self.recorder_progress > self.lead_ns

    def _peers_ready(self) -> bool:
        """Both sides matched: our publishers count their subscribers, the recorder says so.

        A publisher matching a subscription does not mean the subscription has matched the
        publisher (DDS discovery is per side); until it has, samples are dropped there.  The
        tracker and reference recover from that by the republished step; a recorder would
        lose the first steps, so with ``lockstep_recorder`` it has to announce its side.
        """
        if not (self.sub_cmd.get_publisher_count() >= 1
                and self.pub_odom.get_subscription_count() >= self.config.lockstep_subscribers):
            return False
        if not self.config.lockstep_recorder:
            return True
        pose_wanted = min(1, self.count_subscribers(self.pub_pose.topic_name))   # recorded?
        # /clock: every reader in the graph matched (the reference's samples and the
        # recorder's sim time follow it, and nobody republishes a step for them)
        clock_wanted = max(1, self.count_subscribers(self.pub_clock.topic_name))
        return (self.recorder_ready and self.pub_pose.get_subscription_count() >= pose_wanted
                and self.pub_clock.get_subscription_count() >= clock_wanted)

    def _lockstep_watchdog(self) -> None:
        if self.finished:
            return
        now = time.monotonic()
        if not self.started:
            if self._peers_ready():
                self.started = True
                self.log('info', f'peers matched: starting lockstep run of '
                                 f'{self.final_step} steps (dt = {self.dt} s)')
                self.waiting_since = now
                self._publish_step()
            elif now - self.waiting_since > self.config.startup_timeout:
                self._abort('no tracker/reference discovered', 'startup_timeout')
            return
        if now - self.waiting_since > self.config.lockstep_timeout:
            self._abort(f'the recorder made no progress (at stamp {self.recorder_progress} ns)'
                        if self.holding else f'no command for step {self.plant.k}')
        elif self.holding:
            return                                 # step k not published yet: nothing to repeat
        elif now - self.last_publish > self.config.lockstep_retry:
            self._publish_state(step_time_ns(self.plant.k, self.dt))   # same sample again

    def _abort(self, why: str, limit: str = 'lockstep_timeout') -> None:
        self.log('error', f'lockstep run aborted at step {self.plant.k}: {why} within '
                          f'{getattr(self.config, limit)} s ({limit}); is the tracker '
                          'running on the same ROS_DOMAIN_ID and namespace?')
        self.exit_code = EXIT_RUN               # RunError's code
        self._finish()

    def _finish(self) -> None:
        if self.mode == 'lockstep':
            self.pub_odom_count.publish(UInt64(data=self.odom_sent))
            self.pub_done.publish(UInt64(data=self.plant.k))
        self.finished = True          # run() stops spinning, then drain() waits for the acks

    def drain(self) -> None:
        """After the run: give ``run_done`` up to 2 s to reach its subscribers."""
        if self.mode == 'lockstep':
            self.pub_odom_count.wait_for_all_acked(Duration(seconds=2.0))
            self.pub_done.wait_for_all_acked(Duration(seconds=2.0))

    def _on_stamped_cmd(self, msg: TwistStamped) -> None:
        self.last_cmd_header = msg.header
        self._on_cmd(msg.twist)

    def _on_cmd(self, msg: Twist) -> None:
        v, w = msg.linear.x, msg.angular.z
        if not (math.isfinite(v) and math.isfinite(w)):
            self.log('warn', f'ignoring non-finite cmd_vel ({v}, {w})')
            return
        self.commands += 1
        if self.mode != 'lockstep':
            self.cmd = (v, w)
            self.last_cmd_time = time.monotonic()
            return
        if not self.started or self.finished:
            return
        if self.plant.k >= self.final_step:      # command for the last pose: run complete
            self._complete()
            return
        self.plant.command(v, w)
        self._advance()
        self.waiting_since = time.monotonic()
        if self.paced and self._ahead():
            self.holding = True                  # the recorder's progress publishes it
            self.holds += 1
            return
        self._publish_step()

    def _advance(self) -> None:
        self.plant.advance()
        if self.plant.k % self.progress_every == 0:
            t = step_time_ns(self.plant.k, self.dt) * 1e-9
            self.log('info', f'progress: t = {t:.2f} s of '
                             f'{self.final_step * self.dt:.2f} s')

    def _publish_step(self) -> None:
        """Publish step k; where no odometry is due, hold the command and step on."""
        while not self._publish_state(step_time_ns(self.plant.k, self.dt)):
            if self.plant.k >= self.final_step:
                self._complete()
                return
            self._advance()

    def _complete(self) -> None:
        held = f', waited for the recorder {self.holds} times' if self.paced else ''
        self.log('info', f'lockstep run complete: {self.plant.k} steps, '
                         f't = {step_time_ns(self.plant.k, self.dt) * 1e-9:.3f} s{held}')
        self._finish()

    # ------------------------------------------------------------------ real time
    def _realtime_step(self) -> None:
        """A timer tick: the steps whose time has come, each published with its own stamp.

        A robot moves on while its driver is late: when a tick comes late (a loaded
        machine), the steps it missed are taken now with the command in force and their
        odometry published in a burst, stamped with their own times (step k at
        ``origin + k dt``, the origin the smallest ``clock - k dt`` seen: a stamp is never
        ahead of the clock).  The stamps are then the time of the motion they report, as
        a controller that integrates over the time that passed needs them to be.  After a
        stall of more than :data:`MAX_BURST` steps only the last of them are published
        (every one is integrated; logged).
        """
        now = self.get_clock().now().nanoseconds
        grid = now - self.plant.k * self.dt_ns
        if self._rt_origin_ns is None or grid < self._rt_origin_ns:
            self._rt_origin_ns = grid      # the earliest tick on time: no stamp is ahead of now
        due = (now - self._rt_origin_ns) // self.dt_ns
        stale = self.last_cmd_time is None or \
            time.monotonic() - self.last_cmd_time > self.config.cmd_timeout
        v, w = (0.0, 0.0) if stale and self.last_cmd_time is not None else self.cmd
        quiet = due - MAX_BURST          # steps up to this one are integrated, not published
        if quiet >= self.plant.k:
            self.log('warn', f'the timer was {(due - self.plant.k) * self.dt:.3g} s late (a '
                     f'stalled machine): {quiet + 1 - self.plant.k} steps integrated without '
                     f'publishing, the odometry of the last {MAX_BURST} steps published')
        while self.plant.k <= due:
            self._publish_state(self._rt_origin_ns + self.plant.k * self.dt_ns,
                                publish=self.plant.k > quiet)
            self.plant.command(v, w)
            self.plant.advance()
            if self.final_step and self.plant.k >= self.final_step:
                self._finish()
                return


#: Console entry point of the plant node: ``main(args)`` is ``run(PlantNode, args)``
#: (:func:`~nonfragile_tracker.nodes.common.run`: the exit code).
main = partial(run, PlantNode)


if __name__ == '__main__':
    # `python -m nonfragile_tracker.nodes.plant` is the console script's process: the
    # entry's signal handling, stack dumps on SIGUSR1 and tear-down deadline
    import sys

    from nonfragile_tracker.nodes.entry import main as node_main
    sys.exit(node_main('plant', sys.argv))
