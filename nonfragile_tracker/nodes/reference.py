"""``reference``: publishes the desired trajectory, and per-step samples of it.

The trajectory (a built-in analytic path as exact knots, a waypoint file, or a
nav_msgs/Path relayed from a planner) goes to the tracker as one transient-local message,
which the tracker samples itself at each odometry stamp; the node follows the trajectory
rebuilt from the very message it published, shows it on ``reference/path`` and publishes
its samples (``reference/pose|twist|accel``) for the bag and third parties, one per
``/clock`` step in lockstep, at ``publish_rate`` in real time.

See doc/ros-interface.md, section "reference" (its parameters, what it publishes) and
"Time and lockstep".
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import partial
from typing import Any

import numpy as np
from geometry_msgs.msg import AccelStamped, PoseStamped, TwistStamped
from nav_msgs.msg import Path as PathMsg
from rclpy.parameter import Parameter
from rosgraph_msgs.msg import Clock

from ..interface import topics
from ..control.simulation.reference import Path, make_path
from ..control.simulation.trajectory import Trajectory, TrajectoryError, load_waypoints
from .common import (DATA_QOS, LATCHED_QOS, AdapterNode, Param, StartupError, check_mode,
                     fill_reference, ns_to_stamp, require_at_least, run, settings_from,
                     stamp_ns)
from trajectory_msgs.msg import MultiDOFJointTrajectory

from ..control.simulation.trajectory import analytic_knot_times, path_samples
from ..interface.msgconv import multidof_cdr, multidof_from_cdr
from .trajectory_io import multidof_to_trajectory, path_to_trajectory, trajectory_to_path

PARAMS = [
    Param('mode', 'lockstep', 'lockstep (one sample per /clock) or realtime (wall timer)',
          read_only=True),
    Param('path', 'circle', 'path name: circle or figure_eight', read_only=True),
    Param('radius', 0.5, 'path radius / half width (m)', low=1e-9, high=1e6, read_only=True),
    Param('rate', 0.01, 'angular rate of the path parameter (rad/s)', read_only=True),
    Param('center', [0.0, 0.0], 'path centre [x, y] in odom (m)', read_only=True),
    Param('phase', 0.0, 'phase of the path parameter at t = 0 (rad)', read_only=True),
    Param('publish_rate', 100.0, 'realtime: samples per second (Hz)', low=1e-3, high=1e5,
          read_only=True),
    Param('lockstep_subscribers', 0, 'lockstep: publish the samples only once each reference '
          'topic has this many matched subscribers (a recorder: 1); steps seen before are '
          'published then; 0 = publish at once', read_only=True),
    Param('publish_samples', True, 'publish the per-step samples reference/pose|twist|accel '
          '(lockstep: per /clock; real time: at publish_rate); the tracker does not need '
          'them', read_only=True),
    Param('horizon', 3600.0, 'built-in path: the trajectory message covers [0, horizon] s '
          '(after it the tracker brings the robot to rest); `nonfragile_tracker run` makes '
          'it at least the run\'s duration', low=1e-3, high=1e9, read_only=True),
    Param('trajectory_file', '', 'waypoint file (CSV or YAML: t, x, y[, yaw][, speed]) to '
          'follow instead of the built-in path; "" = built-in path', read_only=True),
    Param('trajectory_topic', '', 'relay nav_msgs/Path trajectories from this topic '
          '(reliable, volatile); "" = none', read_only=True),
    Param('smoothing', 0.0, 'waypoint file: 0 interpolates (cubic spline), > 0 smoothing '
          'spline penalty (noisy points)', low=0.0, high=1e12, read_only=True),
    Param('cruise_speed', 0.5, 'time law for a Path with zero stamps: cruise speed (m/s)',
          low=1e-6, high=1e3, read_only=True),
    Param('max_accel', 0.5, 'time law for a Path with zero stamps: acceleration limit '
          '(m/s^2)', low=1e-6, high=1e3, read_only=True),
    Param('odom_frame', topics.ODOM_FRAME, 'frame of the trajectory (the odometry frame)',
          read_only=True),
    Param('start_delay', 1.0, 'real time: a trajectory file starts this long (s) after the '
          'node starts (its Path is stamped node start + start_delay), time for the tracker '
          'to receive it; a tracker that starts following later re-bases it (its '
          'start_tolerance)', low=0.0, high=1e6, read_only=True),
    Param('display_points', 400, 'points of the reference/path shown (at least 2)'),
]


@dataclass(frozen=True)
class ReferenceSettings:
    """The reference node's validated parameters (see ``PARAMS``)."""

    mode: str
    path: Path
    publish_rate: float
    lockstep_subscribers: int
    publish_samples: bool
    horizon: float
    trajectory_file: str
    trajectory_topic: str
    smoothing: float
    cruise_speed: float
    max_accel: float
    frame: str
    display_points: int
    start_delay: float = 1.0


def reference_settings(values: dict[str, Any]) -> ReferenceSettings:
    """Validate the reference's parameter values; InputError (e.g. PathError) if bad.

    Parameters
    ----------
    values : dict
        ``PARAMS`` by name; the path's own parameters are checked by
        :func:`~nonfragile_tracker.control.simulation.reference.make_path`.

    Returns
    -------
    ReferenceSettings

    Raises
    ------
    StartupError
        A ``center`` that is not [x, y], ``lockstep_subscribers`` below 0 or
        ``display_points`` below 2.
    """
    mode = check_mode(values['mode'])
    center = list(values['center'])
    if len(center) != 2:
        raise StartupError(f'center needs [x, y], got {center}')
    path = make_path(values['path'], radius=values['radius'], rate=values['rate'],
                     center_x=center[0], center_y=center[1], phase=values['phase'])
    require_at_least(values, 'lockstep_subscribers', 0)
    require_at_least(values, 'display_points', 2)
    return settings_from(ReferenceSettings, values, mode=mode, path=path,
                         frame=values['odom_frame'])


class ReferenceNode(AdapterNode[ReferenceSettings]):
    """ROS adapter around the reference paths and trajectories.

    :class:`.control.simulation.reference.Path` and :mod:`.control.simulation.trajectory`.

    Parameters
    ----------
    node_name : str, optional
        ``reference`` (the launch files' name; a namespace moves the whole system,
        its topics are relative).
    **node_kwargs
        rclpy ``Node`` keyword arguments (:class:`~nonfragile_tracker.nodes.common.AdapterNode`).
    """

    def __init__(self, node_name: str = 'reference', **node_kwargs: Any):
        super().__init__(node_name, **node_kwargs)
        self.config = cfg = self.bind_parameters(PARAMS, reference_settings)
        self.mode = cfg.mode
        self.path = cfg.path
        self.frame = cfg.frame
        self.pub_pose = self.create_publisher(PoseStamped, topics.REF_POSE, DATA_QOS)
        self.pub_twist = self.create_publisher(TwistStamped, topics.REF_TWIST, DATA_QOS)
        self.pub_accel = self.create_publisher(AccelStamped, topics.REF_ACCEL, DATA_QOS)
        self.pub_traj = self.create_publisher(PathMsg, topics.TRAJECTORY, LATCHED_QOS)
        self.pub_multidof = self.create_publisher(MultiDOFJointTrajectory,
                                                  topics.TRAJECTORY_MULTIDOF, LATCHED_QOS)
        self.pub_display = self.create_publisher(PathMsg, topics.REF_PATH, LATCHED_QOS)
        self._msgs = (PoseStamped(), TwistStamped(), AccelStamped())
        self._sample_pubs = (self.pub_pose, self.pub_twist, self.pub_accel)
        for m in self._msgs:
            m.header.frame_id = self.frame
        self.traj: Trajectory = Trajectory.analytic(self.path)
        self.origin_ns = 0
        self.last_refusal = ''
        self._pending: list[int] = []      # lockstep: stamps seen before the subscribers
        if self.mode == 'lockstep':
            if cfg.publish_samples or cfg.trajectory_topic:   # sample and relay times
                self.set_parameters([Parameter('use_sim_time', value=True)])
            if cfg.publish_samples:
                self.sub_clock = self.create_subscription(Clock, topics.CLOCK, self._on_clock,
                                                          DATA_QOS)
        else:
            self.t0_ns = self.get_clock().now().nanoseconds   # path time 0 = node start
            if cfg.publish_samples:
                self.timer = self.create_timer(1.0 / cfg.publish_rate, self._on_timer)
        start_ns = 0 if self.mode == 'lockstep' else self.t0_ns
        self._display_origin = start_ns
        file = cfg.trajectory_file
        if file:
            try:
                traj = load_waypoints(file, smoothing=cfg.smoothing)
            except (TrajectoryError, OSError) as exc:
                raise StartupError(f'reference: trajectory_file: {exc}') from None
            if self.mode == 'realtime':      # a start the tracker can meet: now (after the
                # node's start-up and the file's loading) + start_delay
                start_ns = self.get_clock().now().nanoseconds + int(round(cfg.start_delay * 1e9))
            self._follow(trajectory_to_path(traj, start_ns, self.frame), file)
        elif self.mode == 'lockstep' and not cfg.trajectory_topic:
            self._follow_analytic(start_ns)
        else:          # real time: the exact path's samples; a relay: the planner's plans
            self.origin_ns = start_ns          # path time 0 = node start (real time)
            self._display(self.traj, start_ns)
        relay = cfg.trajectory_topic
        if relay:
            self.create_subscription(PathMsg, relay, self._on_relay, 10)

    def apply_config(self, old: ReferenceSettings, new: ReferenceSettings) -> None:
        """An accepted runtime set (post-set callback): show the path with the new points.

        Parameters
        ----------
        old, new : ReferenceSettings
            The settings before and after the change.
        """
        if new.display_points != old.display_points:
            self._display(self.traj, self._display_origin)

    def _display(self, traj: Trajectory, origin_ns: int) -> None:
        self._display_origin = origin_ns
        n = self.config.display_points
        if traj.is_analytic:
            w = abs(self.path.params['rate'])
            span = 2 * math.pi / w if w > 0 else 1.0
            times = np.linspace(0.0, span, n)
        else:
            times = np.linspace(traj.t_start, traj.t_end, n)
        self.pub_display.publish(trajectory_to_path(traj, origin_ns, self.frame, times))

    def _follow_analytic(self, origin_ns: int) -> None:
        """Publish the built-in path as knots and follow the trajectory rebuilt from them.

        Start-up work in pieces of at most about 0.1 s for any horizon (an hour of the
        figure eight: 48,001 knots, about 0.2 s of CPU in all; it was 8 s), with a check
        for a stop signal between them (:meth:`check_stop`): the path sampled, the message
        made as its CDR bytes (the message object, point by point, took seconds), read
        back as the tracker reads them, and published as is.
        """
        try:
            t_ns = analytic_knot_times(self.path, self.config.horizon)
        except TrajectoryError as exc:
            raise StartupError(f'reference: {exc}') from None
        s = path_samples(self.path, t_ns)
        self.check_stop()
        raw = multidof_cdr(t_ns, s.x, s.y, s.heading, s.vx, s.vy, s.ax, s.ay, origin_ns,
                           self.frame)
        self.check_stop()
        self.traj, self.origin_ns = multidof_to_trajectory(multidof_from_cdr(raw),
                                                           frame=self.frame,
                                                           source=f'path {self.path.name}')
        self.check_stop()
        self.pub_multidof.publish(raw)
        self._display(Trajectory.analytic(self.path), origin_ns)
        self.log('info', f'trajectory: path {self.path.name} as {len(t_ns)} knots over '
                         f'{self.config.horizon:g} s on {self.pub_multidof.topic_name}')

    def _follow(self, msg: PathMsg, source: str) -> None:
        """Adopt the trajectory of a timed Path that this node built, and publish it.

        The per-step samples come from the trajectory rebuilt from ``msg`` exactly as
        the tracker rebuilds it, so the recorded reference is what the tracker follows.
        """
        traj, origin = path_to_trajectory(msg, frame=self.frame, source=source)
        self.traj, self.origin_ns = traj, origin
        self.pub_traj.publish(msg)
        self._display(traj, origin)
        self.log('info', f'trajectory from {source}: {len(traj.knots)} points, '
                         f'{traj.duration:.3f} s')

    def _relay(self, msg: PathMsg, source: str) -> None:
        """Validate a Path (time law if untimed) and follow its timed form."""
        traj, origin = path_to_trajectory(msg, frame=self.frame, source=source,
                                          cruise_speed=self.config.cruise_speed,
                                          max_accel=self.config.max_accel,
                                          now_ns=self.get_clock().now().nanoseconds)
        self._follow(trajectory_to_path(traj, origin, self.frame), source)

    def _on_relay(self, msg: PathMsg) -> None:
        source = f'topic {self.config.trajectory_topic}'
        try:
            self._relay(msg, source)
        except TrajectoryError as exc:
            self.last_refusal = str(exc)
            self.log('error', f'refused trajectory: {exc}; keeping the previous one')

    def publish_sample(self, t_ns: int, t: float) -> None:
        """Publish the sample at path time ``t`` (s) with header stamp ``t_ns``.

        Only to topics with a subscriber (nobody needs them per step: no work then).

        Parameters
        ----------
        t_ns : int
            Header stamp (ns).
        t : float
            Path time (s).
        """
        pubs = self._sample_pubs
        wanted = [p.get_subscription_count() > 0 for p in pubs]
        if not any(wanted):
            return
        ref = self.traj.sample(t)
        for m in self._msgs:
            ns_to_stamp(t_ns, m.header.stamp)
        fill_reference(ref, *self._msgs)
        for pub, msg, w in zip(pubs, self._msgs, wanted):
            if w:
                pub.publish(msg)

    def _on_clock(self, msg: Clock) -> None:
        t_ns = stamp_ns(msg.clock)
        need = self.config.lockstep_subscribers
        if need and any(p.get_subscription_count() < need
               for p in (self.pub_pose, self.pub_twist, self.pub_accel)):
            # not every subscriber matched yet: publish this step when they have (the
            # tracker does not wait for the samples, so nobody republishes the step)
            if len(self._pending) < 10 * topics.DEPTH:
                self._pending.append(t_ns)
            return
        if self._pending:
            pending, self._pending = self._pending, []
            for s in pending:
                if s != t_ns:
                    self.publish_sample(s, (s - self.origin_ns) * 1e-9)
        self.publish_sample(t_ns, (t_ns - self.origin_ns) * 1e-9)

    def _on_timer(self) -> None:
        now = self.get_clock().now().nanoseconds
        self.publish_sample(now, (now - self.origin_ns) * 1e-9)


#: Console entry point of the reference node: ``main(args)`` is ``run(ReferenceNode, args)``
#: (:func:`~nonfragile_tracker.nodes.common.run`: the exit code).
main = partial(run, ReferenceNode)


if __name__ == '__main__':
    # `python -m nonfragile_tracker.nodes.reference` is the console script's process: the
    # entry's signal handling, stack dumps on SIGUSR1 and tear-down deadline
    import sys

    from nonfragile_tracker.nodes.entry import main as node_main
    sys.exit(node_main('reference', sys.argv))
