"""A saturation certificate against the nonlinear robot: starts on and beyond its boundary.

:func:`check_region` runs the package's own tracking loop
(:func:`.control.simulation.simulate.simulate_tracking`, the tracker with its own clamps)
from error states on the boundary of a certified set
(:class:`.control.synthesis.saturation.SaturationCertificate`) and says whether each
converges, how low the speed went and how often the turn-rate clamp bound;
:func:`smallest_failing` scales starts outward until one does not converge.

See doc/theory.md, section "Saturation: a certified region of attraction" (the error
states, the delay-consistent reference), and benchmarks/README.md.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .plant import PlantConfig
from .tracker import TrackerConfig
from .reference import Path
from .simulate import simulate_tracking

__all__ = ['RobotSetup', 'StartResult', 'RegionCheck', 'boundary_starts', 'reference_speeds',
           'simulate_start', 'check_region', 'smallest_failing']


@dataclass(frozen=True)
class RobotSetup:
    """The simulated robot and tracker (SI units).

    Parameters
    ----------
    path : Path
        The reference.
    A_tau : numpy.ndarray, shape (4, 4)
        The plant's state-delay matrix (the tracker compensates it).
    tau : float
        The state delay (s).
    cmd_latency : float
        Command latency of the plant (s).
    lag : float
        First-order actuator lag on ``v`` and ``w`` (s).
    max_angular_speed, min_speed, max_linear_speed, max_linear_accel : float
        The tracker's clamps and speed floor.
    dt : float
        Plant and tracker step (s).
    duration : float
        Simulated time (s).
    """

    path: Path
    A_tau: np.ndarray
    tau: float
    cmd_latency: float = 0.0
    lag: float = 0.0
    max_angular_speed: float = 2.0
    min_speed: float = 1e-3
    max_linear_speed: float = 1.0
    max_linear_accel: float = 0.0
    dt: float = 0.01
    duration: float = 60.0


@dataclass(frozen=True)
class StartResult:
    """One simulated start."""

    e0: np.ndarray
    converged: bool
    final_error: float          # largest position error over the last 10 % of the run (m)
    lowest_speed: float         # smallest |v| along the run (m/s)
    w_clamped: bool             # the turn-rate clamp bound at some step


@dataclass(frozen=True)
class RegionCheck:
    """Starts on the boundary of a certified set and what became of them."""

    starts: tuple[StartResult, ...]

    @property
    def converged(self) -> int:
        """How many starts converged."""
        return sum(s.converged for s in self.starts)

    @property
    def lowest_speed(self) -> float:
        """The smallest ``|v|`` over every run (m/s)."""
        return min(s.lowest_speed for s in self.starts)

    @property
    def w_clamped(self) -> int:
        """How many runs hit the turn-rate clamp."""
        return sum(s.w_clamped for s in self.starts)


def boundary_starts(S: Any, count: int, seed: int = 0) -> np.ndarray:
    """``count`` error states on ``e' S e = 1`` (random directions, reproducible).

    Parameters
    ----------
    S : array_like, shape (n, n)
        The set's matrix (``P + tau Q``).
    count : int
        Number of starts.
    seed : int
        Seed of the directions.

    Returns
    -------
    numpy.ndarray, shape (count, n)
    """
    S = np.asarray(S, float)
    d = np.random.default_rng(seed).normal(size=(count, S.shape[0]))
    out: np.ndarray = d / np.sqrt(np.einsum('ij,jk,ik->i', d, S, d))[:, None]
    return out


def reference_speeds(setup: RobotSetup, samples: int = 2000) -> tuple[float, float, float]:
    """Smallest and largest speed and largest acceleration of the reference the tracker follows.

    The delay-consistent reference (:class:`.control.simulation.tracker.Tracker`'s
    ``_compensated_reference``): velocity ``p_d' - A_tau,p xi_d(t - tau)``, feedforward
    ``p_d'' - A_tau,p xi_d'(t - tau) - A_tau,v xi_d(t - tau)``; sampled over the duration.

    Parameters
    ----------
    setup : RobotSetup
        The reference and the state delay.
    samples : int
        Sample times.

    Returns
    -------
    (float, float, float)
        ``min ||q*||``, ``max ||q*||`` (m/s), ``max ||u*||`` (m/s^2).
    """
    At = np.asarray(setup.A_tau, float)
    lo, hi, acc = math.inf, 0.0, 0.0
    for t in np.linspace(0.0, setup.duration, samples):
        r = setup.path.sample(float(t))
        z = setup.path.sample(max(float(t) - setup.tau, 0.0)) if t >= setup.tau else r
        xi = np.array(z.xi)
        dxi = np.array([z.vx, z.ax, z.vy, z.ay]) if t >= setup.tau else \
            np.array([r.vx, 0.0, r.vy, 0.0])
        d, dd = At @ xi, At @ dxi
        q = math.hypot(r.vx - d[0], r.vy - d[2])
        u = math.hypot(r.ax - dd[0] - d[1], r.ay - dd[2] - d[3])
        lo, hi, acc = min(lo, q), max(hi, q), max(acc, u)
    return lo, hi, acc


def simulate_start(K: Any, e0: Any, setup: RobotSetup, *, perturbation: Any = None,
                   tolerance: float = 1e-2) -> StartResult:
    """The nonlinear loop from the error state ``e0`` (see module text).

    Parameters
    ----------
    K : array_like, shape (2, 4)
        The gain.
    e0 : array_like, shape (4,)
        The initial error state ``[ex, evx, ey, evy]``.
    setup : RobotSetup
        The robot and tracker.
    perturbation : array_like, optional
        ``E Delta F`` added to the gain (2 x 4).
    tolerance : float
        Converged: the final position error is below ``tolerance`` times the initial error's
        size ``max(|(ex, ey)|, |(evx, evy)| x 1 s)``.

    Returns
    -------
    StartResult
    """
    e0 = np.asarray(e0, float)
    At = np.asarray(setup.A_tau, float)
    r = setup.path.sample(0.0)
    d = At @ np.array(r.xi)
    vx, vy = r.vx - d[0] + e0[1], r.vy - d[2] + e0[3]
    plant = PlantConfig(dt=setup.dt, tau=setup.tau, A_tau=tuple(map(tuple, At.tolist())),
                        x0=r.x + e0[0], y0=r.y + e0[2], th0=math.atan2(vy, vx),
                        v0=math.hypot(vx, vy), cmd_latency=setup.cmd_latency,
                        lag_v=setup.lag, lag_w=setup.lag)
    tracker = TrackerConfig(K=tuple(map(tuple, np.asarray(K, float).tolist())), dt=setup.dt,
                            max_linear_speed=setup.max_linear_speed,
                            max_angular_speed=setup.max_angular_speed,
                            min_speed=setup.min_speed, max_linear_accel=setup.max_linear_accel,
                            perturbation=None if perturbation is None else tuple(
                                map(tuple, np.asarray(perturbation, float).tolist())),
                            delay_compensation=True, A_tau=tuple(map(tuple, At.tolist())),
                            tau=setup.tau)
    steps = int(round(setup.duration / setup.dt))
    run = simulate_tracking(plant, tracker, setup.path, steps)
    err = run.error
    tail = err[-max(steps // 10, 1):]
    size = max(math.hypot(e0[0], e0[2]), math.hypot(e0[1], e0[3]) * 1.0)
    final = float(np.max(tail)) if np.all(np.isfinite(tail)) else math.inf
    w_hit = bool(np.any(np.abs(run.cmd_w) >= setup.max_angular_speed * (1 - 1e-9)))
    return StartResult(e0, final <= tolerance * size, final, float(np.min(np.abs(run.speed))),
                       w_hit)


def check_region(S: Any, K: Any, setup: RobotSetup, *, count: int = 100, seed: int = 0,
                 scale: float = 1.0, perturbation: Any = None) -> RegionCheck:
    """Simulate ``count`` starts on the boundary of ``e' S e = scale^2``.

    Parameters
    ----------
    S : array_like, shape (4, 4)
        The certified set's matrix (``P + tau Q``).
    K : array_like, shape (2, 4)
        The gain.
    setup : RobotSetup
        The robot and tracker.
    count : int
        Number of starts.
    seed : int
        Seed of the directions.
    scale : float
        Multiple of the boundary (1: on it).
    perturbation : array_like, optional
        ``E Delta F`` added to the gain.

    Returns
    -------
    RegionCheck
    """
    starts = boundary_starts(S, count, seed) * scale
    return RegionCheck(tuple(simulate_start(K, e, setup, perturbation=perturbation)
                             for e in starts))


def smallest_failing(S: Any, K: Any, setup: RobotSetup, *, directions: int = 12,
                     seed: int = 1, max_scale: float = 256.0, rtol: float = 0.1,
                     perturbation: Any = None) -> tuple[float, np.ndarray | None]:
    """The smallest multiple of the boundary at which a start fails (doubling, bisection).

    Parameters
    ----------
    S : array_like, shape (4, 4)
        The certified set's matrix.
    K : array_like, shape (2, 4)
        The gain.
    setup : RobotSetup
        The robot and tracker.
    directions : int
        Directions searched (random, reproducible).
    seed : int
        Seed of the directions.
    max_scale : float
        Largest multiple tried.
    rtol : float
        Relative width at which a bisection stops.
    perturbation : array_like, optional
        ``E Delta F`` added to the gain.

    Returns
    -------
    (float, numpy.ndarray or None)
        The smallest failing multiple found and its start (``inf``, None: none up to
        ``max_scale``).
    """
    best, best_e = math.inf, None
    for e in boundary_starts(S, directions, seed):
        lo, hi = 1.0, 2.0
        while hi <= min(max_scale, best) and simulate_start(K, hi * e, setup,
                                                            perturbation=perturbation).converged:
            lo, hi = hi, 2 * hi
        if hi > min(max_scale, best):
            continue
        while hi - lo > rtol * lo:
            mid = 0.5 * (lo + hi)
            if simulate_start(K, mid * e, setup, perturbation=perturbation).converged:
                lo = mid
            else:
                hi = mid
        if hi < best:
            best, best_e = hi, hi * e
    return best, best_e
