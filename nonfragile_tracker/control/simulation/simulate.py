"""Fixed-step simulations: the linear delay loop (paper Figs. 2-5) and the tracking loop.

:func:`simulate_tracking` runs exactly the sequence of the ROS lockstep loop:
for each step ``k`` with an odometry sample due (every step for the paper's plant)
the measured pose (yaw through a quaternion, as in the message), its stamp and the
reference sample at that stamp go into :meth:`.Tracker.step`, and its command is
given to :meth:`.UnicyclePlant.command`; then :meth:`.UnicyclePlant.advance` applies
the command in force (held at steps without odometry).

See doc/ros-interface.md, section "Time and lockstep" (equal to the simulation).
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Callable, cast

import numpy as np
from numpy.typing import ArrayLike

from .interfaces import ControllerFactory, Plant, PlantFactory, make_controller, make_plant
from .tracker import Command, TrackerConfig
from .plant import PlantConfig, UnicyclePlant, odometry_period_steps
from .model import quaternion_to_yaw, yaw_to_quaternion
from .timing import step_time
from .metrics import TrackingMetrics, tracking_metrics
from .reference import Path, RefSample
from .sensors import OdometrySample
from .timing import period_disagreement

__all__ = ['TrackingRun', 'simulate_tracking', 'run_loop', 'report_override',
           'DelayRun', 'simulate_delay_loop',
           'rk4_delay_steps',
           'steps_for_duration']


def steps_for_duration(duration: float, dt: float) -> int:
    """Number of plant steps in ``duration`` seconds (at least 1).

    Parameters
    ----------
    duration : float
        Length of the run [s], > 0.
    dt : float
        Plant step [s].

    Returns
    -------
    int
        ``round(duration / dt)``, at least 1.

    Raises
    ------
    ValueError
        If ``duration`` is not > 0.
    """
    if not duration > 0:
        raise ValueError(f'duration must be > 0 s, got {duration!r}')
    return max(1, int(round(duration / dt)))


@dataclass(frozen=True)
class TrackingRun:
    """Samples of a tracking run, one row per step ``k = 0..steps`` (SI units).

    Row ``k`` holds the true pose at ``t_k``, the reference at ``t_k`` and the last
    command the tracker sent up to step ``k`` (``commanded[k]`` is 1 where it computed
    one at step ``k``; with the paper's plant every step, from the pose and reference
    of that step; the last command is computed but not applied).
    """

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    th: np.ndarray
    speed: np.ndarray        # speed in force at t_k (what odom reports)
    xd: np.ndarray
    yd: np.ndarray
    vxd: np.ndarray
    vyd: np.ndarray
    cmd_v: np.ndarray
    cmd_w: np.ndarray
    commanded: np.ndarray    # 1.0 at steps where the tracker computed a command

    def metrics(self, tolerance: float = 0.01) -> TrackingMetrics:
        """Tracking metrics of the run (:func:`~.metrics.tracking_metrics`).

        Parameters
        ----------
        tolerance : float, optional
            Error [m] within which the robot counts as tracking.

        Returns
        -------
        TrackingMetrics
        """
        return tracking_metrics(self.t, self.x, self.y, self.xd, self.yd, self.cmd_v,
                                self.cmd_w, tolerance=tolerance)

    @property
    def error(self) -> np.ndarray:
        """Position error ``|p - p_d|`` in m at every sample."""
        return cast(np.ndarray, np.hypot(self.x - self.xd, self.y - self.yd))


def simulate_tracking(plant_config: PlantConfig, tracker_config: TrackerConfig, path: Path,
                      steps: int, *, controller: str | ControllerFactory | None = None,
                      plant: str | PlantFactory | None = None) -> TrackingRun:
    """Run the nonlinear tracking loop for ``steps`` plant steps (``steps + 1`` samples).

    The tracker takes its step from the odometry stamps (``dt = 0``, the default); a
    ``dt`` set by hand that disagrees with the odometry period (``plant dt`` times the
    odometry decimation) is run as set and reported (:func:`report_override`), as the
    tracker node reports it.

    Parameters
    ----------
    plant_config : PlantConfig
        The simulated robot (step, actuator, odometry, latencies).
    tracker_config : TrackerConfig
        The tracker (gain, ``dt``, limits, predictor).
    path : Path
        The reference path, sampled at each odometry stamp.
    steps : int
        Number of plant steps.
    controller, plant : str or callable, optional
        The controller and the plant (:func:`~.interfaces.make_controller`,
        :func:`~.interfaces.make_plant`; default our law and the unicycle).

    Returns
    -------
    TrackingRun

    Warns
    -----
    UserWarning
        If the tracker's ``dt`` is set and disagrees with the odometry period.
    """
    report_override(plant_config, tracker_config)
    tracker = make_controller(tracker_config, controller)
    dt = plant_config.dt

    def command(meas: OdometrySample, th: float, k: int, ref: RefSample) -> Command:
        if meas.step == k:
            return tracker.step(meas.x, meas.y, th, ref, meas.v, measured_rate=meas.w)
        ts = step_time(meas.step, dt)
        return tracker.step(meas.x, meas.y, th, path.sample(ts), meas.v, stamp=ts,
                            measured_rate=meas.w)

    return run_loop(make_plant(plant_config, plant), steps, command,
                    lambda k: path.sample(step_time(k, dt)))


def report_override(plant_config: PlantConfig, tracker_config: TrackerConfig) -> str | None:
    """Warn (once per call) when the tracker's ``dt`` override disagrees with the odometry.

    The odometry period of a lockstep run is ``plant dt`` times the odometry decimation;
    a ``dt`` set by hand more than :data:`.control.simulation.timing.CHANGE` away from it
    is what the tracker node reports on /diagnostics
    (:func:`.control.simulation.timing.period_disagreement`).

    Parameters
    ----------
    plant_config, tracker_config : PlantConfig, TrackerConfig
        The plant (its odometry period) and the tracker (its ``dt``).

    Returns
    -------
    str or None
        The message warned, None if the override agrees or there is none.
    """
    period = odometry_period_steps(plant_config.odom_rate, plant_config.dt)[0]
    msg = period_disagreement(tracker_config.dt, step_time(period, plant_config.dt))
    if msg is not None:
        warnings.warn(msg, UserWarning, stacklevel=3)
    return msg


def run_loop(plant: PlantConfig | Plant, steps: int,
             command: Callable[[OdometrySample, float, int, RefSample], Command],
             reference: Callable[[int], RefSample]) -> TrackingRun:
    """The lockstep sequence of the ROS nodes, in process: the one simulation loop.

    For each step ``k``: the plant's odometry due at ``k`` (if any; yaw through a
    quaternion, as in the message) goes to ``command(measurement, yaw, k, reference(k))``, whose
    command the plant takes (after its command latency); otherwise the command in force
    is held.  ``reference(k)`` is logged with step ``k``.  Used by
    :func:`simulate_tracking` and :func:`.control.simulation.follow.simulate_following`.

    Parameters
    ----------
    plant : Plant or PlantConfig
        The simulated robot (:class:`~.interfaces.Plant`, at its initial state), or the
        settings of a :class:`~.plant.UnicyclePlant`.
    steps : int
        Number of plant steps (``steps + 1`` samples).
    command : callable
        ``command(measurement, yaw, k, reference)`` returns the :class:`.Command` for an
        odometry sample (``yaw`` [rad] read back through a quaternion).
    reference : callable
        ``reference(k)`` is the reference sample logged at step ``k``.

    Returns
    -------
    TrackingRun
    """
    if isinstance(plant, PlantConfig):
        plant = UnicyclePlant(plant)
    rows: list[tuple[float | bool, ...]] = []
    append = rows.append
    dt = plant.dt
    cmd_v, cmd_w = plant.cmd
    for k in range(steps + 1):
        t = step_time(k, dt)
        ref = reference(k)
        meas = plant.odometry()
        if meas is not None:
            th = quaternion_to_yaw(*yaw_to_quaternion(meas.th))   # as through a message
            cmd = command(meas, th, k, ref)
            cmd_v, cmd_w = cmd.v, cmd.w
            plant.command(cmd_v, cmd_w)
        append((t, plant.x, plant.y, plant.th, plant.v, ref.x, ref.y, ref.vx, ref.vy,
                cmd_v, cmd_w, meas is not None))
        if k < steps:
            plant.advance()
    return TrackingRun(*np.array(rows, dtype=float).T.copy())


@dataclass(frozen=True)
class DelayRun:
    """Trajectory of the linear delay loop: ``t`` (s) and ``xi`` (one row per time)."""

    t: np.ndarray
    xi: np.ndarray


def simulate_delay_loop(A0: ArrayLike, A1: ArrayLike, tau: float, xi0: ArrayLike,
                        duration: float, dt: float = 1e-3,
                        history: Callable[[float], ArrayLike] | None = None) -> DelayRun:
    """Integrate ``xi' = A0 xi + A1 xi(t - tau)`` with RK4 and a history buffer.

    ``tau`` must be a multiple of ``dt`` (to 1e-9 relative); the delayed state at
    the RK4 half step is the mean of the two neighbouring buffer samples.  The
    initial function is ``history`` (callable ``s -> xi(s)`` for ``s`` in
    ``[-tau, 0]``) or the constant ``xi0``.

    Parameters
    ----------
    A0, A1 : array_like, shape (n, n)
        Matrices of the current and the delayed state.
    tau : float
        Delay [s], a multiple of ``dt``.
    xi0 : array_like, shape (n,)
        State at ``t = 0`` (and the constant initial function without ``history``).
    duration : float
        Length of the run [s].
    dt : float, optional
        Integration step [s].
    history : callable, optional
        ``history(s)`` is the state at ``s`` in ``[-tau, 0)`` (shape (n,)).

    Returns
    -------
    DelayRun
        ``t`` of shape (steps + 1,) and ``xi`` of shape (steps + 1, n).

    Raises
    ------
    ValueError
        For mismatched shapes, or a ``tau`` that is not a multiple of ``dt``.
    """
    A0 = np.asarray(A0, float)
    A1 = np.asarray(A1, float)
    xi0 = np.asarray(xi0, float)
    n = A0.shape[0]
    if A0.shape != (n, n) or A1.shape != (n, n) or xi0.shape != (n,):
        raise ValueError(f'shapes do not match: A0 {A0.shape}, A1 {A1.shape}, xi0 {xi0.shape}')
    N = int(round(tau / dt))
    if abs(N * dt - tau) > 1e-9 * max(1.0, tau):
        raise ValueError(f'tau = {tau} s is not a multiple of dt = {dt} s')
    steps = steps_for_duration(duration, dt)
    if N == 0:                      # no delay: xi' = (A0 + A1) xi
        A0, A1 = A0 + A1, np.zeros_like(A1)
    out = np.zeros((N + steps + 1, n))
    for i in range(N + 1):
        s = (i - N) * dt
        out[i] = xi0 if history is None or i == N else np.asarray(history(s), float)
    rk4_delay_steps(out, N, steps, dt, lambda x, xd: A0 @ x + A1 @ xd)
    return DelayRun(np.arange(steps + 1) * dt, out[N:].copy())


def rk4_delay_steps(out: np.ndarray, N: int, steps: int, dt: float,
                    f: Callable[[np.ndarray, np.ndarray], np.ndarray]) -> None:
    """RK4 steps of ``xi' = f(xi, xi(t - N dt))`` in place over the history buffer ``out``.

    ``out[:N + 1]`` holds the initial function on ``[-N dt, 0]``; ``out[N + k + 1]`` is
    written from ``out[N + k]``.  The delayed state at the half step is the mean of the
    two neighbouring samples.  Shared by :func:`simulate_delay_loop` and the batched loop
    (:func:`.control.simulation.batch.simulate_delay_loop_batch`), so both integrate the same way.

    Parameters
    ----------
    out : numpy.ndarray, shape (N + steps + 1, ...)
        The buffer, written in place from row ``N + 1`` on.
    N : int
        The delay in steps.
    steps : int
        Number of steps to take.
    dt : float
        Step [s].
    f : callable
        ``f(xi, xi_delayed)`` returns ``xi'`` (same shape as a row of ``out``).
    """
    for k in range(steps):
        i = N + k
        x = out[i]
        d0, d1 = out[i - N], out[i - N + 1]
        dm = 0.5 * (d0 + d1)
        k1 = f(x, d0)
        k2 = f(x + 0.5 * dt * k1, dm)
        k3 = f(x + 0.5 * dt * k2, dm)
        k4 = f(x + dt * k3, d1)
        out[i + 1] = x + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
