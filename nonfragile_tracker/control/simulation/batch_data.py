"""The batch's data: paths, settings, gain schedule, reference, metrics and result.

Per-case paths, the resolved settings, the gain schedule, the reference, the metrics and the
result of :func:`.simulate_batch`.

What the batch's loop (:mod:`.batch`) and the vector twins of the single run's steps (in
:mod:`~.simulation.tracker`, :mod:`~.simulation.plant`, :mod:`.sensors`) read and write, in
one module below them all, so none of them imports another for its types.  See doc/study.md
for what a batch computes.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any, Callable

import numpy as np

from .errors import BatchError
from .timing import step_time_ns
from .reference import PATHS, Path

__all__ = ['PathBatch', 'Settings', 'segment_index', 'Reference', 'BatchRun', 'Schedule',
           'Metrics', 'per_case_vector', 'BLOCK', 'per_value']

#: Steps per block of the metrics' rows (the loops write a row per step, reduce per block).
BLOCK = 16


@dataclass(frozen=True)
class PathBatch:
    """Per-case parameters of an analytic path (:mod:`.control.simulation.reference`).

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
        """The single-run :class:`.control.simulation.reference.Path` of case ``i``.

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


def per_case_vector(value: Any, name: str, n: int, *, low: float | None = None
                    ) -> np.ndarray:
    """``value`` as ``n`` finite numbers, one per case (a scalar broadcasts).

    Parameters
    ----------
    value : float or array_like
        A number or ``n`` numbers.
    name : str
        The setting's name, for the error message.
    n : int
        Number of cases.
    low : float, optional
        Smallest value allowed.

    Returns
    -------
    numpy.ndarray

    Raises
    ------
    BatchError
        If the values are not numbers, not ``n`` of them, not finite or below ``low``.
    """
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
    """Resolved per-case arrays of a batch, as the vector twins read them.

    Internal to the batch (built by :func:`~.batch.simulate_batch` from
    :class:`~.batch.BatchCases`); a
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

    Internal to the batch (its loop and the vector twins).

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
            self.r = per_case_vector(path.radius, 'radius', n)
            if np.any(self.r <= 0):
                raise BatchError('radius: every radius must be > 0 m')
            self.w = per_case_vector(path.rate, 'rate', n)
            self.cx = per_case_vector(path.center_x, 'center_x', n)
            self.cy = per_case_vector(path.center_y, 'center_y', n)
            self.ph = per_case_vector(path.phase, 'phase', n)
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


@dataclass(frozen=True)
class BatchRun:
    """Per-case results of :func:`~.batch.simulate_batch` (arrays of N; SI units).

    Metrics follow :func:`.control.simulation.metrics.tracking_metrics` on the position error
    sampled at every step: ``settling_time`` (nan: not within ``tolerance`` at the end),
    ``first_within``, ``final_error``, ``rms_error``, ``steady_error`` (max error over
    ``t >= steady_from``), ``peak_abs_v``/``peak_abs_w`` (commands), ``finite`` (False if
    the state became non-finite).  With ``record=True``, ``trace`` holds ``(steps + 1, N)``
    arrays ``t, x, y, th, speed, xd, yd, cmd_v, cmd_w, commanded`` (rows as
    :class:`.control.simulation.simulate.TrackingRun`).
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


@dataclass(frozen=True)
class Schedule:
    """Per-case gains ``K`` (N, 2, 4) and perturbations ``P`` (N, S, 2, 4) by segment.

    Internal to the batch: the gain in force at each step, for its loops and
    :class:`.control.simulation.tracker.VectorTracker`.
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
    """Per-case metrics updated from blocks of per-step rows (see :func:`~.batch.simulate_batch`).

    Without ``exact`` on the squared error (square roots at the end).  The error and the
    command of each step are written to a row of a block of ``BLOCK`` steps (``eblk``,
    ``cblk``), whose rows are reduced at once when it is full (:meth:`flush`).  Internal
    to the batch (its loop and the vector twins).

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
# Per-case values

def per_value(fn: Callable[[float], Any], values: np.ndarray, dtype: Any) -> np.ndarray:
    """``[fn(v) for v in values]`` evaluated once per distinct value (scalar functions).

    Parameters
    ----------
    fn : callable
        A function of one float.
    values : numpy.ndarray
        The values, one per case.
    dtype : numpy dtype
        Type of the result.

    Returns
    -------
    numpy.ndarray
    """
    uniq, inv = np.unique(values, return_inverse=True)
    return np.array([fn(float(v)) for v in uniq], dtype=dtype)[inv.reshape(-1)]
