"""One adapter: any controller, ours or a peer's, through the same loop on the same base.

:func:`run` hands a controller factory to
:func:`~nonfragile_tracker.control.simulation.follow.simulate_following` - the node's
lockstep sequence in process: the plant's odometry (its rate, latency, noise, jitter), the
:class:`~nonfragile_tracker.control.simulation.follow.Follower` sampling the trajectory at
each odometry stamp (and waiting, finishing at its end), the plant taking the command after
its latency through its actuator (lag, acceleration limits).  Every controller is wrapped
in :class:`Adapted`, which applies the same output clamps to all (the tracker config's
``max_linear_speed`` and ``max_angular_speed``; a non-finite command stops the base, as our
tracker does), times each call and can record what the controller was given.  Nothing else
differs between the rows of the table: same :class:`PlantConfig`, same trajectory, same
clamps.  :func:`score` turns a run into the table's figures.
"""
from __future__ import annotations

import inspect
import math
import time
from dataclasses import dataclass, field
from functools import partial
from typing import Any, Callable

import numpy as np

from nonfragile_tracker.control.simulation.follow import simulate_following
from nonfragile_tracker.control.simulation.interfaces import load_factory
from nonfragile_tracker.control.simulation.tracker import Command, TrackerConfig
from nonfragile_tracker.control.simulation.plant import PlantConfig
from nonfragile_tracker.control.simulation.reference import RefSample
from nonfragile_tracker.control.simulation.simulate import TrackingRun
from nonfragile_tracker.control.simulation.trajectory import Trajectory

__all__ = ['OURS', 'REALISTIC', 'PLANT_DT', 'base_plant', 'bind', 'Adapted', 'PeerRun', 'run',
           'Score', 'score', 'cross_track', 'DIVERGED']

#: Our law, the package's default controller.
OURS = 'nonfragile_tracker.control.simulation.tracker:Tracker'
#: The plant step (s).
PLANT_DT = 0.01
#: The realistic base (issue 38): 50 ms first-order lag on v and w, 1 m/s^2 and 3 rad/s^2,
#: 1 mm / 1 mrad odometry noise, and a little jitter: each command's latency one plant step
#: (10 ms) longer at random.  (The odometry stays on its 10 ms grid: an odometry jitter must
#: be below half the 20 ms period of 50 Hz, i.e. zero whole steps of 10 ms.)
REALISTIC = dict(lag_v=0.05, lag_w=0.05, max_linear_accel=1.0, max_angular_accel=3.0,
                 odom_noise=(0.001, 0.001, 0.001), cmd_latency_jitter=0.01)
#: A run whose time-indexed error after settling exceeds this (m) has diverged.
DIVERGED = 0.25


def base_plant(latency: float, odom_rate: float, seed: int,
               start: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0),
               **overrides: Any) -> PlantConfig:
    """The realistic base with a command latency (s), odometry rate (Hz), seed and start.

    Parameters
    ----------
    latency : float
        Command latency (s).
    odom_rate : float
        Odometry rate (Hz).
    seed : int
        Noise (and command-jitter) seed.
    start : (x, y, th, v)
        Initial pose (m, m, rad) and speed (m/s).
    **overrides
        Other :class:`PlantConfig` fields (e.g. ``cmd_latency_jitter=0``).

    Returns
    -------
    PlantConfig
    """
    x0, y0, th0, v0 = start
    kw: dict[str, Any] = dict(REALISTIC, **overrides)
    return PlantConfig(dt=PLANT_DT, x0=x0, y0=y0, th0=th0, v0=v0, cmd_latency=latency,
                       odom_rate=odom_rate, noise_seed=seed, **kw)


def bind(factory: str | Callable[..., Any], plant_config: PlantConfig,
         trajectory: Trajectory | None = None) -> Callable[..., Any]:
    """``factory`` with the base (keyword ``plant_config``) and the trajectory (keyword
    ``trajectory``: a path follower's path) given, if it takes them.

    Parameters
    ----------
    factory : str or callable
        ``module:name`` or a factory ``f(tracker_config[, plant_config=, trajectory=])``.
    plant_config : PlantConfig
        The base.
    trajectory : Trajectory, optional
        What the run follows.

    Returns
    -------
    callable
        ``f(tracker_config) -> Controller``.
    """
    f = load_factory(factory) if isinstance(factory, str) else factory
    try:
        params = inspect.signature(f).parameters
    except (TypeError, ValueError):          # a builtin or C-level callable: no keyword
        return f
    given = {k: v for k, v in (('plant_config', plant_config), ('trajectory', trajectory))
             if k in params and v is not None}
    return partial(f, **given) if given else f


class Adapted:
    """A controller with the adapter's clamps, timing and (optional) input record.

    Parameters
    ----------
    inner : Controller
        The controller.
    config : TrackerConfig
        Its speed limits are the clamps.
    record : bool
        Keep every call's inputs in :attr:`inputs` (``(x, y, th, ref, measured_speed,
        stamp, stamp_ns, measured_rate)``) and the resets in :attr:`resets`.
    """

    def __init__(self, inner: Any, config: TrackerConfig, record: bool = False):
        self.inner = inner
        self.vmax = float(config.max_linear_speed)
        self.wmax = float(config.max_angular_speed)
        self.record = record
        self.inputs: list[tuple[Any, ...]] = []
        self.resets: list[float | None] = []
        self.compute_ns: list[int] = []
        self.clamped = 0

    @property
    def timing(self) -> Any:
        """The controller's period estimator."""
        return self.inner.timing

    @property
    def horizon(self) -> float:
        """The controller's horizon (s)."""
        return float(self.inner.horizon)

    def reset(self, v: float | None = None) -> None:
        """Reset the controller."""
        if self.record:
            self.resets.append(v)
        self.inner.reset(v)

    def step(self, x: float, y: float, th: float, ref: RefSample,
             measured_speed: float | None = None, stamp: float | None = None,
             stamp_ns: int | None = None, measured_rate: float | None = None) -> Command:
        """The controller's command, clamped to the speed limits (non-finite: stop)."""
        if self.record:
            self.inputs.append((x, y, th, ref, measured_speed, stamp, stamp_ns, measured_rate))
        t0 = time.perf_counter_ns()
        cmd = self.inner.step(x, y, th, ref, measured_speed, stamp=stamp, stamp_ns=stamp_ns,
                              measured_rate=measured_rate)
        self.compute_ns.append(time.perf_counter_ns() - t0)
        v, w = float(cmd.v), float(cmd.w)
        if not (math.isfinite(v) and math.isfinite(w)):
            self.clamped += 1
            return cmd._replace(v=0.0, w=0.0, saturated=True)
        cv, cw = min(max(v, -self.vmax), self.vmax), min(max(w, -self.wmax), self.wmax)
        if cv != v or cw != w:
            self.clamped += 1
            return cmd._replace(v=cv, w=cw, saturated=True)
        return cmd


@dataclass
class PeerRun:
    """A run and what the adapter saw of its controller."""

    run: TrackingRun
    controller: Adapted
    trajectory: Trajectory
    plant_config: PlantConfig
    tracker_config: TrackerConfig
    extra: dict = field(default_factory=dict)


def run(factory: str | Callable[..., Any], plant_config: PlantConfig,
        tracker_config: TrackerConfig, trajectory: Trajectory, duration: float, *,
        record: bool = False,
        wrap: Callable[[Adapted], Any] | None = None,
        plant: str | Callable[..., Any] | None = None) -> PeerRun:
    """Run ``factory``'s controller on the base ``plant_config`` along ``trajectory``.

    Parameters
    ----------
    factory : str or callable
        ``module:name`` or ``f(tracker_config[, plant_config=...]) -> Controller``
        (:func:`bind`); :data:`OURS` for our law.
    plant_config : PlantConfig
        The base.
    tracker_config : TrackerConfig
        Given to the factory; its speed limits are the clamps of every controller.
    trajectory : Trajectory
        What to follow (already re-timed, if it is to be).
    duration : float
        Simulated time (s).
    record : bool
        Record the controller's inputs (:class:`Adapted`).
    wrap : callable, optional
        Wraps the adapted controller once more (tests: drive the base open loop).
    plant : str or callable, optional
        The base behind the plant seam (``module:name`` or ``f(plant_config) -> Plant``,
        e.g. a MuJoCo base of ``physics``); default the kinematic plant of ``plant_config``.
        Every controller of a row gets the same.

    Returns
    -------
    PeerRun
    """
    made: list[Adapted] = []
    f = bind(factory, plant_config, trajectory)

    def make(config: TrackerConfig) -> Any:
        a = Adapted(f(config), config, record=record)
        made.append(a)
        return a if wrap is None else wrap(a)

    steps = max(1, int(round(duration / plant_config.dt)))
    tr = simulate_following(plant_config, tracker_config, trajectory, steps, controller=make,
                            plant=plant)
    return PeerRun(tr, made[0], trajectory, plant_config, tracker_config)


# ------------------------------------------------------------------------------- scoring

def cross_track(px: np.ndarray, py: np.ndarray, qx: np.ndarray, qy: np.ndarray) -> np.ndarray:
    """Distance (m) from each point ``p`` to the polyline ``q`` (its nearest segment).

    The nearest vertex is found by a k-d tree; the distance is the smaller of the two
    segments at that vertex (exact for a polyline whose segments are short against its
    curvature radius).
    """
    from scipy.spatial import cKDTree
    q = np.column_stack([qx, qy])
    p = np.column_stack([px, py])
    _, i = cKDTree(q).query(p)
    best = np.hypot(*(p - q[i]).T)
    for j0 in (i - 1, i):
        j0 = np.clip(j0, 0, len(q) - 2)
        a, b = q[j0], q[j0 + 1]
        ab = b - a
        L2 = np.einsum('ij,ij->i', ab, ab)
        s = np.clip(np.einsum('ij,ij->i', p - a, ab) / np.where(L2 > 0, L2, 1.0), 0.0, 1.0)
        d = np.hypot(*(p - (a + s[:, None] * ab)).T)
        best = np.minimum(best, d)
    return best


@dataclass(frozen=True)
class Score:
    """The table's figures of one run (SI units; nan where not defined)."""

    rms: float               # time-indexed |p - p_d(t)| after settling (m)
    max: float
    rms_active: float        # the same over the whole active trajectory (from its start)
    max_active: float
    cross_rms: float         # distance to the planned path after settling (m)
    cross_max: float
    lap_delta: float         # arrival time - planned end (s); nan for endless paths
    dw_rms: float            # RMS dw/dt of the commands (rad/s^2)
    saturated: float         # share of the commands at a speed limit
    diverged: bool
    compute_med_us: float    # per command (the controller's step alone)
    compute_p99_us: float


def score(pr: PeerRun, settle: float = 10.0, arrive_tol: float = 0.02) -> Score:
    """The figures of a run after ``settle`` s, while the trajectory is active.

    The window is ``settle <= t <= t_end`` (the end of the trajectory, or of the run for an
    endless path); ``rms_active``, ``max_active``: over ``t_start <= t <= t_end`` (the run's
    start for an endless path).  ``lap_delta``: the time from which the robot stays within
    ``arrive_tol`` of the end point at rest (< 1 cm/s), minus the planned end; nan if it
    never does within the run.  ``saturated``: the share of the commands in the window with
    ``|v|`` or ``|w|`` at its limit.  ``diverged``: the error in the window exceeds
    :data:`DIVERGED` or is not finite.
    """
    r = pr.run
    traj = pr.trajectory
    t = r.t
    t_end = min(traj.t_end, t[-1]) if math.isfinite(traj.t_end) else t[-1]
    win = (t >= settle) & (t <= t_end)
    e = r.error[win]
    t0 = traj.t_start if math.isfinite(traj.t_start) else t[0]
    act = r.error[(t >= t0) & (t <= t_end)]
    a_ok = bool(np.all(np.isfinite(act))) and act.size > 0
    finite = bool(np.all(np.isfinite(e))) and e.size > 0
    rms = float(np.sqrt(np.mean(e * e))) if finite else math.nan
    mx = float(np.max(e)) if finite else math.nan
    if math.isfinite(traj.t_start):
        tt = np.arange(traj.t_start, traj.t_end + 1e-9, 0.005)
    else:
        tt = np.arange(0.0, t[-1] + 1e-9, 0.005)
    s = traj.evaluate(tt)
    if finite:
        ct = cross_track(r.x[win], r.y[win], s.x, s.y)
        c_rms, c_max = float(np.sqrt(np.mean(ct * ct))), float(np.max(ct))
    else:
        c_rms = c_max = math.nan
    lap = math.nan
    if math.isfinite(traj.t_end):
        end = traj.sample(traj.t_end)
        ok = (np.hypot(r.x - end.x, r.y - end.y) <= arrive_tol) & (np.abs(r.speed) < 0.01)
        if ok[-1]:
            bad = np.nonzero(~ok)[0]
            k = 0 if bad.size == 0 else bad[-1] + 1
            lap = float(t[k] - traj.t_end)
    cmd = (r.commanded > 0.5) & win
    tc, wc, vc = t[cmd], r.cmd_w[cmd], r.cmd_v[cmd]
    dw = np.diff(wc) / np.diff(tc) if tc.size > 1 else np.zeros(0)
    dw_rms = float(np.sqrt(np.mean(dw * dw))) if dw.size else math.nan
    a = pr.controller
    sat = float(np.mean((np.abs(vc) >= a.vmax * (1 - 1e-9)) | (np.abs(wc) >= a.wmax * (1 - 1e-9)))
                ) if vc.size else math.nan
    c_ns = np.asarray(a.compute_ns, float)
    diverged = (not finite) or mx > DIVERGED
    return Score(rms, mx, float(np.sqrt(np.mean(act * act))) if a_ok else math.nan,
                 float(np.max(act)) if a_ok else math.nan, c_rms, c_max, lap, dw_rms, sat,
                 bool(diverged),
                 float(np.median(c_ns)) / 1e3 if c_ns.size else math.nan,
                 float(np.percentile(c_ns, 99)) / 1e3 if c_ns.size else math.nan)
