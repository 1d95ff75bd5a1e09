"""Following a timed trajectory to its end: the tracking law plus the end-of-trajectory rule.

:class:`Follower` is the one step function of a tracker that samples its trajectory
itself (at the odometry stamp): ``step(x, y, th, t, speed)`` samples the
:class:`~.trajectory.Trajectory` at ``t`` and calls :meth:`.tracker.Tracker.step`; it waits
at rest before the trajectory's first time and, after its end, stops once the speed is
below ``rest_speed`` (the last command ramped to zero within the law's acceleration
limits).  :func:`simulate_following` is the in-process run with exactly the node's
sequence, so a lockstep ROS run and it agree to round-off.  No ROS import.

See doc/trajectories.md, section "Start, end and bad input".
"""
from __future__ import annotations

import math
from typing import Any, cast


from .actuator import within
from .limits import ACCEL_FRACTION, Limits, within_limits
from .interfaces import Controller, ControllerFactory, PlantFactory, make_controller, make_plant
from .tracker import Command, TrackerConfig
from .plant import PlantConfig
from .timing import step_time_ns
from .reference import RefSample
from .simulate import TrackingRun, report_override, run_loop
from .trajectory import Trajectory

__all__ = ['Follower', 'simulate_following', 'REST_SPEED', 'path_errors', 'trajectory_time',
           'start_offset', 'START_TOLERANCE', 'MAX_START_DISTANCE']

#: Default speed (m/s) below which, after the trajectory's end, the robot is at rest.
REST_SPEED = 0.01
#: Default lateness (s) beyond which a trajectory that starts at rest is re-based.
START_TOLERANCE = 0.1
#: Default largest distance (m) between the robot and the reference at the first step.
MAX_START_DISTANCE = 1.0


def start_offset(trajectory: Trajectory, t_first: float, *,
                 start_tolerance: float = START_TOLERANCE,
                 rest_speed: float = REST_SPEED) -> float:
    """Time shift (s) applied to a trajectory first followed at trajectory time ``t_first``.

    Parameters
    ----------
    trajectory : Trajectory
        The trajectory about to be followed.
    t_first : float
        Trajectory time (s) of the first step that follows it (at or after ``t_start``).
    start_tolerance : float
        Lateness (s) accepted without re-basing (transport delays).
    rest_speed : float
        The trajectory starts at rest when its speed at ``t_start`` is below this (m/s).

    Returns
    -------
    float
        ``t_first - t_start`` when the trajectory starts at rest and the first step is
        more than ``start_tolerance`` late (the trajectory is then sampled at
        ``t - offset``: it starts at the first step), else ``0.0`` (on its stamps; also
        for analytic paths, which have no start).
    """
    t0 = trajectory.t_start
    late = t_first - t0
    if not math.isfinite(t0) or not late > start_tolerance:
        return 0.0
    r = trajectory.sample(t0)
    if math.hypot(r.vx, r.vy) >= rest_speed:
        return 0.0
    return late


def path_errors(x: float, y: float, th: float, ref: RefSample) -> tuple[float, float, float]:
    """Along-track, cross-track (m) and heading error (rad) of a pose against a reference.

    In the reference point's frame (x along its heading, y to its left, REP-103):
    along-track ``> 0`` means the robot is ahead, cross-track ``> 0`` that it is to the
    left; the heading error is ``th - heading`` wrapped to ``[-pi, pi]``.

    Parameters
    ----------
    x, y : float
        Position of the robot (m).
    th : float
        Heading of the robot (rad).
    ref : RefSample
        The reference point (position ``x``, ``y`` and ``heading``).

    Returns
    -------
    (float, float, float)
        Along-track (m), cross-track (m), heading error (rad).
    """
    dx, dy = x - ref.x, y - ref.y
    c, s = math.cos(ref.heading), math.sin(ref.heading)
    return (c * dx + s * dy, -s * dx + c * dy, math.remainder(th - ref.heading, math.tau))


def trajectory_time(stamp_ns: int, origin_ns: int) -> float:
    """Trajectory time (s) of a stamp: ``(stamp - origin) * 1e-9`` (integer ns difference).

    What a lockstep tracker passes to :meth:`Follower.step` for the odometry stamp, and
    what the bag reader samples a recorded trajectory message at (one formula).

    Parameters
    ----------
    stamp_ns : int
        The stamp (ns).
    origin_ns : int
        The trajectory's origin (ns: its header stamp, or when it was received).

    Returns
    -------
    float
    """
    return (int(stamp_ns) - int(origin_ns)) * 1e-9


class Follower:
    """Track ``trajectory`` with ``tracker`` and stop at its end.

    Parameters
    ----------
    tracker : Controller
        The tracking law (:class:`~.interfaces.Controller`; reset on :meth:`set_trajectory`).
    trajectory : Trajectory
        What to follow; time ``t`` of :meth:`step` is trajectory time (s).
    rest_speed : float
        After ``t_end``, ``|cmd v|`` below this (m/s) ends the run: with a zero command, or,
        for a law configured with acceleration limits (a ``TrackerConfig``'s
        ``max_*_accel``, the command's), the last command ramped to zero within them (a turn
        still asked for at rest is not cut in one step), the run finished at zero.
    start_tolerance : float
        A trajectory starting at rest and first followed more than this (s) after its
        start time is re-based to start then (:func:`start_offset`).
    max_start_distance : float
        At the first step, a robot further than this (m) from the reference refuses the
        trajectory (``refused``); 0 = no check.
    """

    def __init__(self, tracker: Controller, trajectory: Trajectory, rest_speed: float = REST_SPEED,
                 *, start_tolerance: float = START_TOLERANCE,
                 max_start_distance: float = MAX_START_DISTANCE):
        if not (math.isfinite(rest_speed) and rest_speed > 0):
            raise ValueError(f'rest_speed must be a finite number > 0 m/s, got {rest_speed!r}')
        for name, val in (('start_tolerance', start_tolerance),
                          ('max_start_distance', max_start_distance)):
            if not (math.isfinite(val) and val >= 0):
                raise ValueError(f'{name} must be a finite number >= 0, got {val!r}')
        self.tracker = tracker
        self.rest_speed = float(rest_speed)
        self.start_tolerance = float(start_tolerance)
        self.max_start_distance = float(max_start_distance)
        self.set_trajectory(trajectory)

    def set_trajectory(self, trajectory: Trajectory) -> None:
        """Start a new run on ``trajectory`` (compensator re-initialised from odometry).

        Parameters
        ----------
        trajectory : Trajectory
            The trajectory to follow from now on.
        """
        self.trajectory = trajectory
        self.finished = False
        self.ended = False          # past t_end (still settling until finished)
        self.finished_at: float | None = None
        #: ``(t, v, w)`` of the last command of the stop ramp (see :meth:`step`), or None.
        self._stopping: tuple[float, float, float] | None = None
        self.last_ref: RefSample | None = None
        self.started = False        # the first step at or after t_start has been taken
        self.offset = 0.0           # trajectory time = t - offset (see start_offset)
        self.refused: str | None = None    # why the trajectory was refused at its start
        self.tracker.reset()

    def splice(self, trajectory: Trajectory) -> None:
        """Continue the motion on ``trajectory`` (a replanned path): no new run.

        The compensator, the start (and its re-basing offset) and the time base are kept;
        ``trajectory`` is timed on from the follower's time now
        (:func:`~.replan.splice_path`).

        Parameters
        ----------
        trajectory : Trajectory
            The trajectory to follow from now on.
        """
        self.trajectory = trajectory
        self.finished = self.ended = False
        self.finished_at = None
        self._stopping = None

    def step(self, x: float, y: float, th: float, t: float,
             measured_speed: float | None = None, measured_rate: float | None = None
             ) -> Command:
        """Command for the pose ``(x, y, th)`` measured at trajectory time ``t``.

        With a controller's ``horizon`` > 0 (our law's predictor) the trajectory is sampled
        at ``t + horizon`` (the time the command acts); the times the controller sees are
        trajectory times (consistent: it uses differences only, and a new trajectory
        resets it).

        Parameters
        ----------
        x, y : float
            Measured position (m).
        th : float
            Measured heading (rad).
        t : float
            Trajectory time of the measurement (s, :func:`trajectory_time`).
        measured_speed : float, optional
            Measured speed (m/s; initialises the tracker's speed state).
        measured_rate : float, optional
            Measured yaw rate (rad/s), passed to the controller.

        Returns
        -------
        Command
        """
        traj = self.trajectory
        if not self.started and t >= traj.t_start:
            self._start(x, y, t)
        t = t - self.offset
        ref = traj.sample(t)
        self.last_ref = ref
        if self.finished or self.refused:
            return Command(v=0.0, w=0.0)
        if self._stopping is not None:
            return self._stop_step(t)
        if t < self.trajectory.t_start:
            # not started: wait at rest (holding a point with v = 0 would turn the robot
            # on the spot); the compensator starts from the measured speed at t_start
            self.tracker.reset()
            return Command(v=0.0, w=0.0)
        horizon = self.tracker.horizon
        if horizon > 0.0:
            # a predictor evaluates the law at the time the command acts: sample the
            # trajectory there (exact, also across its end) instead of extrapolating
            ref = self.trajectory.sample(t + horizon)
        cmd = self.tracker.step(x, y, th, ref, measured_speed, stamp=t,
                                measured_rate=measured_rate)
        if t > self.trajectory.t_end:
            self.ended = True
            if abs(cmd.v) < self.rest_speed:
                if cmd.w != 0.0 and any(self._stop_limits()):
                    self._stopping = (t, cmd.v, cmd.w)     # ramp to rest from this command
                    return cmd
                return self._finish(t, cmd.error)
        return cmd

    def _stop_limits(self) -> tuple[float, float]:
        """The acceleration limits (command's, m/s^2, rad/s^2; 0 = none) the stop ramps at.

        Those of a controller configured with them (our law's ``TrackerConfig``); else none,
        and the stop is one zero command.
        """
        c = getattr(self.tracker, 'config', None)
        if not isinstance(c, TrackerConfig):
            return 0.0, 0.0
        return c.max_linear_accel, c.max_angular_accel

    def _stop_step(self, t: float) -> Command:
        """The next command of the stop ramp: the last moved toward zero within the limits."""
        t0, v, w = cast(tuple[float, float, float], self._stopping)
        h = max(t - t0, 0.0)
        av, aw = self._stop_limits()
        v = within(0.0, v, av * h) if av > 0 else 0.0
        w = within(0.0, w, aw * h) if aw > 0 else 0.0
        if v == 0.0 and w == 0.0:
            return self._finish(t)
        self._stopping = (t, v, w)
        return Command(v=v, w=w)

    def _finish(self, t: float, error: tuple[float, float, float, float] | None = None
                ) -> Command:
        """End the run at ``t``: the zero command, the law reset."""
        self._stopping = None
        self.finished = True
        self.finished_at = t
        self.tracker.reset(0.0)
        return Command(v=0.0, w=0.0) if error is None else Command(v=0.0, w=0.0, error=error)

    def _start(self, x: float, y: float, t: float) -> None:
        """The first step on the trajectory: re-base a late start, check the distance."""
        self.started = True
        traj = self.trajectory
        self.offset = start_offset(traj, t, start_tolerance=self.start_tolerance,
                                   rest_speed=self.rest_speed)
        ref = traj.sample(t - self.offset)
        d = math.hypot(x - ref.x, y - ref.y)
        if self.max_start_distance > 0 and d > self.max_start_distance:
            self.refused = (f'{traj.source}: the robot at ({x:.3f}, {y:.3f}) m is {d:.3f} m '
                            f'from the trajectory\'s start ({ref.x:.3f}, {ref.y:.3f}) m, more '
                            f'than max_start_distance = {self.max_start_distance:g} m; drive '
                            'it closer or send a trajectory that starts at the robot')
            self.tracker.reset(0.0)


def simulate_following(plant_config: PlantConfig, tracker_config: TrackerConfig,
                       trajectory: Trajectory, steps: int, *,
                       rest_speed: float = REST_SPEED, origin_ns: int = 0,
                       start_tolerance: float = START_TOLERANCE,
                       max_start_distance: float = MAX_START_DISTANCE,
                       limits: Limits | None = None,
                       accel_fraction: float = ACCEL_FRACTION,
                       controller: str | ControllerFactory | None = None,
                       plant: str | PlantFactory | None = None) -> TrackingRun:
    """In-process run of a :class:`Follower`, the ROS lockstep sequence step by step.

    Step ``k`` is stamped ``t_k`` (integer nanoseconds); the trajectory is sampled at
    ``(t_k - origin_ns) * 1e-9`` as the tracker node does.  With ``limits`` the
    trajectory is first re-timed within them as the tracker node (``retime: true``) does
    (:func:`.limits.within_limits`).

    Parameters
    ----------
    plant_config, tracker_config : PlantConfig, TrackerConfig
        The plant and the tracker.
    trajectory : Trajectory
        The trajectory followed.
    steps : int
        Plant steps (``steps + 1`` samples).
    rest_speed : float
        Speed (m/s) below which the robot is at rest (after the trajectory's end; a
        trajectory that starts slower starts at rest, :func:`start_offset`).
    origin_ns : int
        The trajectory's origin (ns).
    start_tolerance : float
        Lateness (s) of the first step accepted without re-basing a trajectory that starts
        at rest (:func:`start_offset`).
    max_start_distance : float
        Largest distance (m) between the robot and the reference at the first step.
    limits : Limits, optional
        The robot's limits: the trajectory is re-timed within them first.
    accel_fraction : float, optional
        With ``limits``: the share of the acceleration limits the trajectory may use
        (the tracker's ``trajectory_accel_fraction``).
    controller, plant : str or callable, optional
        The controller and the plant (:func:`~.interfaces.make_controller`,
        :func:`~.interfaces.make_plant`; default our law and the unicycle).

    Returns
    -------
    TrackingRun
    """
    if limits is not None:
        trajectory = within_limits(trajectory, limits, accel_fraction)[0]
    report_override(plant_config, tracker_config)
    follower = Follower(make_controller(tracker_config, controller), trajectory, rest_speed,
                        start_tolerance=start_tolerance, max_start_distance=max_start_distance)
    dt = plant_config.dt

    def traj_time(k: int) -> float:
        return (step_time_ns(k, dt) - origin_ns) * 1e-9

    def command(meas: Any, th: float, k: int, ref: RefSample) -> Command:
        return follower.step(meas.x, meas.y, th, traj_time(meas.step), meas.v, meas.w)

    return run_loop(make_plant(plant_config, plant), steps, command,
                    lambda k: trajectory.sample(traj_time(k) - follower.offset))
