"""Batch simulation: the tracking loop (and the linear delay loop) for N cases at once.

:func:`simulate_batch` runs the lockstep sequence of the single run
(:func:`~nonfragile_tracker.control.simulation.simulate.simulate_tracking`) for ``N`` cases
(:class:`BatchCases`: gains and perturbation schedules, latency, lag, limits, odometry,
initial state, the reference) in parallel, every quantity a numpy array over cases; case
``i`` equals the single run to round-off (bit for bit with ``exact=True``).
:func:`simulate_delay_loop_batch` does the same for the linear delay loop.  Each piece is the
vector twin beside its scalar step (``VectorTracker`` in :mod:`~.simulation.tracker`,
``VectorPlant`` in :mod:`~.simulation.plant`, ``VectorOdometer``, ``VectorCommandLine``,
``VectorActuator``): one loop.

See doc/study.md, section "The batch simulation" (what is per case and shared, agreement
with the single run, the loop and its speed).
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from .plant import PlantConfig, delay_steps, odometry_period_steps
from .tracker import TrackerConfig
from .timing import step_time, step_time_ns
from .errors import BatchError
from .timing import period_disagreement
from .batch_data import (BLOCK, BatchRun, Metrics, PathBatch, Reference, Schedule, Settings,
                         per_case_vector, segment_index)
from .batch_data import per_value
from .command_line import VectorCommandLine
from .plant import VectorPlant
from .tracker import VectorTracker
from .sensors import VectorOdometer

__all__ = ['BatchError', 'BatchCases', 'PathBatch', 'BatchRun', 'simulate_batch',
           'perturbation_schedule', 'sample_deltas', 'simulate_delay_loop_batch',
           'segment_index']


# ---------------------------------------------------------------------------------------------
# Inputs


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
            What :func:`.control.simulation.simulate.simulate_tracking` runs for case ``i``.

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
        vals[name] = per_case_vector(getattr(plant, name) if given is None else given, name, n,
                                     low=low)
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


# ---------------------------------------------------------------------------------------------
# Result


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
        :func:`.control.simulation.simulate.simulate_tracking`).
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
        sine and cosines); a case equals :func:`.control.simulation.simulate.simulate_tracking` bit
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
    every case (the vector twins ``VectorOdometer``, ``VectorTracker``, ``VectorCommandLine``,
    ``VectorPlant`` beside their scalar steps, and ``Metrics``) and stepped by
    ``_loop``; for odometry of the plant's own state without actuator dynamics (and
    without ``exact``) the plant takes fewer operations a step (``VectorPlant``).
    """
    _check_run(tracker, steps, tolerance)
    steps = int(steps)
    cases = BatchCases(1) if cases is None else cases
    s = _resolve(cases, plant, tracker)
    metrics = Metrics(s.n, steps, plant.dt, tolerance, steady_from, exact)
    ref = Reference(path, s.n, steps, plant.dt)
    odom = VectorOdometer(s)
    body = VectorPlant(plant, s, exact, odom.ideal, tracker.max_angular_speed)
    schedule = Schedule(s.K, s.P, s.hold_ns, plant.dt)
    tdt = float(s.tdt[0]) if np.all(s.tdt == s.tdt[0]) else s.tdt   # a scalar when shared
    trace = {name: np.zeros((steps + 1, s.n)) for name in _TRACE} if record else None
    with np.errstate(all='ignore'):
        trk = VectorTracker(s, tracker, schedule, tdt, metrics.cblk, exact, body.recur,
                            odom.ideal)
        line = VectorCommandLine(s.cmd_d, s.v0, bool(np.any(s.cmd_d) and odom.ideal))
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
    if tracker.compensates:
        raise BatchError('the batch simulation does not vectorize the tracker\'s gain '
                         'compensation (gain_v, gain_w); set them to 1 or use '
                         'simulate_tracking for single runs')
    if tracker.slides:
        raise BatchError('the batch simulation does not vectorize the tracker\'s side-slip '
                         'correction (side_slip_rates, side_slip); leave them empty or use '
                         'simulate_tracking for single runs')
    if isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or steps < 1:
        raise BatchError(f'steps must be an integer >= 1, got {steps!r}')
    if not (isinstance(tolerance, (int, float)) and math.isfinite(tolerance) and tolerance > 0):
        raise BatchError(f'tolerance must be a finite number > 0 m, got {tolerance!r}')


#: The per-step arrays of ``BatchRun.trace`` (rows as
#: :class:`.control.simulation.simulate.TrackingRun`).
_TRACE = ('t', 'x', 'y', 'th', 'speed', 'xd', 'yd', 'cmd_v', 'cmd_w', 'commanded')


@dataclass(frozen=True)
class _Parts:
    """The state of a batch run, one part per piece of the single run (see :func:`_loop`)."""

    ref: Reference
    odometry: VectorOdometer
    tracker: VectorTracker
    commands: VectorCommandLine
    plant: VectorPlant
    metrics: Metrics


def _loop(parts: _Parts, steps: int, trace: dict[str, np.ndarray] | None
          ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`simulate_batch`'s general loop; the last error row and which cases stayed finite.

    Every step in the order of :func:`.control.simulation.simulate.run_loop`: the odometry due, the
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


# ---------------------------------------------------------------------------------------------
# Linear delay loop

def simulate_delay_loop_batch(A0: Any, A1: Any, tau: float, xi0: Any, duration: float,
                              dt: float = 1e-3) -> tuple[np.ndarray, np.ndarray]:
    """:func:`.control.simulation.simulate.simulate_delay_loop` for N loops at once.

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
