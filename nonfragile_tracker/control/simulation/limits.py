"""Trajectories within a robot's limits: check, margins and time-optimal re-timing.

A base has limits on its speed ``|v|``, its linear acceleration ``|v'|``, its turn rate
``|w|``, its angular acceleration ``|w'|`` and, car-like, its curvature ``|w / v| <=
1 / min_turning_radius`` (a bicycle model steered by ``delta``: ``w = v tan(delta) / L``,
so ``min_turning_radius = L / tan(delta_max)``; De Luca, Oriolo and Samson, LNCIS 229).
A value of 0 means *unknown / none*: not checked.

:func:`check` samples a bounded trajectory and returns, per limit, the peak, its time and
place, the margin and the first violation.  :func:`retime` gives a trajectory along the
same path whose timing satisfies the limits: the time-optimal parameterization ``s(t)``
along the arc length under the limits and under the planner's own speed at each place
(it never drives faster than the plan, it only slows down where the plan is too fast for
the base).  The method is TOPP-RA (Pham and Pham, IEEE T-RO 2018): with ``x = s'^2`` and
``u = s''`` on an arc-length grid every limit is linear in ``(x, u)``; a backward pass
computes the controllable sets of ``x``, a forward pass takes the largest admissible
``u``, and the result is sampled into the quintic Hermite form
(:func:`control.simulation.trajectory.from_states`).  The rows, the passes and why not the
``toppra`` package are in the documentation: doc/theory.md, section "Re-timing within
limits" (#topp-ra).
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

from .trajectory import Trajectory, from_states
from .errors import TrajectoryError

__all__ = ['Limits', 'LimitReport', 'LimitCheck', 'Retimed', 'check', 'retime',
           'LIMIT_NAMES', 'MOVING_SPEED', 'WINDOW', 'refuse_tight_turns']

#: Below this speed (m/s) a trajectory is at rest: no heading rate, no curvature.
MOVING_SPEED = 1e-3
#: Below this speed (m/s) the curvature is not checked (a spline's end into rest curls
#: over millimetres; the turning-radius check is about the path driven).
CURVATURE_SPEED = 0.01
#: Most samples of a check (a long trajectory is sampled coarser; its knots always).
MAX_SAMPLES = 100_000
#: Window (s) of the acceleration checks: one command period of a 50 Hz base.
WINDOW = 0.02
#: Relative excess of a limit allowed after re-timing (the knots' interpolation).
TOLERANCE = 0.01
#: Most TOPP-RA passes of :func:`retime` (each tightens the rows still exceeded).
ITERATIONS = 4
#: Names of the limits, as the tracker's parameters spell them.
LIMIT_NAMES = ('max_linear_speed', 'max_linear_accel', 'max_angular_speed',
               'max_angular_accel', 'min_turning_radius')
_UNITS = {'max_linear_speed': 'm/s', 'max_linear_accel': 'm/s^2',
          'max_angular_speed': 'rad/s', 'max_angular_accel': 'rad/s^2',
          'min_turning_radius': 'm'}
_QUANTITY = {'max_linear_speed': 'speed', 'max_linear_accel': 'linear acceleration',
             'max_angular_speed': 'turn rate', 'max_angular_accel': 'angular acceleration',
             'min_turning_radius': 'turning radius'}


@dataclass(frozen=True)
class Limits:
    """A base's limits (SI units); 0 = unknown or none (not checked).

    Parameters
    ----------
    max_linear_speed, max_linear_accel, max_angular_speed, max_angular_accel : float
        ``|v|`` (m/s), ``|v'|`` (m/s^2), ``|w|`` (rad/s), ``|w'|`` (rad/s^2).
    min_turning_radius : float
        Smallest radius the base can turn on (m; car-like bases), 0 = turns on the spot.
    """

    max_linear_speed: float = 0.0
    max_linear_accel: float = 0.0
    max_angular_speed: float = 0.0
    max_angular_accel: float = 0.0
    min_turning_radius: float = 0.0

    def __post_init__(self) -> None:
        for name in LIMIT_NAMES:
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or \
                    not math.isfinite(v) or v < 0:
                raise TrajectoryError(f'limit {name} must be a finite number >= 0 '
                                      f'({_UNITS[name]}; 0 = none), got {v!r}')

    @classmethod
    def from_values(cls, values: Mapping[str, Any]) -> 'Limits':
        """The limits among a parameter dict (missing names: 0).

        Parameters
        ----------
        values : mapping
            Parameters by name (e.g. the tracker's); the names of :data:`LIMIT_NAMES` are read.

        Returns
        -------
        Limits
        """
        return cls(**{n: float(values.get(n, 0.0) or 0.0) for n in LIMIT_NAMES})

    def scaled(self, factor: float) -> 'Limits':
        """Rate limits times ``factor`` (headroom for the feedback); the radius unchanged.

        Parameters
        ----------
        factor : float
            Scale of the speed and acceleration limits.

        Returns
        -------
        Limits
        """
        return Limits(self.max_linear_speed * factor, self.max_linear_accel * factor,
                      self.max_angular_speed * factor, self.max_angular_accel * factor,
                      self.min_turning_radius)


@dataclass(frozen=True)
class LimitReport:
    """One limit against a trajectory: peak, where, margin and the first violation."""

    name: str
    limit: float               # 0: not checked
    peak: float
    t: float                   # time of the peak (s, trajectory time)
    x: float
    y: float
    violated_at: float | None = None       # first time above the limit (s)
    violated_value: float | None = None    # the value there

    @property
    def checked(self) -> bool:
        """A limit was given (non-zero)."""
        return self.limit > 0

    @property
    def margin(self) -> float:
        """``limit - peak`` (radius: ``smallest radius - limit``); negative = violated."""
        return self.peak - self.limit if self.name == 'min_turning_radius' else \
            self.limit - self.peak

    def describe(self) -> str:
        """One line: the quantity, its peak and the margin, or the violation."""
        u = _UNITS[self.name]
        q = _QUANTITY[self.name]
        word = 'smallest' if self.name == 'min_turning_radius' else 'peak'
        head = (f'{self.name:<19} {word} {q} {self.peak:.4g} {u} at t = {self.t:.3f} s '
                f'({self.x:.3f}, {self.y:.3f}) m')
        if not self.checked:
            return f'{head}; limit not given'
        if self.violated_at is None:
            return f'{head}; limit {self.limit:g} {u}, margin {self.margin:.4g} {u}'
        return (f'{head}; VIOLATES {self.name} = {self.limit:g} {u}: {q} '
                f'{self.violated_value:.4g} {u} first at t = {self.violated_at:.3f} s')


@dataclass(frozen=True)
class LimitCheck:
    """All limits against a trajectory (:func:`check`)."""

    reports: tuple[LimitReport, ...]

    @property
    def violations(self) -> list[LimitReport]:
        """The limits that are exceeded."""
        return [r for r in self.reports if r.checked and r.violated_at is not None]

    @property
    def ok(self) -> bool:
        """No limit is exceeded."""
        return not self.violations

    def __getitem__(self, name: str) -> LimitReport:
        return next(r for r in self.reports if r.name == name)


@dataclass(frozen=True)
class _Profile:
    """Sampled kinematics of a trajectory: per time, speed, accelerations, curvature."""

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    speed: np.ndarray
    accel: np.ndarray          # dv/dt (tangential)
    rate: np.ndarray           # w (heading rate)
    rate_dot: np.ndarray       # dw/dt
    curvature: np.ndarray      # |kappa| (0 where at rest)
    moving: np.ndarray


def _samples(traj: Trajectory, step: float) -> np.ndarray:
    if traj.is_analytic:
        raise TrajectoryError(f'{traj.source}: an analytic path is unbounded; limits are '
                              'checked on bounded trajectories')
    n = int(min(max(math.ceil(traj.duration / step), 2000), MAX_SAMPLES))
    ts = np.linspace(traj.t_start, traj.t_end, n + 1)
    # every knot too: the curvature and acceleration change fastest there
    return np.union1d(ts, traj.knots)


def _profile(traj: Trajectory, step: float = 1e-3, window: float = 0.0) -> _Profile:
    ts = _samples(traj, step)
    s = traj.evaluate(ts)
    speed = np.hypot(s.vx, s.vy)
    moving = speed > MOVING_SPEED
    safe = np.where(moving, speed, 1.0)
    accel = np.where(moving, (s.vx * s.ax + s.vy * s.ay) / safe, np.hypot(s.ax, s.ay))
    cross = s.vx * s.ay - s.vy * s.ax
    rate = np.where(moving, cross / safe ** 2, 0.0)
    kappa = np.where(speed > CURVATURE_SPEED, np.abs(cross) / safe ** 3, 0.0)
    # dw/dt exactly, from the jerk: w = (v x a)/|v|^2
    inside = (ts > traj.t_start) & (ts < traj.t_end)
    jerk = traj._pp(np.clip(ts, traj.t_start, traj.t_end), 3)
    jerk[~inside] = 0.0
    cross_j = s.vx * jerk[:, 1] - s.vy * jerk[:, 0]
    dot = s.vx * s.ax + s.vy * s.ay
    rate_dot = np.where(moving, cross_j / safe ** 2 - 2 * cross * dot / safe ** 4, 0.0)
    if window > 0:
        # what a base commanded every `window` seconds sees: the mean rates of change
        # over a window (brief spikes of the jerk at a spline's knots average out)
        tw = ts + window
        e = traj.evaluate(tw)
        sp = np.hypot(e.vx, e.vy)
        mw = sp > MOVING_SPEED
        sw = np.where(mw, sp, 1.0)
        rw = np.where(mw, (e.vx * e.ay - e.vy * e.ax) / sw ** 2, 0.0)
        both = moving & mw
        rate_dot = np.where(both, (rw - rate) / window, 0.0)
        accel = np.where(tw <= traj.t_end, (sp - speed) / window, accel)
    return _Profile(ts, s.x, s.y, speed, accel, rate, rate_dot, kappa, moving)


def check(traj: Trajectory, limits: Limits, *, step: float = 1e-3,
          tolerance: float = 1e-6, window: float | None = None) -> LimitCheck:
    """Each limit against a bounded trajectory: peak, time, place, margin, violation.

    Parameters
    ----------
    traj : Trajectory
        A bounded trajectory (waypoints, Path, MultiDOFJointTrajectory).
    limits : Limits
        The base's limits (0 = not checked).
    step : float
        Sampling step (s); the knots are sampled too.
    tolerance : float
        Relative excess allowed (round-off of a trajectory re-timed onto its limits).
    window : float or None
        The accelerations are the mean rates of change of speed and turn rate over this
        many seconds (a base commanded at 50 Hz sees the change over 0.02 s, not the
        spline's jerk between two knots); None: :data:`WINDOW`, 0: instantaneous.

    Returns
    -------
    LimitCheck
        One :class:`LimitReport` per limit, in :data:`LIMIT_NAMES` order.
    """
    p = _profile(traj, step, WINDOW if window is None else window)
    series = {'max_linear_speed': p.speed, 'max_linear_accel': np.abs(p.accel),
              'max_angular_speed': np.abs(p.rate), 'max_angular_accel': np.abs(p.rate_dot),
              'min_turning_radius': p.curvature}
    out = []
    for name in LIMIT_NAMES:
        vals = series[name]
        lim = float(getattr(limits, name))
        i = int(np.argmax(vals))
        radius = name == 'min_turning_radius'
        peak = (1.0 / vals[i] if vals[i] > 0 else math.inf) if radius else float(vals[i])
        viol_t = viol_v = None
        if lim > 0:
            bound = (1.0 / lim) if radius else lim
            over = np.flatnonzero(vals > bound * (1 + tolerance))
            if over.size:
                j = int(over[0])
                viol_t = float(p.t[j])
                viol_v = (1.0 / vals[j]) if radius else float(vals[j])
        out.append(LimitReport(name, lim, peak, float(p.t[i]), float(p.x[i]), float(p.y[i]),
                               viol_t, viol_v))
    return LimitCheck(tuple(out))


def refuse_tight_turns(traj: Trajectory, limits: Limits, *, step: float = 1e-3) -> None:
    """Raise :class:`TrajectoryError` if the path turns tighter than ``min_turning_radius``.

    No timing fixes a curvature: the message names the place, the time and the curvature.

    Parameters
    ----------
    traj : Trajectory
        A bounded trajectory.
    limits : Limits
        The robot's limits (``min_turning_radius`` 0: nothing to refuse).
    step : float
        Sampling step of the check (s).

    Raises
    ------
    TrajectoryError
        If the path's curvature exceeds ``1 / min_turning_radius`` somewhere.
    """
    if limits.min_turning_radius <= 0:
        return
    r = check(traj, Limits(min_turning_radius=limits.min_turning_radius), step=step)
    rep = r['min_turning_radius']
    if rep.violated_at is not None:
        p = _profile(traj, step)
        j = int(np.argmax(p.curvature))
        raise TrajectoryError(
            f'{traj.source}: the path turns tighter than min_turning_radius = '
            f'{limits.min_turning_radius:g} m: curvature {p.curvature[j]:.4g} 1/m (radius '
            f'{1 / p.curvature[j]:.4g} m) at ({p.x[j]:.3f}, {p.y[j]:.3f}) m, t = '
            f'{p.t[j]:.3f} s (first above the limit at t = {rep.violated_at:.3f} s); a '
            'car-like base cannot drive it at any speed: plan a wider turn')


@dataclass(frozen=True)
class Retimed:
    """A re-timed trajectory and what changed (:func:`retime`)."""

    trajectory: Trajectory
    before: LimitCheck
    after: LimitCheck
    duration_before: float
    duration_after: float
    slowed: list[tuple[float, float]] = field(default_factory=list)   # (t0, t1) of the new
                                                                      # time slowed > 1 %
    used: Limits | None = None      # the limits of the last pass (tightened if needed)

    @property
    def changed(self) -> bool:
        """The timing was changed (the trajectory violated a limit)."""
        return self.trajectory is not None and self.duration_after != self.duration_before

    def describe(self) -> str:
        """What changed, in one paragraph."""
        if not self.changed:
            return 'within the limits: timing unchanged'
        names = ', '.join(r.name for r in self.before.violations)
        spans = '; '.join(f'{a:.2f}-{b:.2f} s' for a, b in self.slowed[:6])
        more = f' (+{len(self.slowed) - 6} more)' if len(self.slowed) > 6 else ''
        return (f're-timed for {names}: duration {self.duration_before:.3f} s -> '
                f'{self.duration_after:.3f} s, slower than planned during {spans}{more}')


@functools.lru_cache(maxsize=16)
def _pairs(m: int) -> tuple[np.ndarray, np.ndarray]:
    """All pairs of ``m`` constraint rows (the candidate vertices of a 2-D LP)."""
    i, j = np.triu_indices(m, 1)
    return i, j


def _vertices_max_min(A: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """Max and min of ``x`` over ``{(x, u): A [x, u] <= b}`` (2-D LP by vertex enumeration).

    Returns ``(nan, nan)`` if the set is empty.
    """
    i, j = _pairs(A.shape[0])
    a1, a2 = A[i], A[j]
    det = a1[:, 0] * a2[:, 1] - a1[:, 1] * a2[:, 0]
    ok = np.abs(det) > 1e-12
    if not ok.any():
        return math.nan, math.nan
    d = det[ok]
    b1, b2 = b[i][ok], b[j][ok]
    xv = (b1 * a2[ok, 1] - b2 * a1[ok, 1]) / d
    uv = (a1[ok, 0] * b2 - a2[ok, 0] * b1) / d
    feas = np.all(A @ np.vstack([xv, uv]) <= b[:, None] + 1e-9 * (1 + np.abs(b[:, None])),
                  axis=0)
    if not feas.any():
        return math.nan, math.nan
    xs = xv[feas]
    return float(xs.max()), float(xs.min())


def _rows(lim: Limits, kappa: float, dkappa: float, xmax: float
          ) -> tuple[list[list[float]], list[float]]:
    """Constraint rows ``A [x, u] <= b`` of one grid point (x = s'^2, u = s'')."""
    A = [[1.0, 0.0], [-1.0, 0.0]]
    b = [xmax, 0.0]
    if lim.max_linear_accel > 0:
        A += [[0.0, 1.0], [0.0, -1.0]]
        b += [lim.max_linear_accel, lim.max_linear_accel]
    if lim.max_angular_accel > 0 and (kappa or dkappa):
        A += [[dkappa, kappa], [-dkappa, -kappa]]
        b += [lim.max_angular_accel, lim.max_angular_accel]
    return A, b


def retime(traj: Trajectory, limits: Limits, *, ds: float = 0.002, knot_step: float = 0.02,
           step: float = 1e-3, smooth: int = 9) -> Retimed:
    """The trajectory along the same path, timed within ``limits`` (never faster than planned).

    Parameters
    ----------
    traj : Trajectory
        A bounded trajectory (it starts and ends as planned, at most at the limits).
    limits : Limits
        The base's limits (0 = none); a path tighter than ``min_turning_radius`` is refused
        (:func:`refuse_tight_turns`).
    ds : float
        Arc-length grid of the TOPP-RA passes (m).
    knot_step : float
        Time between the knots of the re-timed trajectory (s).
    step : float
        Sampling step of the checks (s).
    smooth : int
        Grid steps of the moving average that removes TOPP-RA's chattering (1 = none).

    Returns
    -------
    Retimed
        The original trajectory unchanged if it violates no limit, else the re-timed one,
        with the checks before and after and the spans that were slowed.
    """
    refuse_tight_turns(traj, limits, step=step)
    before = check(traj, limits, step=step)
    if before.ok:
        return Retimed(traj, before, before, traj.duration, traj.duration)
    used = limits
    for _ in range(ITERATIONS):
        new, T, spans = _topp(traj, used, ds=ds, knot_step=knot_step, step=step, smooth=smooth)
        after = check(new, limits, step=step, tolerance=TOLERANCE)
        if after.ok:
            break
        # the spline between the knots adds a little: tighten the rows still exceeded
        scale = {r.name: r.limit / r.peak * 0.98 for r in after.violations
                 if r.name != 'min_turning_radius'}
        used = Limits(**{n: getattr(used, n) * scale.get(n, 1.0) for n in LIMIT_NAMES})
    return Retimed(new, before, after, traj.duration, T, spans, used)


def _topp(traj: Trajectory, limits: Limits, *, ds: float, knot_step: float, step: float,
          smooth: int) -> tuple[Trajectory, float, list[tuple[float, float]]]:
    """One TOPP-RA pass: the re-timed trajectory, its duration and the slowed spans.

    The path on an arc-length grid (:class:`_PathGrid`), the controllable sets of the
    squared speed (backward pass, :func:`_controllable`), the greedy forward pass
    (:func:`_forward`), the new timing as a map of the original time
    (:func:`_retimed`) and the spans slowed (:func:`_slowed_spans`).
    """
    path = _PathGrid.of(traj, limits, _profile(traj, step), ds)
    lo, hi = _controllable(limits, path)
    xs = _forward(limits, path, lo, hi, smooth)
    sd = np.sqrt(xs)
    h = path.h
    dt = np.where(sd[1:] + sd[:-1] > 0, 2 * h / np.maximum(sd[1:] + sd[:-1], 1e-300), 0.0)
    if not np.all(np.isfinite(dt)) or np.any((sd[1:] + sd[:-1]) <= 0):
        raise TrajectoryError(f'{traj.source}: the path cannot be timed within the limits '
                              '(it would have to stop inside); check the limits')
    tg = traj.t_start + np.concatenate([[0.0], np.cumsum(dt)])
    T = float(tg[-1] - tg[0])
    new = _retimed(traj, path, tg, T, knot_step)
    return new, T, _slowed_spans((path.vplan > 1.01 * sd) & path.mv, tg)


@dataclass(frozen=True)
class _PathGrid:
    """The path on ``n + 1`` places of arc length ``sg`` (step ``h``) for TOPP-RA.

    ``s_t``: arc length at the profile's times ``t`` (``keep``: the first time at each
    place: stops keep their place); ``vplan`` the planned speed, ``mv`` where it moves,
    ``kappa``/``dkappa`` the curvature and its derivative in arc length, ``xmax`` the
    largest squared speed the speed limits allow.
    """

    n: int
    h: float
    sg: np.ndarray
    s_t: np.ndarray
    t: np.ndarray
    keep: np.ndarray
    vplan: np.ndarray
    mv: np.ndarray
    kappa: np.ndarray
    dkappa: np.ndarray
    xmax: np.ndarray

    @classmethod
    def of(cls, traj: Trajectory, limits: Limits, p: _Profile, ds: float) -> _PathGrid:
        """The grid of ``traj`` (profile ``p``: its samples) at spacing about ``ds``."""
        # arc length along the original timing
        s_t = np.concatenate([[0.0],
                              np.cumsum(0.5 * (p.speed[1:] + p.speed[:-1]) * np.diff(p.t))])
        L = float(s_t[-1])
        if L <= 0:
            raise TrajectoryError(f'{traj.source}: the trajectory does not move; nothing to '
                                  'time')
        n = max(int(math.ceil(L / ds)), 20)
        sg = np.linspace(0.0, L, n + 1)
        h = L / n
        # original time at each grid place (first time there: stops keep their place)
        keep = np.concatenate([[True], np.diff(s_t) > 0])
        t_of_s = np.interp(sg, s_t[keep], p.t[keep])
        g = traj.evaluate(t_of_s)
        vplan = np.hypot(g.vx, g.vy)
        mv = vplan > MOVING_SPEED
        sv = np.where(mv, vplan, 1.0)
        kappa = np.where(mv, (g.vx * g.ay - g.vy * g.ax) / sv ** 3, 0.0)
        # curvature on the grid between stops; interpolated over near-rest samples
        if mv.any():
            kappa = np.interp(sg, sg[mv], kappa[mv])
        dkappa = np.gradient(kappa, sg)
        xmax = vplan ** 2
        if limits.max_linear_speed > 0:
            xmax = np.minimum(xmax, limits.max_linear_speed ** 2)
        if limits.max_angular_speed > 0:
            with np.errstate(divide='ignore'):
                xmax = np.minimum(xmax, np.where(np.abs(kappa) > 0,
                                                 (limits.max_angular_speed / np.abs(kappa)) ** 2,
                                                 np.inf))
        return cls(n, h, sg, s_t, p.t, keep, vplan, mv, kappa, dkappa, xmax)


def _controllable(limits: Limits, path: _PathGrid) -> tuple[np.ndarray, np.ndarray]:
    """Backward pass: the controllable sets ``[lo, hi]`` of the squared speed per place.

    The end at most as fast as planned: at rest for a trajectory that ends at rest.
    """
    n, h, kappa, dkappa, xmax = path.n, path.h, path.kappa, path.dkappa, path.xmax
    lo = np.zeros(n + 1)
    hi = np.zeros(n + 1)
    hi[n] = xmax[n]
    for i in range(n - 1, -1, -1):
        A, b = _rows(limits, float(kappa[i]), float(dkappa[i]), float(xmax[i]))
        A += [[1.0, 2 * h], [-1.0, -2 * h]]
        b += [hi[i + 1], -lo[i + 1]]
        top, bot = _vertices_max_min(np.array(A), np.array(b))
        if math.isnan(top):                  # empty by round-off: the slowest admissible
            top = bot = 0.0
        hi[i], lo[i] = max(top, 0.0), max(bot, 0.0)
    return lo, hi


def _forward(limits: Limits, path: _PathGrid, lo: np.ndarray, hi: np.ndarray, smooth: int
             ) -> np.ndarray:
    """Forward pass: the squared speed at each place, the largest admissible ``u``.

    TOPP-RA chatters where a second-order row (the angular acceleration) is active: u
    alternates between its bounds from one grid step to the next while x stays on the
    boundary.  A moving average of x over ``smooth`` grid steps (linear rows: the average
    of admissible (x, u) pairs is admissible where the coefficients vary slowly), kept
    below the controllable bound, removes it.
    """
    n, h, kappa, dkappa = path.n, path.h, path.kappa, path.dkappa
    xs = np.zeros(n + 1)
    xs[0] = min(path.xmax[0], hi[0])       # the start as planned (within the limits)
    for i in range(n):
        x = xs[i]
        u_hi = (hi[i + 1] - x) / (2 * h)
        u_lo = (lo[i + 1] - x) / (2 * h)
        if limits.max_linear_accel > 0:
            u_hi = min(u_hi, limits.max_linear_accel)
            u_lo = max(u_lo, -limits.max_linear_accel)
        k, dk = float(kappa[i]), float(dkappa[i])
        if limits.max_angular_accel > 0 and k != 0:
            a, c = (limits.max_angular_accel - dk * x) / k, (-limits.max_angular_accel - dk * x) / k
            u_hi = min(u_hi, max(a, c))
            u_lo = max(u_lo, min(a, c))
        u = u_hi if u_hi >= u_lo else u_lo
        xs[i + 1] = max(x + 2 * h * u, 0.0)
    if smooth > 1:
        kern = np.ones(smooth) / smooth
        pad = np.pad(xs, smooth, mode='edge')
        ends = xs[0], xs[-1]
        xs = np.minimum(np.convolve(pad, kern, mode='same')[smooth:-smooth], hi)
        xs[0], xs[-1] = ends
    return xs


def _retimed(traj: Trajectory, path: _PathGrid, tg: np.ndarray, T: float, knot_step: float
             ) -> Trajectory:
    """The trajectory re-timed to reach the grid places at the times ``tg``.

    The new timing as a C2 map sigma(t) of the original time (sigma = t_of_s(s(t))): the
    re-timed trajectory is q(sigma(t)) with the original q, so its position, velocity
    q' sigma' and acceleration q'' sigma'^2 + q' sigma'' are consistent to round-off (a
    switch of the bang-bang s'' is smoothed over a few grid steps by the spline).
    """
    from scipy.interpolate import CubicSpline
    m = max(int(math.ceil(T / knot_step)), 2)
    tk = np.linspace(tg[0], tg[-1], m + 1)
    keep = path.keep
    sig = np.interp(path.sg, path.s_t[keep], path.t[keep])   # on the dense samples: on the path
    sig[0], sig[-1] = traj.t_start, traj.t_end
    ok = np.concatenate([[True], np.diff(tg) > 1e-12])
    smap = CubicSpline(tg[ok], sig[ok])
    sk, sdk, sddk = smap(tk), smap(tk, 1), smap(tk, 2)
    gk = traj.evaluate(np.clip(sk, traj.t_start, traj.t_end))
    vx, vy = gk.vx * sdk, gk.vy * sdk
    ax = gk.ax * sdk ** 2 + gk.vx * sddk
    ay = gk.ay * sdk ** 2 + gk.vy * sddk
    return from_states(tk, gk.x, gk.y, vx, vy, ax, ay, yaw=gk.heading,
                       source=f'{traj.source} (re-timed)')


def _slowed_spans(slow: np.ndarray, tg: np.ndarray) -> list[tuple[float, float]]:
    """Spans of the new time ``tg`` where ``slow`` holds (the plan was > 1 % faster)."""
    spans: list[tuple[float, float]] = []
    start = None
    for i in range(slow.size):
        if slow[i] and start is None:
            start = tg[i]
        elif not slow[i] and start is not None:
            spans.append((float(start), float(tg[i])))
            start = None
    if start is not None:
        spans.append((float(start), float(tg[-1])))
    return spans


def within_limits(traj: Trajectory, limits: Limits) -> tuple[Trajectory, str]:
    """The trajectory a tracker follows: re-timed if it exceeds ``limits``, and a note.

    Parameters
    ----------
    traj : Trajectory
        As received (analytic paths and trajectories within the limits pass unchanged).
    limits : Limits
        The base's limits (the tracker's parameters).

    Returns
    -------
    (Trajectory, str)
        The trajectory to follow and what changed ('' when nothing did).  A path tighter
        than ``min_turning_radius`` raises :class:`TrajectoryError` (place, curvature).
    """
    if traj.is_analytic or not any(getattr(limits, n) for n in LIMIT_NAMES):
        return traj, ''
    r = retime(traj, limits)
    if not r.changed:
        return traj, ''
    exceeded = '; '.join(v.describe() for v in r.before.violations)
    return r.trajectory, f'{r.describe()} ({exceeded})'
