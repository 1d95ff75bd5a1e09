"""Batch simulation: the tracking loop (and the linear delay loop) for N cases at once.

:func:`simulate_batch` runs the lockstep sequence of :func:`control.simulation.simulate.run_loop`
with :class:`control.simulation.loop.Tracker` and
:class:`control.simulation.loop.UnicyclePlant` for ``N``
cases in parallel, every quantity a numpy array over cases, with the operations of the
scalar step functions in the same order (``exact=False`` allows a few cheaper forms of
the same values: the yaw is not sent through a quaternion, the arc's sine and cosines
come from series and angle addition, the heading's cosine and sine are carried from step
to step by angle addition and evaluated afresh every 16 steps, the metrics are taken on
the squared error).  Each step is a fixed sequence of whole-array operations on
preallocated buffers: at about 1,000 cases numpy's per-call overhead dominates, so
throughput grows with ``N``; the loop runs in the calling process (the study splits large
batches over processes, :func:`control.simulation.study.run_study`).  Case ``i`` of a batch equals
:func:`control.simulation.simulate.simulate_tracking` with :meth:`BatchCases.configs` ``(i)`` to
round-off (the test checks 1e-12; bit for bit with ``exact=True``, about 1e-14 without,
away from rest).
Per case (:class:`BatchCases`; any field left ``None`` takes the base configuration's
value):

* the gain ``K`` and its perturbation schedule ``E Delta(t) F``: ``S`` matrices, the
  one in force at a command computed at ``t`` being number ``floor(t / hold) mod S``
  (``S = 1``: constant; ``S = 2``: periodic switching; ``S`` large with random
  ``Delta``: random time-varying, see :func:`sample_deltas`);
* command latency, actuator lag and acceleration limits of ``v`` and ``w``;
* odometry latency, rate (the tracker's step is the odometry period, as the tracker
  measures it from the stamps; a ``dt`` override is used as set and warned about when it
  disagrees, as the tracker node reports it) and noise (the per-case seed draws the same
  sequence as :class:`control.simulation.sensors.Odometer`);
* initial pose and speed;
* the reference: a shared path (any object with ``sample(t) -> RefSample``, e.g. a
  :class:`control.simulation.trajectory.Trajectory`, sampled once per step) or per-case
  parameters of the analytic circle / figure eight (:class:`PathBatch`).

Shared by all cases: the plant step ``dt``, the state delay ``tau`` and ``A_tau``,
the tracker's speed limits and delay compensation.  Not vectorized (refused with
:class:`BatchError`): the tracker's latency predictor.

Per-case metrics are accumulated while running (no ``N x steps`` arrays unless
``record=True``).  :func:`simulate_delay_loop_batch` is
:func:`control.simulation.simulate.simulate_delay_loop` for ``N`` matrices ``A0`` at once.
The vectorized pieces of the single run's state (odometry, tracker, command line, plant)
are in :mod:`control.simulation.batch_parts`, the fast path for ideal odometry in
:mod:`control.simulation.batch_ideal`.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from .loop import (PlantConfig, TrackerConfig, delay_steps, odometry_period_steps, step_time,
                   step_time_ns)
from .reference import PATHS, Path
from .errors import BatchError
from .timing import period_disagreement
from .batch_parts import BLOCK, BatchPlant, BatchTracker, CommandLine, Odometry, per_value
from .batch_ideal import IdealRun, ideal_loop

__all__ = ['BatchError', 'BatchCases', 'PathBatch', 'BatchRun', 'simulate_batch',
           'perturbation_schedule', 'sample_deltas', 'simulate_delay_loop_batch',
           'segment_index']


# ---------------------------------------------------------------------------------------------
# Inputs

@dataclass(frozen=True)
class PathBatch:
    """Per-case parameters of an analytic path (:mod:`control.simulation.reference`).

    ``kind`` is ``'circle'`` or ``'figure_eight'``; each parameter is a scalar or an
    array of ``N`` values (broadcast).
    """

    kind: str = 'circle'
    radius: Any = 0.5
    rate: Any = 0.01
    center_x: Any = 0.0
    center_y: Any = 0.0
    phase: Any = 0.0

    def path(self, i: int) -> Path:
        """The single-run :class:`control.simulation.reference.Path` of case ``i``.

        Parameters
        ----------
        i : int
            Case index.

        Returns
        -------
        Path
        """
        factory = PATHS.get(self.kind)
        if factory is None:
            raise BatchError(f'path kind {self.kind!r}: choose {_KINDS}')
        return factory(**{name: float(_pick(getattr(self, name), i)) for name in _PATH_FIELDS})

    def take(self, idx: Any) -> 'PathBatch':
        """The cases ``idx`` (index array) as a new :class:`PathBatch`.

        Parameters
        ----------
        idx : array_like of int
            Indices of the cases kept (scalar parameters stay scalars).

        Returns
        -------
        PathBatch
        """
        return replace(self, **{name: _pick(getattr(self, name), idx) for name in _PATH_FIELDS})


_PATH_FIELDS = ('radius', 'rate', 'center_x', 'center_y', 'phase')
_KINDS = ' or '.join(PATHS)


def _pick(value: Any, i: Any) -> Any:
    """``value[i]`` for a per-case array, ``value`` for a scalar."""
    arr = np.asarray(value, float)
    return arr if arr.ndim == 0 else arr[i]


@dataclass(frozen=True)
class BatchCases:
    """Per-case settings; ``None`` = the base configuration's value for every case.

    Arrays have ``N`` entries (scalars broadcast).  ``perturbation`` is ``E Delta F``
    per case and segment, shape ``(N, S, 2, 4)`` (or ``(N, 2, 4)`` for constant);
    ``hold`` is the segment length (s).  ``odom_noise`` is ``(N, 3)``.
    """

    n: int
    K: Any = None
    perturbation: Any = None
    hold: float = math.inf
    x0: Any = None
    y0: Any = None
    th0: Any = None
    v0: Any = None
    cmd_latency: Any = None
    lag_v: Any = None
    lag_w: Any = None
    max_linear_accel: Any = None
    max_angular_accel: Any = None
    odom_latency: Any = None
    odom_rate: Any = None
    odom_noise: Any = None
    noise_seed: Any = None

    def take(self, idx: Any) -> 'BatchCases':
        """The cases ``idx`` (an index array or slice) as a new :class:`BatchCases`.

        Parameters
        ----------
        idx : array_like of int or slice
            The cases kept, in that order.

        Returns
        -------
        BatchCases
        """
        idx = np.arange(self.n)[idx]
        kw = {}
        for name, ndim in [(nm, 1) for nm in _PER_CASE] + [('K', 3), ('odom_noise', 2)]:
            val = getattr(self, name)
            if val is not None and np.ndim(val) == ndim:
                val = np.asarray(val)[idx]
            kw[name] = val
        if self.perturbation is not None:
            kw['perturbation'] = np.asarray(self.perturbation)[idx]
        return replace(self, n=int(idx.size), **kw)

    def configs(self, i: int, plant: PlantConfig, tracker: TrackerConfig
                ) -> tuple[PlantConfig, TrackerConfig]:
        """The single-run configurations of case ``i`` (constant perturbation only).

        Parameters
        ----------
        i : int
            Case index.
        plant, tracker : PlantConfig, TrackerConfig
            The batch's base configuration (the values of the fields left ``None``).

        Returns
        -------
        tuple of (PlantConfig, TrackerConfig)
            What :func:`control.simulation.simulate.simulate_tracking` runs for case ``i``.

        Raises
        ------
        BatchError
            If case ``i`` has a time-varying perturbation.
        """
        s = _resolve(self, plant, tracker)
        kw: dict[str, Any] = {name: float(getattr(s, name)[i]) for name in _PER_CASE
                              if name != 'noise_seed'}
        kw['odom_noise'] = tuple(float(v) for v in s.noise[i])
        kw['noise_seed'] = int(s.seed[i])
        pc = replace(plant, **kw)
        P = s.P[i]
        if P.shape[0] > 1 and np.any(P != P[0]):
            raise BatchError(f'case {i} has a time-varying perturbation; a single run has a '
                             'constant one')
        tc = replace(tracker, K=tuple(map(tuple, s.K[i].tolist())),
                     perturbation=tuple(map(tuple, P[0].tolist())))
        return pc, tc


_PER_CASE = ('x0', 'y0', 'th0', 'v0', 'cmd_latency', 'lag_v', 'lag_w', 'max_linear_accel',
             'max_angular_accel', 'odom_latency', 'odom_rate', 'noise_seed')


def _vector(value: Any, name: str, n: int, *, low: float | None = None) -> np.ndarray:
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise BatchError(f'{name}: expected numbers, got {value!r}') from None
    if arr.ndim > 1 or (arr.ndim == 1 and arr.size != n):
        raise BatchError(f'{name}: expected a number or {n} numbers (one per case), got shape '
                         f'{arr.shape}')
    arr = np.broadcast_to(arr, (n,)).copy()
    bad = ~np.isfinite(arr)
    if low is not None:
        bad |= arr < low
    if bad.any():
        i = int(np.argmax(bad))
        need = 'finite' if low is None else f'finite and >= {low:g}'
        raise BatchError(f'{name}[{i}] is {arr[i]!r}; every value must be {need}')
    return arr


@dataclass
class Settings:
    """Resolved per-case arrays of a batch, as the parts of :mod:`.batch_parts` read them.

    Internal to the batch (built by :func:`simulate_batch` from :class:`BatchCases`); a
    per-case value not named as a field is in ``vals`` (read as an attribute).
    """

    n: int
    K: np.ndarray          # (N, 2, 4)
    P: np.ndarray          # (N, S, 2, 4)
    hold_ns: int
    vals: dict[str, np.ndarray]
    noise: np.ndarray      # (N, 3)
    seed: np.ndarray       # (N,) int
    cmd_d: np.ndarray      # (N,) int steps
    odom_d: np.ndarray
    period: np.ndarray
    tdt: np.ndarray        # the tracker's step per case (its dt, else the odometry period)
    comp_n: np.ndarray     # compensation history length per case

    def __getattr__(self, name: str) -> np.ndarray:
        try:
            return self.vals[name]
        except KeyError:
            raise AttributeError(name) from None


def _resolve(cases: BatchCases, plant: PlantConfig, tracker: TrackerConfig) -> Settings:
    n = cases.n
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise BatchError(f'number of cases must be an integer >= 1, got {n!r}')
    if not plant.regular:
        raise BatchError('the batch simulation does not model latency or odometry jitter, '
                         'stalls or a latency schedule (cmd_latency_jitter, odom_jitter, stalls, '
                         'cmd_latency_schedule); '
                         'run those cases with control.simulation.simulate.run_loop')
    vals = {}
    for name in _PER_CASE:
        given = getattr(cases, name)
        low = None if name in ('x0', 'y0', 'th0', 'v0') else 0.0
        vals[name] = _vector(getattr(plant, name) if given is None else given, name, n, low=low)
    seed = vals['noise_seed']
    if np.any(seed != np.round(seed)):
        raise BatchError('noise_seed: every seed must be an integer >= 0')
    seed = seed.astype(np.int64)
    noise = np.array(plant.odom_noise if cases.odom_noise is None else cases.odom_noise,
                     dtype=float)
    if noise.shape not in ((3,), (n, 3)) or not np.all(np.isfinite(noise)) or np.any(noise < 0):
        raise BatchError('odom_noise: expected 3 standard deviations >= 0 or one row of 3 per '
                         f'case ({n} x 3), got shape {noise.shape}')
    noise = np.broadcast_to(noise, (n, 3)).copy()
    K = np.array(tracker.K if cases.K is None else cases.K, dtype=float)
    if K.shape == (2, 4):
        K = np.broadcast_to(K, (n, 2, 4))
    if K.shape != (n, 2, 4) or not np.all(np.isfinite(K)):
        raise BatchError(f'K: expected a finite 2x4 gain or {n} of them, got shape {K.shape}')
    if cases.perturbation is None:
        P = np.zeros((2, 4)) if tracker.perturbation is None else np.array(tracker.perturbation)
        P = np.broadcast_to(P, (n, 1, 2, 4))
    else:
        P = np.array(cases.perturbation, dtype=float)
        if P.ndim == 3:
            P = P[:, None]
        if P.ndim != 4 or P.shape[0] != n or P.shape[2:] != (2, 4) or P.shape[1] < 1 \
                or not np.all(np.isfinite(P)):
            raise BatchError('perturbation: expected finite E Delta F of shape (N, S, 2, 4) '
                             f'with N = {n}, got shape {P.shape}')
    hold = cases.hold
    if P.shape[1] > 1:
        if not (isinstance(hold, (int, float)) and math.isfinite(hold) and hold > 0):
            raise BatchError(f'hold: a perturbation with {P.shape[1]} segments needs a segment '
                             f'length > 0 s, got {hold!r}')
        hold_ns = int(round(hold * 1e9))
        if hold_ns < 1:
            raise BatchError(f'hold: {hold!r} s is shorter than 1 ns')
    else:
        hold_ns = 1
    dt = plant.dt
    cmd_d = per_value(lambda v: delay_steps(v, dt)[0], vals['cmd_latency'], np.int64)
    odom_d = per_value(lambda v: delay_steps(v, dt)[0], vals['odom_latency'], np.int64)
    try:
        period = per_value(lambda v: odometry_period_steps(v, dt)[0], vals['odom_rate'],
                            np.int64)
    except ValueError as exc:
        raise BatchError(f'odom_rate: {exc}') from None
    # the tracker's step: its dt override, else the odometry period of each case (the
    # interval between stamps, in whole nanoseconds as the tracker measures it)
    odom_period = per_value(lambda p: step_time(int(p), dt), period.astype(float), float)
    if tracker.dt > 0:
        tdt = np.full(n, tracker.dt)
        for p in np.unique(odom_period):
            msg = period_disagreement(tracker.dt, float(p))
            if msg is not None:
                warnings.warn(msg, UserWarning, stacklevel=3)
                break
    else:
        tdt = odom_period
    if tracker.delay_compensation:
        comp_n = per_value(lambda t: max(delay_steps(tracker.tau, t)[0], 1), tdt, np.int64)
    else:
        comp_n = np.ones(n, dtype=np.int64)
    return Settings(n, K, P, hold_ns, vals, noise, seed, cmd_d, odom_d, period, tdt, comp_n)


def perturbation_schedule(E: Any, F: Any, deltas: Any) -> np.ndarray:
    """``E Delta F`` for an array of ``Delta`` (``(..., p, q)``): shape ``(..., m, n)``.

    Parameters
    ----------
    E : array_like, (m, p)
        Left factor of the perturbation.
    F : array_like, (q, n)
        Right factor of the perturbation.
    deltas : array_like, (..., p, q)
        The uncertainties ``Delta`` (e.g. from :func:`sample_deltas`).

    Returns
    -------
    numpy.ndarray, (..., m, n)

    Raises
    ------
    BatchError
        If the shape of ``Delta`` does not match ``E`` and ``F``.
    """
    E = np.asarray(E, float)
    F = np.asarray(F, float)
    D = np.asarray(deltas, float)
    if D.shape[-2:] != (E.shape[1], F.shape[0]):
        raise BatchError(f'Delta must be {E.shape[1]}x{F.shape[0]} (E is {E.shape}, F is '
                         f'{F.shape}), got {D.shape[-2:]}')
    out: np.ndarray = np.einsum('ip,...pq,qj->...ij', E, D, F)
    return out


def sample_deltas(rng: np.random.Generator, n: int, segments: int, shape: tuple[int, int],
                  *, radius: tuple[float, float] = (0.0, 1.0)) -> np.ndarray:
    """Random ``Delta`` with spectral norm in ``radius``: shape ``(n, segments, p, q)``.

    Each matrix is a Gaussian matrix scaled to spectral norm ``r``, ``r`` uniform in
    ``radius`` (``(1, 1)``: on the boundary ``||Delta||_2 = 1``).

    Parameters
    ----------
    rng : numpy.random.Generator
        Source of the draws.
    n : int
        Number of cases.
    segments : int
        Matrices per case (the segments of a switching schedule; 1: constant).
    shape : (int, int)
        ``(p, q)``, the shape of ``Delta``.
    radius : (float, float)
        Range ``[lo, hi]`` of the spectral norms, ``0 <= lo <= hi``.

    Returns
    -------
    numpy.ndarray, (n, segments, p, q)

    Raises
    ------
    BatchError
        If ``radius`` is not a valid range.
    """
    lo, hi = (float(v) for v in radius)
    if not (0 <= lo <= hi and math.isfinite(hi)):
        raise BatchError(f'Delta norm range must satisfy 0 <= lo <= hi, got {radius!r}')
    G = rng.standard_normal((n, segments) + tuple(shape))
    norms = np.linalg.norm(G, ord=2, axis=(-2, -1))
    r = rng.uniform(lo, hi, size=(n, segments))
    out: np.ndarray = G * (r / np.maximum(norms, 1e-300))[..., None, None]
    return out


def segment_index(k: Any, dt: float, hold_ns: int, segments: int) -> Any:
    """Perturbation segment in force at step ``k``: ``floor(t_k / hold) mod segments``.

    Parameters
    ----------
    k : int or array_like of int
        Plant step(s).
    dt : float
        Plant step (s).
    hold_ns : int
        Segment length (ns).
    segments : int
        Number of segments ``S``.

    Returns
    -------
    int or numpy.ndarray
        The segment index(es), in ``0 .. S - 1``.
    """
    return (step_time_ns(k, dt) // hold_ns) % segments


class Reference:
    """Reference samples at step indices: a shared table or per-case analytic formulas.

    Internal to the batch (its loops and :mod:`control.simulation.batch_ideal`).

    Parameters
    ----------
    path : Path-like or PathBatch
        Shared reference (``sample(t)``, sampled once per step) or per-case parameters.
    n : int
        Number of cases.
    steps : int
        Plant steps of the run.
    dt : float
        Plant step (s).
    """

    def __init__(self, path: Any, n: int, steps: int, dt: float):
        self.n = n
        self.dt_ns = int(round(dt * 1e9))
        if isinstance(path, PathBatch) and all(np.ndim(getattr(path, f)) == 0
                                               for f in _PATH_FIELDS):
            path = path.path(0)             # the same path for every case: one table
        if isinstance(path, PathBatch):
            if path.kind not in PATHS:
                raise BatchError(f'path kind {path.kind!r}: choose {_KINDS}')
            self.table = None
            self.kind = path.kind
            self.r = _vector(path.radius, 'radius', n)
            if np.any(self.r <= 0):
                raise BatchError('radius: every radius must be > 0 m')
            self.w = _vector(path.rate, 'rate', n)
            self.cx = _vector(path.center_x, 'center_x', n)
            self.cy = _vector(path.center_y, 'center_y', n)
            self.ph = _vector(path.phase, 'phase', n)
        else:
            if not callable(getattr(path, 'sample', None)):
                raise BatchError(f'path must have sample(t) or be a PathBatch, got {path!r}')
            rows = [path.sample(step_time_ns(k, dt) * 1e-9) for k in range(steps + 1)]
            tab = np.array([(s.x, s.y, s.vx, s.vy, s.ax, s.ay) for s in rows], dtype=float)
            # (steps + 1, 2, 1) each: position, velocity, acceleration as column pairs
            self.table = tuple(tab[:, j:j + 2, None].copy() for j in (0, 2, 4))
            self.rows = list(zip(*self.table))      # (position, velocity, acceleration)

    def at(self, k: Any) -> tuple[Any, Any, Any]:
        """Position, velocity, acceleration ``(2, 1)`` (shared) or ``(2, N)`` at step ``k``.

        Parameters
        ----------
        k : int or numpy.ndarray
            The step, or an array of N steps (per-case odometry stamps).

        Returns
        -------
        tuple
            Position, velocity and acceleration.
        """
        if self.table is not None:
            if np.ndim(k) == 0:
                row: tuple[Any, Any, Any] = self.rows[k]
                return row
            return tuple(col[k][:, :, 0].T for col in self.table)
        t = (np.asarray(k, dtype=np.int64) * self.dt_ns) * 1e-9
        r, w, cx, cy = self.r, self.w, self.cx, self.cy
        a = w * t + self.ph
        if self.kind == 'circle':
            c, s = np.cos(a), np.sin(a)
            return (np.stack((cx + r * c, cy + r * s)), np.stack((-r * w * s, r * w * c)),
                    np.stack((-r * w * w * c, -r * w * w * s)))
        s1, c1 = np.sin(a), np.cos(a)
        s2, c2 = np.sin(2 * a), np.cos(2 * a)
        return (np.stack((cx + r * s1, cy + 0.5 * r * s2)), np.stack((r * w * c1, r * w * c2)),
                np.stack((-r * w * w * s1, -2 * r * w * w * s2)))


# ---------------------------------------------------------------------------------------------
# Result

@dataclass(frozen=True)
class BatchRun:
    """Per-case results of :func:`simulate_batch` (arrays of N; SI units).

    Metrics follow :func:`control.simulation.metrics.tracking_metrics` on the position error
    sampled at every step: ``settling_time`` (nan: not within ``tolerance`` at the end),
    ``first_within``, ``final_error``, ``rms_error``, ``steady_error`` (max error over
    ``t >= steady_from``), ``peak_abs_v``/``peak_abs_w`` (commands), ``finite`` (False if
    the state became non-finite).  With ``record=True``, ``trace`` holds ``(steps + 1, N)``
    arrays ``t, x, y, th, speed, xd, yd, cmd_v, cmd_w, commanded`` (rows as
    :class:`control.simulation.simulate.TrackingRun`).
    """

    steps: int
    dt: float
    tolerance: float
    steady_from: float
    settling_time: np.ndarray
    first_within: np.ndarray
    final_error: np.ndarray
    rms_error: np.ndarray
    steady_error: np.ndarray
    peak_abs_v: np.ndarray
    peak_abs_w: np.ndarray
    finite: np.ndarray
    trace: dict[str, np.ndarray] | None = None

    @property
    def n(self) -> int:
        """Number of cases."""
        return int(self.final_error.size)


# ---------------------------------------------------------------------------------------------
# The loop

def simulate_batch(plant: PlantConfig, tracker: TrackerConfig, path: Any, steps: int,
                   cases: BatchCases | None = None, *, tolerance: float = 0.01,
                   steady_from: float | None = None, record: bool = False,
                   exact: bool = True) -> BatchRun:
    """Run the tracking loop for every case of ``cases`` for ``steps`` plant steps.

    Parameters
    ----------
    plant, tracker : PlantConfig, TrackerConfig
        Base configuration (shared settings and defaults of every per-case field).
    path : Path-like or PathBatch
        Shared reference (``sample(t)``) or per-case analytic path parameters.
    steps : int
        Plant steps (``steps + 1`` samples, as
        :func:`control.simulation.simulate.simulate_tracking`).
    cases : BatchCases, optional
        Per-case settings (default: one case, the base configuration).
    tolerance : float
        Error tolerance (m) of the settling time.
    steady_from : float, optional
        Start (s) of the window of ``steady_error`` (default: half the run).
    record : bool
        Keep the full per-step arrays (memory ``~ 80 N steps`` bytes).
    exact : bool
        True (default): every transcendental function evaluated as the single run does
        (the yaw through a quaternion with libm's ``atan2`` element by element, the arc's
        sine and cosines); a case equals :func:`control.simulation.simulate.simulate_tracking` bit
        for bit in every configuration tested.  False: cheaper forms of the same values
        (about 3 x faster; numpy's own ``arctan2`` already differs from libm's by an ulp
        for some arguments), for statistics over many cases; their
        round-off differences grow by up to ``1 / min_speed`` where the speed is near 0
        (a robot coming to rest at a trajectory's end: about 2e-12; elsewhere 1e-13).

    Returns
    -------
    BatchRun

    Raises
    ------
    BatchError
        A bad per-case value, or a feature that is not vectorized (the predictor, the
        tracker's command rate limit).

    Notes
    -----
    The run is set up from parts that each hold one piece of the single run's state for
    every case (``Odometry``, ``BatchTracker``, ``CommandLine``,
    ``BatchPlant`` of :mod:`control.simulation.batch_parts`, ``Metrics``) and stepped by
    ``_loop``; the common
    configuration of odometry of the plant's own state, no delay compensation and no
    actuator dynamics (without ``exact``) takes the specialised ``ideal_loop``
    (:mod:`control.simulation.batch_ideal`).
    """
    _check_run(tracker, steps, tolerance)
    steps = int(steps)
    cases = BatchCases(1) if cases is None else cases
    s = _resolve(cases, plant, tracker)
    metrics = Metrics(s.n, steps, plant.dt, tolerance, steady_from, exact)
    ref = Reference(path, s.n, steps, plant.dt)
    odom = Odometry(s)
    body = BatchPlant(plant, s, exact, odom.ideal, tracker.max_angular_speed)
    schedule = Schedule(s.K, s.P, s.hold_ns, plant.dt)
    tdt = float(s.tdt[0]) if np.all(s.tdt == s.tdt[0]) else s.tdt   # a scalar when shared
    trace = {name: np.zeros((steps + 1, s.n)) for name in _TRACE} if record else None
    # odometry of the plant's own state every step, no compensation, no actuator dynamics,
    # no or the paper's delay form: fewer operations per step (ideal_loop)
    delay = body.delay
    ideal = (body.recur and not tracker.delay_compensation and not body.act.on
             and isinstance(tdt, float) and (not delay.on or (delay.diag and delay.Nd > 0)))
    with np.errstate(all='ignore'):
        if ideal:
            run = IdealRun(steps, plant.dt, float(tdt), ref, schedule,
                            (tracker.max_linear_speed, tracker.max_angular_speed,
                             tracker.min_speed),
                            (delay.Nd, delay.ax, delay.ay) if delay.on else None,
                            s.cmd_d if np.any(s.cmd_d) else None, tracker.dt == 0)
            pos, th, err = ideal_loop(run, body.pos, body.th, body.pv, metrics, trace)
            finite = np.isfinite(pos[0]) & np.isfinite(pos[1]) & np.isfinite(th)
        else:
            trk = BatchTracker(s, tracker, schedule, tdt, metrics.cblk, exact, body.recur,
                                odom.ideal)
            line = CommandLine(s.cmd_d, s.v0, bool(np.any(s.cmd_d) and odom.ideal))
            err, finite = _loop(_Parts(ref, odom, trk, line, body, metrics), steps, trace)
    return metrics.result(err, finite, trace)


def _check_run(tracker: TrackerConfig, steps: Any, tolerance: Any) -> None:
    """Refuse what the batch does not vectorize and bad run lengths or tolerances."""
    if tracker.predicts:
        raise BatchError('the batch simulation does not vectorize the latency predictor '
                         '(predict_latency, predict_odom_latency, predict_lag_v, predict_lag_w); '
                         'set them to 0 or use simulate_tracking for single runs')
    if tracker.rate_limited:
        raise BatchError('the batch simulation does not vectorize the tracker\'s command rate '
                         'limit (max_linear_accel, max_angular_accel of the tracker; the '
                         'plant\'s limits are simulated); set them to 0 or use '
                         'simulate_tracking for single runs')
    if isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or steps < 1:
        raise BatchError(f'steps must be an integer >= 1, got {steps!r}')
    if not (isinstance(tolerance, (int, float)) and math.isfinite(tolerance) and tolerance > 0):
        raise BatchError(f'tolerance must be a finite number > 0 m, got {tolerance!r}')


#: The per-step arrays of ``BatchRun.trace`` (rows as
#: :class:`control.simulation.simulate.TrackingRun`).
_TRACE = ('t', 'x', 'y', 'th', 'speed', 'xd', 'yd', 'cmd_v', 'cmd_w', 'commanded')


@dataclass(frozen=True)
class _Parts:
    """The state of a batch run, one part per piece of the single run (see :func:`_loop`)."""

    ref: Reference
    odometry: Odometry
    tracker: BatchTracker
    commands: CommandLine
    plant: BatchPlant
    metrics: Metrics


def _loop(parts: _Parts, steps: int, trace: dict[str, np.ndarray] | None
          ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`simulate_batch`'s general loop; the last error row and which cases stayed finite.

    Every step in the order of :func:`control.simulation.simulate.run_loop`: the odometry due, the
    tracker's command (cases whose odometry is due), the command sent into the plant's
    command line, the log row and metrics, then the plant's advance with the command in
    force and the next measurement.
    """
    ref, odom, trk, line = parts.ref, parts.odometry, parts.tracker, parts.commands
    plant, metrics = parts.plant, parts.metrics
    dt = plant.dt
    reuse_error = odom.ideal and not trk.comp       # tracker's position error = logged one
    ref_rows = ref.rows if ref.table is not None else None
    if not odom.ideal:
        odom.measure(0, plant.pos, plant.th, plant.pv)
    err = np.zeros(trk.n)
    for k in range(steps + 1):
        j = k % BLOCK
        rpos, rvel, racc = ref_rows[k] if ref_rows is not None else ref.at(k)
        # ---- odometry due at k
        if odom.ideal:
            due: bool | np.ndarray = True
            mpos, mth, mv = plant.pos, plant.th, plant.pv
            mstep: int | np.ndarray = k
        else:
            due, mpos, mth, mv, mstep = odom.read(k)
        if due is not False:
            if odom.ideal or (np.ndim(mstep) == 0 and mstep == k):
                q = (rpos, rvel, racc)
            else:
                q = ref.at(mstep)
            line.send(k, trk.command(k, j, due, mpos, mth, mv, q), due)
        # ---- log row k and metrics (err: the error, or its square without exact)
        err = metrics.error(j, trk.epos if reuse_error else plant.pos - rpos)
        if not odom.ideal:
            metrics.cblk[j] = 0.0 if due is False else trk.cmd_log
        if j == BLOCK - 1 or k == steps:
            metrics.flush(k - j, j + 1)
        if trace is not None:
            commanded = 0.0 if due is False else (1.0 if due is True else due)
            row = (step_time_ns(k, dt) * 1e-9, plant.pos[0], plant.pos[1], plant.th, plant.pv,
                   rpos[0], rpos[1], trk.cmd_log[0], trk.cmd_log[1], commanded)
            for name, val in zip(_TRACE, row):
                trace[name][k] = val
        if k == steps:
            break
        v, w = line.in_force(k)
        plant.advance(k, v, w, trk.cs)
        if not odom.ideal:
            odom.measure(k + 1, plant.pos, plant.th, plant.pv)
    pos, th = plant.pos, plant.th
    return err, np.isfinite(pos[0]) & np.isfinite(pos[1]) & np.isfinite(th)


@dataclass(frozen=True)
class Schedule:
    """Per-case gains ``K`` (N, 2, 4) and perturbations ``P`` (N, S, 2, 4) by segment.

    Internal to the batch: the gain in force at each step, for its loops and
    :class:`control.simulation.batch_parts.BatchTracker`.
    """

    K: np.ndarray
    P: np.ndarray
    hold_ns: int
    dt: float

    @property
    def segments(self) -> int:
        """Number of perturbation segments ``S``."""
        return int(self.P.shape[1])

    def segment(self, k: int) -> int:
        """The segment in force at step ``k`` (:func:`segment_index`).

        Parameters
        ----------
        k : int
            Plant step.

        Returns
        -------
        int
        """
        S = self.P.shape[1]
        return segment_index(k, self.dt, self.hold_ns, S) if S > 1 else 0

    def gain(self, seg: int) -> np.ndarray:
        """``K + P[:, seg]`` of every case as one contiguous ``(2, 4, N)`` array.

        Parameters
        ----------
        seg : int
            Segment index.

        Returns
        -------
        numpy.ndarray
        """
        return np.ascontiguousarray((self.K + self.P[:, seg]).transpose(1, 2, 0))


class Metrics:
    """Per-case metrics updated from blocks of per-step rows (see :func:`simulate_batch`).

    Without ``exact`` on the squared error (square roots at the end).  The error and the
    command of each step are written to a row of a block of ``BLOCK`` steps (``eblk``,
    ``cblk``), whose rows are reduced at once when it is full (:meth:`flush`).  Internal
    to the batch (its loops and :mod:`control.simulation.batch_ideal`).

    Parameters
    ----------
    n, steps : int
        Cases and plant steps of the run.
    dt : float
        Plant step (s).
    tolerance : float
        Error tolerance (m) of the settling time.
    steady_from : float or None
        Start (s) of the window of the steady error (None: half the run).
    exact : bool
        The error itself (else its square, square roots at the end).
    """

    def __init__(self, n: int, steps: int, dt: float, tolerance: float,
                 steady_from: float | None, exact: bool):
        self.steps, self.dt, self.tolerance, self.exact = steps, dt, tolerance, exact
        self.dt_ns = dt_ns = int(round(dt * 1e9))
        t_end = steps * dt_ns * 1e-9
        self.steady_from = 0.5 * t_end if steady_from is None else float(steady_from)
        self.thr = tolerance if exact else tolerance * tolerance
        self.last_out = np.full(n, -1, dtype=np.int64)
        self.first_in = np.full(n, -1, dtype=np.int64)
        self.sqblk = np.zeros((BLOCK + 1, n))      # row 0: the sum of squares so far
        self.eblk = np.empty((BLOCK, n)) if exact else self.sqblk[1:]
        self.cblk = np.zeros((BLOCK, 2, n))        # commands sent (0: none)
        self.steady = np.zeros(n)
        steady_k = max(0, int(self.steady_from / (dt_ns * 1e-9)) - 2)   # first k: t_k >= from
        while steady_k <= steps and step_time_ns(steady_k, dt) * 1e-9 < self.steady_from:
            steady_k += 1
        self.steady_k = steady_k
        self.peak = np.zeros((2, n))
        self.searching = True
        self.cabs = np.empty_like(self.cblk)
        self.sums = np.empty_like(self.steady)
        self.out = np.empty(self.eblk.shape, dtype=bool)
        self.sq = np.empty((2, n))

    def error(self, j: int, dp: np.ndarray) -> np.ndarray:
        """Row ``j`` of the block: the position error ``|dp|`` (its square without exact).

        Parameters
        ----------
        j : int
            Row of the block.
        dp : numpy.ndarray
            Position error (2, N).

        Returns
        -------
        numpy.ndarray
            The row (written in place).
        """
        err: np.ndarray = self.eblk[j]
        if self.exact:
            np.hypot(dp[0], dp[1], out=err)
            np.multiply(err, err, out=self.sqblk[j + 1])
        else:
            np.multiply(dp, dp, out=self.sq)
            np.add(self.sq[0], self.sq[1], out=err)
        return err

    def flush(self, k0: int, m: int) -> None:
        """Take the first ``m`` rows, those of steps ``k0 .. k0 + m - 1``.

        Every update equals the step-by-step one: the sum of squares adds the rows in
        order after the running sum (a reduction over the first axis adds row by row), the
        others are maxima and first/last indices.

        Parameters
        ----------
        k0 : int
            Step of the first row.
        m : int
            Number of rows.
        """
        rows = self.eblk[:m]
        np.add.reduce(self.sqblk[:m + 1], axis=0, out=self.sums)
        self.sqblk[0] = self.sums
        out = np.greater(rows, self.thr, out=self.out[:m])   # nan: never back within
        hit = np.logical_or.reduce(out, axis=0)
        if hit.any():
            last = (k0 + m - 1) - np.argmax(out[::-1], axis=0)
            np.copyto(self.last_out, last, where=hit)
        if self.searching:
            inside = ~out
            fin = (self.first_in < 0) & inside.any(axis=0)
            if fin.any():
                np.copyto(self.first_in, k0 + np.argmax(inside, axis=0), where=fin)
            self.searching = bool((self.first_in < 0).any())
        if k0 + m - 1 >= self.steady_k:
            lo = max(0, self.steady_k - k0)
            np.fmax(self.steady, np.fmax.reduce(rows[lo:], axis=0), out=self.steady)
        cabs = np.abs(self.cblk[:m], out=self.cabs[:m])
        np.fmax(self.peak, np.fmax.reduce(cabs, axis=0), out=self.peak)

    def result(self, err: np.ndarray, finite: np.ndarray,
               trace: dict[str, np.ndarray] | None) -> BatchRun:
        """The :class:`BatchRun` of the run whose last error row is ``err``.

        Parameters
        ----------
        err : numpy.ndarray
            The last error row.
        finite : numpy.ndarray
            Which cases stayed finite.
        trace : dict or None
            The per-step arrays (``record=True``).

        Returns
        -------
        BatchRun
        """
        steady = self.steady
        if not self.exact:
            err = np.sqrt(err)
            steady = np.sqrt(steady)
        dt_ns = self.dt_ns
        last_out, first_in = self.last_out, self.first_in
        within_end = err <= self.tolerance
        settle = np.where(within_end, ((last_out + 1) * dt_ns) * 1e-9, np.nan)
        first = np.where(first_in >= 0, (first_in * dt_ns) * 1e-9, np.nan)
        steady = np.where(finite, steady, np.nan)
        return BatchRun(steps=self.steps, dt=self.dt, tolerance=float(self.tolerance),
                        steady_from=self.steady_from, settling_time=settle,
                        first_within=first, final_error=err.copy(),
                        rms_error=np.sqrt(self.sqblk[0] / (self.steps + 1)),
                        steady_error=steady, peak_abs_v=self.peak[0].copy(),
                        peak_abs_w=self.peak[1].copy(), finite=finite, trace=trace)


# ---------------------------------------------------------------------------------------------
# Linear delay loop

def simulate_delay_loop_batch(A0: Any, A1: Any, tau: float, xi0: Any, duration: float,
                              dt: float = 1e-3) -> tuple[np.ndarray, np.ndarray]:
    """:func:`control.simulation.simulate.simulate_delay_loop` for N loops at once.

    The history before time 0 is constant.

    Parameters
    ----------
    A0 : array_like, (N, n, n) or (n, n)
        Delay-free matrices (e.g. ``A + B (K + E Delta_i F)``).
    A1 : array_like, (N, n, n) or (n, n)
        Delayed-state matrices.
    tau : float
        Delay (s), a multiple of ``dt``.
    xi0 : array_like, (N, n) or (n,)
        Initial states (the history before 0 is constant).
    duration, dt : float
        Length and RK4 step (s).

    Returns
    -------
    t : numpy.ndarray, (steps + 1,)
    xi : numpy.ndarray, (steps + 1, N, n)
    """
    from .simulate import rk4_delay_steps, steps_for_duration
    A0 = np.asarray(A0, float)
    A1 = np.asarray(A1, float)
    xi0 = np.asarray(xi0, float)
    N = max(A0.shape[0] if A0.ndim == 3 else 1, A1.shape[0] if A1.ndim == 3 else 1,
            xi0.shape[0] if xi0.ndim == 2 else 1)
    n = A0.shape[-1]
    try:
        A0 = np.broadcast_to(A0, (N, n, n))
        A1 = np.broadcast_to(A1, (N, n, n))
        xi0 = np.broadcast_to(xi0, (N, n))
    except ValueError:
        raise BatchError(f'shapes do not match: A0 {A0.shape}, A1 {A1.shape}, '
                         f'xi0 {xi0.shape}') from None
    if not (np.all(np.isfinite(A0)) and np.all(np.isfinite(A1)) and np.all(np.isfinite(xi0))):
        raise BatchError('A0, A1 and xi0 must be finite')
    Nd = int(round(tau / dt))
    if abs(Nd * dt - tau) > 1e-9 * max(1.0, tau):
        raise BatchError(f'tau = {tau} s is not a multiple of dt = {dt} s')
    steps = steps_for_duration(duration, dt)
    if Nd == 0:
        A0, A1 = A0 + A1, np.zeros_like(A1)
    out = np.zeros((Nd + steps + 1, N, n))
    out[:Nd + 1] = xi0

    def f(x: np.ndarray, xd: np.ndarray) -> Any:
        return np.einsum('kij,kj->ki', A0, x) + np.einsum('kij,kj->ki', A1, xd)

    rk4_delay_steps(out, Nd, steps, dt, f)
    return np.arange(steps + 1) * dt, out[Nd:].copy()
