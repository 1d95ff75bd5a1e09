"""Trajectories within a robot's limits: check, margins and time-optimal re-timing.

The limits are speed, linear acceleration, turn rate, angular acceleration and, car-like,
curvature (``1 / min_turning_radius``); 0 means *unknown / none*: not checked.
:func:`check` samples a bounded trajectory and returns, per limit, the peak, its time and
place, the margin and the first violation.  :func:`retime` re-times it at the cost the
limits demand: the path from the points' geometry (:func:`fit_path`), then the time-optimal
timing on it (TOPP-RA, closed-form passes), checked again to 1 %.

See doc/trajectories.md, section "Within the robot's limits", and the derivation in
doc/theory.md, section "Re-timing within limits" (#topp-ra).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

from .trajectory import Trajectory
from .errors import TrajectoryError

__all__ = ['Limits', 'LimitReport', 'LimitCheck', 'Retimed', 'check', 'retime',
           'LIMIT_NAMES', 'MOVING_SPEED', 'WINDOW', 'refuse_tight_turns', 'fit_path',
           'PathFit', 'PathPiece', 'PATH_TOLERANCE', 'time_optimal_duration', 'within_limits',
           'ACCEL_FRACTION', 'MIN_ACCEL_FRACTION', 'TOLERANCE', 'valid_accel_fraction']

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
#: The first pass of :func:`retime` times the accelerations at this fraction of their
#: limits (the quintic interpolation between 20 ms knots adds up to about 4 %).
HEADROOM = 0.95
#: Largest distance (m) of the re-timed path from the trajectory's points (:func:`fit_path`).
PATH_TOLERANCE = 1e-3
#: A plan that stays within ``tolerance / 2`` of one place this long (s) rests there, and
#: the re-timed trajectory stops there too; a shorter stay is a near-duplicate point.
REST_DWELL = 0.2
#: Turn (rad) between two chords beyond which the path reverses there (a cusp).
CUSP_ANGLE = 0.75 * math.pi
#: Most grid steps of the re-timing passes (a longer path gets a coarser grid).
MAX_GRID = 8_000
#: Most smoothing-spline fits of the search for the smoothest path within the tolerance.
FIT_ITERATIONS = 8
#: Length (m) by which a fitted piece is continued beyond its ends (natural spline ends).
EXTEND = 0.1
#: Step (m) of the chord parameter in a piece's arc-length table.
ARC_TABLE_STEP = 0.002
#: Least time (s) between the points the planned speed at a point is taken from.
SPEED_GAP = 0.1
#: Time (s) the re-timed trajectory rests at a stop or a cusp (two knots at rest: the
#: motion between them stays below MOVING_SPEED).
REST_KNOT = 1e-3
#: Share of the base's acceleration limits a followed trajectory may use (the tracker's
#: ``trajectory_accel_fraction``): the rest is the feedback's.  A reference at the whole
#: limit leaves the tracker no acceleration to correct an error with: its leading commands
#: ramp at the limit, fall behind and overshoot (measured: the line-arc lap on bases with
#: 80 ms of lag and 0.5 m/s^2 / 1.5 rad/s^2, 2.8-3.5 mm cross-track RMS at the whole limit,
#: 1.2-1.4 mm at 80 %; the saturation certificate's premise ``||u_d|| < u_max``,
#: :mod:`.synthesis.saturation`, says the same).
ACCEL_FRACTION = 0.8
#: The smallest share accepted (a trajectory at less than 5 % of the limits barely moves).
MIN_ACCEL_FRACTION = 0.05


def valid_accel_fraction(fraction: object) -> bool:
    """Whether ``fraction`` is a share of the acceleration limits a trajectory may use.

    Parameters
    ----------
    fraction : object
        The value given (``trajectory_accel_fraction``, ``--accel-fraction``).

    Returns
    -------
    bool
        A number (not a bool) in [:data:`MIN_ACCEL_FRACTION`, 1].
    """
    return (not isinstance(fraction, bool) and isinstance(fraction, (int, float))
            and MIN_ACCEL_FRACTION <= fraction <= 1.0)


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

    def of_motion(self, gain_v: float = 1.0, gain_w: float = 1.0) -> 'Limits':
        """The limits of the motion a base with static channel gains makes within these.

        The limits are the command's (``cmd_vel``, as a base's firmware and ``identify``
        see them); a base that turns at ``gain_w`` of its commanded rate (a skid-steer)
        turns at most ``gain_w * max_angular_speed`` and changes its turn rate at most
        ``gain_w * max_angular_accel``, and likewise in ``v``.  Gains of 1: these limits.

        Parameters
        ----------
        gain_v, gain_w : float
            The static gains (> 0; the tracker's ``gain_v``, ``gain_w``).

        Returns
        -------
        Limits
        """
        if gain_v == 1.0 and gain_w == 1.0:
            return self
        return Limits(self.max_linear_speed * gain_v, self.max_linear_accel * gain_v,
                      self.max_angular_speed * gain_w, self.max_angular_accel * gain_w,
                      self.min_turning_radius)

    def accel_share(self, fraction: float) -> 'Limits':
        """These limits with the accelerations scaled by ``fraction`` (a trajectory's share).

        Parameters
        ----------
        fraction : float
            In [:data:`MIN_ACCEL_FRACTION`, 1] (:data:`ACCEL_FRACTION`).

        Returns
        -------
        Limits

        Raises
        ------
        TrajectoryError
            For a fraction outside [:data:`MIN_ACCEL_FRACTION`, 1].
        """
        if not valid_accel_fraction(fraction):
            raise TrajectoryError(f'trajectory_accel_fraction must be a number in '
                                  f'[{MIN_ACCEL_FRACTION:g}, 1], got {fraction!r}')
        return Limits(self.max_linear_speed, self.max_linear_accel * fraction,
                      self.max_angular_speed, self.max_angular_accel * fraction,
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


def _kinematics(traj: Trajectory, ts: np.ndarray) -> tuple[np.ndarray, ...]:
    """Position, velocity and acceleration at times ``ts`` (at rest outside the range).

    As :meth:`Trajectory.evaluate` without the heading (the checks do not need it).
    """
    pp = traj._pp
    tc = np.clip(ts, traj.t_start, traj.t_end)
    outside = (ts < traj.t_start) | (ts > traj.t_end)
    pos, vel, acc = pp(tc), pp(tc, 1), pp(tc, 2)
    vel[outside] = 0.0
    acc[outside] = 0.0
    return pos[:, 0], pos[:, 1], vel[:, 0], vel[:, 1], acc[:, 0], acc[:, 1]


def _profile(traj: Trajectory, step: float = 1e-3, window: float = 0.0) -> _Profile:
    ts = _samples(traj, step)
    x, y, vx, vy, ax, ay = _kinematics(traj, ts)
    speed = np.hypot(vx, vy)
    moving = speed > MOVING_SPEED
    safe = np.where(moving, speed, 1.0)
    accel = np.where(moving, (vx * ax + vy * ay) / safe, np.hypot(ax, ay))
    cross = vx * ay - vy * ax
    rate = np.where(moving, cross / safe ** 2, 0.0)
    kappa = np.where(speed > CURVATURE_SPEED, np.abs(cross) / safe ** 3, 0.0)
    if window > 0:
        # what a base commanded every `window` seconds sees: the mean rates of change
        # over a window (brief spikes of the jerk at a spline's knots average out)
        tw = ts + window
        _, _, evx, evy, eax, eay = _kinematics(traj, tw)
        sp = np.hypot(evx, evy)
        mw = sp > MOVING_SPEED
        sw = np.where(mw, sp, 1.0)
        rw = np.where(mw, (evx * eay - evy * eax) / sw ** 2, 0.0)
        both = moving & mw
        rate_dot = np.where(both, (rw - rate) / window, 0.0)
        accel = np.where(tw <= traj.t_end, (sp - speed) / window, accel)
    else:
        # dw/dt exactly, from the jerk: w = (v x a)/|v|^2
        inside = (ts > traj.t_start) & (ts < traj.t_end)
        jerk = traj._pp(np.clip(ts, traj.t_start, traj.t_end), 3)
        jerk[~inside] = 0.0
        cross_j = vx * jerk[:, 1] - vy * jerk[:, 0]
        dot = vx * ax + vy * ay
        rate_dot = np.where(moving, cross_j / safe ** 2 - 2 * cross * dot / safe ** 4, 0.0)
    return _Profile(ts, x, y, speed, accel, rate, rate_dot, kappa, moving)


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


def refuse_tight_turns(traj: Trajectory, limits: Limits, *, step: float = 1e-3,
                       path: PathFit | None = None) -> None:
    """Raise :class:`.TrajectoryError` if the path turns tighter than ``min_turning_radius``.

    No timing fixes a curvature: the message names the place, the planned time and the
    curvature.  The curvature is the path's, taken from the points' geometry
    (:func:`fit_path`), not that of the spline between them (a point appended a few
    milliseconds after the one before curls a spline over millimetres).

    Parameters
    ----------
    traj : Trajectory
        A bounded trajectory.
    limits : Limits
        The robot's limits (``min_turning_radius`` 0: nothing to refuse).
    step : float
        Sampling step (s) of the checks; the fitted path's curvature is sampled every
        ``5 * step`` m (5 mm).
    path : PathFit, optional
        The fitted path (default: :func:`fit_path` of ``traj``).

    Raises
    ------
    TrajectoryError
        If the path's curvature exceeds ``1 / min_turning_radius`` (by more than 1 %)
        somewhere.
    """
    if limits.min_turning_radius <= 0:
        return
    path = fit_path(traj) if path is None else path
    bound = (1 + TOLERANCE) / limits.min_turning_radius
    worst: tuple[float, float, float, float] | None = None      # kappa, x, y, t
    first = None
    for piece in path.pieces:
        s = np.linspace(0.0, piece.length, max(int(piece.length / (5 * step)), 10) + 1)
        p, _, _, kappa, _ = piece.evaluate(s)
        ak = np.abs(kappa)
        t = np.interp(s, piece.s_pts, piece.t_pts)
        j = int(np.argmax(ak))
        if worst is None or ak[j] > worst[0]:
            worst = float(ak[j]), float(p[j, 0]), float(p[j, 1]), float(t[j])
        over = np.flatnonzero(ak > bound)
        if first is None and over.size:
            first = float(t[over[0]])
    if first is not None and worst is not None:
        k, x, y, t = worst
        raise TrajectoryError(
            f'{traj.source}: the path turns tighter than min_turning_radius = '
            f'{limits.min_turning_radius:g} m: curvature {k:.4g} 1/m (radius '
            f'{1 / k:.4g} m) at ({x:.3f}, {y:.3f}) m, t = {t:.3f} s (first above the limit '
            f'at t = {first:.3f} s); a car-like base cannot drive it at any speed: plan a '
            'wider turn')


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
    path: PathFit | None = None     # the path fitted to the points (None: unchanged)

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
        where = (f'slower than planned during {spans}{more}' if spans else
                 'nowhere more than 1 % slower than planned')
        path = '' if self.path is None else (
            f'; path within {self.path.deviation * 1e3:.2f} mm of the points')
        still = '; '.join(f'{r.name} {r.peak:.4g} {_UNITS[r.name]}'
                          for r in self.after.violations)
        still = f'; STILL EXCEEDS {still} after {ITERATIONS} passes' if still else ''
        return (f're-timed for {names}: duration {self.duration_before:.3f} s -> '
                f'{self.duration_after:.3f} s, {where}{path}{still}')


@dataclass(frozen=True)
class PathPiece:
    """One piece of a fitted path (between cusps): a C2 curve, evaluated by arc length.

    ``spline`` is the cubic smoothing spline of ``(x, y)`` over the chord parameter ``u``;
    ``u_tab``/``s_tab`` tabulate the arc length ``s(u)`` (``s`` maps to ``u`` by
    interpolation); ``s_pts``, ``t_pts`` and ``cap`` are the arc length, the planned time
    and the planned speed (the cap of the re-timing) at the points it was fitted to (and
    in the middle of the intervals where the plan is faster than at their ends);
    ``direction`` is +1 forwards, -1 backwards; ``deviation`` the largest distance (m) of
    the trajectory's points from the curve.
    """

    spline: Any
    u_tab: np.ndarray
    s_tab: np.ndarray
    s_pts: np.ndarray
    t_pts: np.ndarray
    cap: np.ndarray
    direction: float
    deviation: float

    @property
    def length(self) -> float:
        """Arc length (m)."""
        return float(self.s_tab[-1])

    def evaluate(self, s: Any) -> tuple[np.ndarray, ...]:
        """Position, unit tangent, ``d2p/ds2``, curvature and ``dkappa/ds`` at arc lengths.

        Parameters
        ----------
        s : array_like
            Arc lengths (m), within ``[0, length]``.

        Returns
        -------
        tuple of numpy.ndarray
            ``p`` (n, 2), ``p_s`` (n, 2), ``p_ss`` (n, 2), ``kappa`` (n,), ``dkappa`` (n,).
        """
        u = np.interp(np.asarray(s, float), self.s_tab, self.u_tab)
        r, r1, r2, r3 = (self.spline(u, k) for k in range(4))
        sig = np.maximum(np.hypot(r1[:, 0], r1[:, 1]), 1e-12)
        cross = r1[:, 0] * r2[:, 1] - r1[:, 1] * r2[:, 0]
        dot = r1[:, 0] * r2[:, 0] + r1[:, 1] * r2[:, 1]
        kappa = cross / sig ** 3
        dkappa = ((r1[:, 0] * r3[:, 1] - r1[:, 1] * r3[:, 0]) / sig ** 3
                  - 3 * cross * dot / sig ** 5) / sig
        p_s = r1 / sig[:, None]
        p_ss = (r2 * sig[:, None] - r1 * (dot / sig)[:, None]) / sig[:, None] ** 3
        return r, p_s, p_ss, kappa, dkappa

    def spans(self) -> list[tuple[float, float]]:
        """Arc-length spans between the places the plan rests (timed from rest to rest).

        Returns
        -------
        list of (float, float)
        """
        stops = self.s_pts[1:-1][self.cap[1:-1] == 0.0].tolist()
        edges = [0.0, *stops, self.length]
        return [(a, b) for a, b in zip(edges[:-1], edges[1:]) if b > a]

    def speed_cap(self, s: Any) -> np.ndarray:
        """The planned speed (m/s) at arc lengths ``s``.

        Its square is linear between the points (constant acceleration: a speed linear in
        the arc length would take infinitely long to leave rest).

        Parameters
        ----------
        s : array_like
            Arc lengths (m).

        Returns
        -------
        numpy.ndarray
        """
        out: np.ndarray = np.sqrt(np.interp(np.asarray(s, float), self.s_pts, self.cap ** 2))
        return out


@dataclass(frozen=True)
class PathFit:
    """The path of a trajectory taken from its points' geometry (:func:`fit_path`)."""

    pieces: tuple[PathPiece, ...]
    tolerance: float

    @property
    def deviation(self) -> float:
        """Largest distance (m) of the trajectory's points from the fitted path."""
        return max((p.deviation for p in self.pieces), default=0.0)

    @property
    def length(self) -> float:
        """Total arc length (m)."""
        return float(sum(p.length for p in self.pieces))


def _clusters(x: np.ndarray, y: np.ndarray, radius: float) -> list[tuple[int, int]]:
    """Runs of consecutive points within ``radius`` of the run's first point."""
    out = []
    n = x.size
    i = 0
    while i < n:
        j = i
        while j + 1 < n and math.hypot(x[j + 1] - x[i], y[j + 1] - y[i]) < radius:
            j += 1
        out.append((i, j))
        i = j + 1
    return out


def _extended(u: np.ndarray, P: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """``u, P`` continued beyond both ends by :data:`EXTEND` m of their own curvature.

    A smoothing spline's ends are *natural* (zero second derivative): a path that starts or
    ends on an arc would have its curvature pulled to 0 there, and overshoot before it.
    Ten points continue each end along the parabola fitted (per coordinate, in ``u``) to
    the last :data:`EXTEND` m; they only shape the fit.  Returns the extended arrays and
    the index of the first original point.
    """
    out_u, out_P = [u], [P]
    steps = EXTEND * np.arange(1, 11) / 10
    for side in (-1, 1):
        ref = u[0] if side < 0 else u[-1]
        near = np.abs(u - ref) <= EXTEND
        if near.sum() < 3:
            near = np.zeros(u.size, bool)
            near[:3] = side < 0
            near[-3:] = side > 0
        du = (u[near] - ref) / EXTEND              # scaled: a well-conditioned fit
        V = np.column_stack([du ** 2, du, np.ones_like(du)])
        coef = np.linalg.lstsq(V, P[near], rcond=None)[0]
        ue = side * steps[::side]                  # ascending, outside [u0, u_end]
        ve = ue / EXTEND
        pe = np.column_stack([ve ** 2, ve, np.ones_like(ve)]) @ coef
        if side < 0:
            out_u.insert(0, ref + ue)
            out_P.insert(0, pe)
        else:
            out_u.append(ref + ue)
            out_P.append(pe)
    return np.concatenate(out_u), np.concatenate(out_P), steps.size


def _smooth_fit(u: np.ndarray, P: np.ndarray, owner: np.ndarray, pts: np.ndarray,
                tolerance: float) -> tuple[Any, float]:
    """The smoothest cubic smoothing spline of ``P(u)`` with every point within tolerance.

    The weights are the points' spacing (the fit does not depend on how densely a stretch
    was sampled); the ends weigh 10^6 times more (the start and the goal stay put to
    ~10 nm: pieces meeting at a cusp meet there); beyond
    them the points are continued (:func:`_extended`).  The penalty ``lam`` is searched in
    log-log steps (the largest residual grows about like ``sqrt(lam)``); each point's
    distance to the curve is at most its residual ``|P(u_owner) - point|`` (its cluster's
    parameter).
    """
    from scipy.interpolate import make_interp_spline, make_smoothing_spline
    m = u.size
    if m < 5:
        spl = make_interp_spline(u, P, k=min(3, m - 1))
        return spl, float(np.hypot(*(spl(u)[owner] - pts).T).max())
    ux, Px, i0 = _extended(u, P)
    du = np.diff(ux)
    w = np.concatenate([[du[0]], 0.5 * (du[1:] + du[:-1]), [du[-1]]])
    w = w / w.mean()
    w[i0] = w[i0 + m - 1] = 1e6
    spacing = float(u[-1] / (m - 1))

    def fit(lam: float) -> tuple[Any, float]:
        spl = make_smoothing_spline(ux, Px, w=w, lam=lam)
        return spl, float(np.hypot(*(spl(u)[owner] - pts).T).max())

    lam = 0.03 ** 4 / spacing
    best: tuple[Any, float] | None = None
    lo = hi = math.nan                      # largest feasible, smallest infeasible lam
    for _ in range(FIT_ITERATIONS):
        spl, e = fit(lam)
        if e <= tolerance:
            if best is None or not lam < lo:
                best, lo = (spl, e), lam
            if e > 0.7 * tolerance:
                break
        else:
            hi = lam if math.isnan(hi) else min(hi, lam)
        step = (0.85 * tolerance / max(e, 1e-12)) ** 2
        new = lam * min(max(step, 1e-3), 1e3)
        if not math.isnan(hi) and not math.isnan(lo):
            new = min(max(new, lo * 1.05), hi / 1.05) if hi > lo * 1.11 else math.sqrt(lo * hi)
            if hi <= lo * 1.11:
                break
        lam = new
    if best is None:                        # interpolate the clusters: within tolerance
        spl = make_interp_spline(u, P, k=3)
        best = spl, float(np.hypot(*(spl(u)[owner] - pts).T).max())
    return best


def fit_path(traj: Trajectory, tolerance: float = PATH_TOLERANCE) -> PathFit:
    """The trajectory's path from its points' geometry, within ``tolerance`` of every point.

    The points are the trajectory's knots (a waypoint file's rows).  Consecutive points
    within ``tolerance / 2`` of one another are merged (near-duplicates, a rest's samples);
    the path is split at cusps (the direction of travel changes, or the chords turn back by
    more than :data:`CUSP_ANGLE`); each piece is a cubic smoothing spline over the chord
    length, as smooth as the tolerance allows (``_smooth_fit``): continuous curvature,
    bounded ``dkappa/ds``, whatever the sampling - uniform in time or in space, uneven, a
    final point appended a few milliseconds after the one before.  The planned speed at
    each point is the slope there of the parabola ``s(t)`` through it and the points
    :data:`SPEED_GAP` s before and after (exact for a constant acceleration); where the
    plan rests (within ``tolerance / 2`` for :data:`REST_DWELL` s or longer), at the ends
    and at cusps it is the plan's speed there (at rest: 0); in the middle of each interval
    it is the speed that takes the planned time over it (``_with_midpoints``).

    Parameters
    ----------
    traj : Trajectory
        A bounded trajectory.
    tolerance : float
        Largest distance (m) of a point from the path.

    Returns
    -------
    PathFit

    Raises
    ------
    TrajectoryError
        An analytic trajectory, or one that does not move.
    """
    if traj.is_analytic:
        raise TrajectoryError(f'{traj.source}: an analytic path is unbounded; only bounded '
                              'trajectories are re-timed')
    t = traj.knots
    g = traj.evaluate(t)
    x, y = g.x, g.y
    dirs = np.asarray(traj._dir, float)
    runs = _clusters(x, y, tolerance / 2)
    k = len(runs)
    if k < 2:
        raise TrajectoryError(f'{traj.source}: the trajectory does not move (all points within '
                              f'{tolerance / 2:g} m); nothing to time')
    first = np.array([a for a, _ in runs])
    last = np.array([b for _, b in runs])
    cnt = (last - first + 1)[:, None]
    P = np.add.reduceat(np.column_stack([x, y]), first, axis=0) / cnt
    P[0] = x[0], y[0]
    P[-1] = x[-1], y[-1]
    owner = np.repeat(np.arange(k), last - first + 1)
    chord = np.hypot(*np.diff(P, axis=0).T)
    gap = t[first[1:]] - t[last[:-1]]
    v = chord / gap
    S = np.concatenate([[0.0], np.cumsum(chord)])
    t_in, t_out = t[first], t[last]
    cap = _point_speeds(traj, S, t_in, t_out, v)
    # cusps: the direction of travel changes, or the chords turn back
    seg_dir = dirs[np.minimum(last[:-1], dirs.size - 1)]     # direction leaving each point
    d = np.diff(P, axis=0) / chord[:, None]
    turn = np.einsum('ij,ij->i', d[1:], d[:-1])
    cusp = np.flatnonzero((seg_dir[1:] != seg_dir[:-1]) | (turn < math.cos(CUSP_ANGLE))) + 1
    bounds = [0, *cusp.tolist(), k - 1]
    pieces = []
    for a, b in zip(bounds[:-1], bounds[1:]):
        sl = slice(a, b + 1)
        u = np.concatenate([[0.0], np.cumsum(chord[a:b])])
        sel = (owner >= a) & (owner <= b)
        spl, dev = _smooth_fit(u, P[sl], owner[sel] - a, np.column_stack([x, y])[sel],
                               tolerance)
        # the arc-length table: s -> u is interpolated linearly, so it is fine (2 mm) or
        # the velocity p_s s' would not be the derivative of the position p(u(s))
        u_tab = np.linspace(0.0, u[-1], max(4 * (b - a), int(u[-1] / ARC_TABLE_STEP)) + 1)
        sig = np.hypot(*spl(u_tab, 1).T)
        s_tab = np.concatenate([[0.0], np.cumsum(0.5 * (sig[1:] + sig[:-1]) *
                                                 np.diff(u_tab))])
        c = cap[sl].copy()
        if a > 0:
            c[0] = 0.0                      # a cusp: at rest
        if b < k - 1:
            c[-1] = 0.0
        s_pts = np.interp(u, u_tab, s_tab)
        s_all, t_all, c_all = _with_midpoints(s_pts, t_in[sl], t_out[sl], c)
        pieces.append(PathPiece(spl, u_tab, s_tab, s_all, t_all, c_all,
                                float(seg_dir[min(a, k - 2)]), dev))
    return PathFit(tuple(pieces), tolerance)


def _point_speeds(traj: Trajectory, S: np.ndarray, t_in: np.ndarray, t_out: np.ndarray,
                  v: np.ndarray) -> np.ndarray:
    """The planned speed at each merged point (arc length ``S``, times ``t_in``..``t_out``).

    Inside: the slope of the parabola ``s(t)`` through the point and the points
    :data:`SPEED_GAP` s before and after it (exact for a constant acceleration, however the
    points are spaced; a duplicate logged 1 ms later is not a neighbour: its noise over 1 ms
    would be a large speed); at the ends the trajectory's speed, within the first and last
    chord's mean speed ``v``; 0 where the plan rests :data:`REST_DWELL` s or longer.
    """
    k = S.size
    cap = np.empty(k)
    j = np.arange(1, k - 1)
    jm = np.minimum(np.searchsorted(t_out, t_in[j] - SPEED_GAP, side='right') - 1, j - 1)
    jp = np.maximum(np.searchsorted(t_in, t_out[j] + SPEED_GAP, side='left'), j + 1)
    jm, jp = np.maximum(jm, 0), np.minimum(jp, k - 1)
    g1, g2 = t_in[j] - t_out[jm], t_in[jp] - t_out[j]
    v1, v2 = (S[j] - S[jm]) / g1, (S[jp] - S[j]) / g2
    cap[1:-1] = (v1 * g2 + v2 * g1) / (g1 + g2)
    ends = traj.evaluate([traj.t_start, traj.t_end])
    cap[0], cap[-1] = math.hypot(ends.vx[0], ends.vy[0]), math.hypot(ends.vx[1], ends.vy[1])
    cap[(t_out - t_in) >= REST_DWELL] = 0.0
    cap[0] = min(cap[0], v[0])
    cap[-1] = min(cap[-1], v[-1])
    return cap


def _with_midpoints(s: np.ndarray, t_in: np.ndarray, t_out: np.ndarray, cap: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The points' speeds with one more in the middle of each interval, matching its time.

    Between points ``v0``, ``v1`` apart by ``c`` (m) in ``g`` (s), a constant acceleration
    over each half to the middle speed ``v`` takes ``c / (v0 + v) + c / (v + v1)``; ``v``
    is chosen so this is ``g``: between sparse waypoints (a planner's 2-5 points) the
    speed the plan reaches between them (rest to rest: ``2 c / g``).  Added only where the
    plan is more than 5 % faster between the points than at them and the points are at
    least :data:`SPEED_GAP` apart (dense samples, duplicates: the ends' speeds suffice).
    """
    c = np.diff(s)
    g = t_in[1:] - t_out[:-1]
    A, B = cap[:-1], cap[1:]
    qb = g * (A + B) - 2 * c
    qc = g * A * B - c * (A + B)
    v = (-qb + np.sqrt(np.maximum(qb * qb - 4 * g * qc, 0.0))) / (2 * g)
    # only where the plan is faster between the points than at them (sparse waypoints):
    # not between dense samples, nor over a duplicate's millisecond (noise / 1 ms)
    need = (g >= SPEED_GAP) & (c > 1.05 * g * 0.5 * (A + B))
    n = s.size
    order = np.argsort(np.concatenate([np.arange(n) * 2.0, np.flatnonzero(need) * 2.0 + 1]))
    s_all = np.concatenate([s, 0.5 * (s[1:] + s[:-1])[need]])[order]
    t_all = np.concatenate([t_in, 0.5 * (t_out[:-1] + t_in[1:])[need]])[order]
    c_all = np.concatenate([cap, v[need]])[order]
    return s_all, t_all, c_all


@dataclass(frozen=True)
class _Grid:
    """One piece on a uniform arc-length grid: the rows of the re-timing passes."""

    h: float
    s: np.ndarray
    p: np.ndarray
    kappa: np.ndarray
    dkappa: np.ndarray
    cap: np.ndarray
    xmax: np.ndarray

    @classmethod
    def of(cls, piece: PathPiece, limits: Limits, h: float, span: tuple[float, float]
           ) -> '_Grid':
        """``span`` of the piece at spacing about ``h`` (m), with the speed rows in ``xmax``."""
        n = max(int(math.ceil((span[1] - span[0]) / h)), 4)
        s = np.linspace(span[0], span[1], n + 1)
        p, _, _, kappa, dkappa = piece.evaluate(s)
        cap = piece.speed_cap(s)
        xmax = cap ** 2
        ak = np.abs(kappa)
        if limits.max_linear_speed > 0:
            xmax = np.minimum(xmax, limits.max_linear_speed ** 2)
        with np.errstate(divide='ignore'):
            if limits.max_angular_speed > 0:
                xmax = np.minimum(xmax, (limits.max_angular_speed / ak) ** 2)
            if limits.max_angular_accel > 0:
                # some u satisfies |u| <= a_max and |kappa' x + kappa u| <= alpha_max
                amax = limits.max_linear_accel if limits.max_linear_accel > 0 else math.inf
                xmax = np.minimum(xmax, (limits.max_angular_accel + ak * amax) /
                                  np.abs(dkappa))
        return cls(float(s[1] - s[0]), s, p, kappa, dkappa, cap, xmax)


#: A large finite bound (a row that is absent: no limit given).
_FREE = 1e12


def _step_rows(limits: Limits, grid: _Grid) -> tuple[np.ndarray, ...]:
    """The rows ``a x + b u <= c`` of each grid step (``x = x_i``, ``x_{i+1} = x_i + 2hu``).

    Per step ``i``: ``|u| <= a_max``; the angular acceleration at both ends of the step,
    ``|kappa'_i x + kappa_i u| <= alpha_max`` and ``|kappa'_{i+1} (x + 2hu) + kappa_{i+1}
    u| <= alpha_max`` (TOPP-RA's *interpolation* discretization: the collocation form,
    the row at ``i`` only, exceeds the limit between the grid points where the curvature
    changes); ``x_{i+1} >= 0``.  Split into the rows that bound ``u`` from above (``b >
    0``: shape (n, 3)) and from below (``b < 0``: (n, 4)), and a bound on ``x`` alone (the
    rows whose ``u`` coefficient vanishes).  Absent limits are rows with ``c = _FREE``.
    """
    n = grid.s.size - 1
    h = grid.h
    A = limits.max_linear_accel if limits.max_linear_accel > 0 else _FREE
    B = limits.max_angular_accel if limits.max_angular_accel > 0 else _FREE
    k0, dk0 = grid.kappa[:-1], grid.dkappa[:-1]
    k1, dk1 = grid.kappa[1:], grid.dkappa[1:]
    K1 = k1 + 2 * h * dk1
    xbound = np.full(n, np.inf)
    cols = []
    for k, dk in ((k0, dk0), (K1, dk1)):
        flat = np.abs(k) < 1e-9
        with np.errstate(divide='ignore'):
            xbound = np.minimum(xbound, np.where(flat & (np.abs(dk) > 0), B / np.abs(dk),
                                                 np.inf))
        sg = np.where(k < 0, -1.0, 1.0)
        cols.append((np.where(flat, 0.0, sg * dk), np.where(flat, 1.0, np.abs(k)),
                     np.where(flat, _FREE, B)))
    one = np.ones(n)
    ua = np.column_stack([0 * one, cols[0][0], cols[1][0]])
    ub = np.column_stack([one, cols[0][1], cols[1][1]])
    uc = np.column_stack([A * one, cols[0][2], cols[1][2]])
    la = np.column_stack([0 * one, -cols[0][0], -cols[1][0], -one])
    lb = np.column_stack([-one, -cols[0][1], -cols[1][1], -2 * h * one])
    lc = np.column_stack([A * one, cols[0][2], cols[1][2], 0 * one])
    return ua, ub, uc, la, lb, lc, xbound


def _passes(limits: Limits, grid: _Grid, smooth: int) -> np.ndarray:
    """The squared speed on the grid: TOPP-RA's backward and forward passes, closed form.

    With ``x = s'^2`` and ``u = s''`` constant per step (``x_{i+1} = x_i + 2 h u_i``)
    every row of a step is linear in ``(x, u)`` (:func:`_step_rows`).  For a given ``x``
    the admissible ``u`` lies between the lower rows and the upper rows; it exists iff
    every (lower, upper) pair agrees, one linear inequality in ``x`` per pair.  So the top
    of the controllable set at ``i`` is the smallest of the pairs' bounds (computed for
    all steps at once) and, with the reach row ``x + 2hu <= hi_{i+1}``, of three affine
    functions of ``hi_{i+1}`` (the backward pass, from the planned end speed).  The
    forward pass from the planned start speed takes the largest admissible ``u``.  A
    moving average over ``smooth`` steps, kept below the tops, removes what chattering
    remains.
    """
    h = grid.h
    ua, ub, uc, la, lb, lc, xbound = _step_rows(limits, grid)
    n = ua.shape[0]
    top = np.minimum(grid.xmax[:-1], xbound)
    # each (lower j, upper k) pair: (a_k b_j - a_j b_k) x >= c_k b_j - c_j b_k
    al = ua[:, None, :] * lb[:, :, None] - la[:, :, None] * ub[:, None, :]
    be = uc[:, None, :] * lb[:, :, None] - lc[:, :, None] * ub[:, None, :]
    neg = al < 0
    with np.errstate(divide='ignore', invalid='ignore'):
        top = np.minimum(top, np.where(neg, be / np.where(neg, al, 1.0), np.inf)
                         .min(axis=(1, 2)))
    # the reach row (1, 2h, hi_{i+1}) with the lower rows 0-2: x <= S_j hi_{i+1} + Q_j
    alr = lb[:, :3] - 2 * h * la[:, :3]
    use = alr < 0
    safe = np.where(use, alr, -1.0)
    S = np.where(use, lb[:, :3] / safe, 0.0)
    Q = np.where(use, -2 * h * lc[:, :3] / safe, np.inf)
    hi = [0.0] * (n + 1)
    hi[n] = float(grid.xmax[n])
    tops = top.tolist()
    S0, S1, S2 = S.T.tolist()
    Q0, Q1, Q2 = Q.T.tolist()
    for i in range(n - 1, -1, -1):
        nxt = hi[i + 1]
        t = min(tops[i], S0[i] * nxt + Q0[i], S1[i] * nxt + Q1[i], S2[i] * nxt + Q2[i])
        hi[i] = t if t > 0.0 else 0.0
    # forward: u from the upper rows (c - a x) / b, at least the lower rows' value
    P0, P1, P2 = (uc / ub).T.tolist()
    R0, R1, R2 = (ua / ub).T.tolist()
    p0, p1, p2 = (lc[:, :3] / lb[:, :3]).T.tolist()
    r0, r1, r2 = (la[:, :3] / lb[:, :3]).T.tolist()
    xs = [0.0] * (n + 1)
    xs[0] = min(float(grid.xmax[0]), hi[0])
    h2 = 2 * h
    for i in range(n):
        x = xs[i]
        nxt = hi[i + 1]
        u = min((nxt - x) / h2, P0[i] - R0[i] * x, P1[i] - R1[i] * x, P2[i] - R2[i] * x)
        lo = max(-x / h2, p0[i] - r0[i] * x, p1[i] - r1[i] * x, p2[i] - r2[i] * x)
        if u < lo:
            u = lo
        xn = x + h2 * u
        xs[i + 1] = nxt if xn > nxt else (xn if xn > 0.0 else 0.0)
    out = np.array(xs)
    if smooth > 1 and n > 2 * smooth:
        kern = np.ones(smooth) / smooth
        pad = np.pad(out, smooth, mode='edge')
        ends = out[0], out[-1]
        out = np.minimum(np.convolve(pad, kern, mode='same')[smooth:-smooth], np.array(hi))
        out[0], out[-1] = ends
    return out


def retime(traj: Trajectory, limits: Limits, *, ds: float = 0.005, knot_step: float = 0.02,
           step: float = 1e-3, smooth: int = 1,
           tolerance: float = PATH_TOLERANCE) -> Retimed:
    """The trajectory along the same path, timed within ``limits`` (never faster than planned).

    The path comes from the points' geometry (:func:`fit_path`: within ``tolerance`` of
    every point, continuous curvature), the timing from TOPP-RA's passes on it
    (``_passes``) under the limits and the planned speed; the result is checked
    (:func:`check`, 1 %: :data:`TOLERANCE`; a trajectory within the limits to that is
    returned unchanged) and, where the interpolation between the knots exceeds a limit,
    timed again with that limit tightened (at most :data:`ITERATIONS` passes).

    Parameters
    ----------
    traj : Trajectory
        A bounded trajectory (it starts and ends as planned, at most at the limits).
    limits : Limits
        The base's limits (0 = none); a path tighter than ``min_turning_radius`` is refused
        (:func:`refuse_tight_turns`).
    ds : float
        Arc-length grid of the passes (m; coarser for paths longer than
        :data:`MAX_GRID` steps).
    knot_step : float
        Time between the knots of the re-timed trajectory (s).
    step : float
        Sampling step of the checks (s).
    smooth : int
        Grid steps of the moving average that removes TOPP-RA's chattering (1 = none).
    tolerance : float
        Largest distance (m) of the re-timed path from the trajectory's points.

    Returns
    -------
    Retimed
        The original trajectory unchanged if it violates no limit, else the re-timed one,
        with the checks before and after, the spans that were slowed and the fitted path.
    """
    # within the limits to the re-timing's own accuracy: left as it is (a trajectory this
    # function wrote, read back from a file, is not re-timed again)
    before = check(traj, limits, step=step, tolerance=TOLERANCE)
    if before.ok:
        return Retimed(traj, before, before, traj.duration, traj.duration)
    path = fit_path(traj, tolerance)
    refuse_tight_turns(traj, limits, path=path)
    h = max(ds, path.length / MAX_GRID)
    # the knots' interpolation adds a little to the accelerations: time them with headroom
    used = Limits(limits.max_linear_speed, limits.max_linear_accel * HEADROOM,
                  limits.max_angular_speed, limits.max_angular_accel * HEADROOM,
                  limits.min_turning_radius)
    for _ in range(ITERATIONS):
        new, T, spans = _timed(traj, path, used, h=h, knot_step=knot_step, smooth=smooth)
        after = check(new, limits, step=step, tolerance=TOLERANCE)
        if after.ok:
            break
        # the spline between the knots adds a little: tighten the rows still exceeded
        # (by at most 30 % a pass: an excess no timing removes must not stall the robot)
        scale = {r.name: max(r.limit / r.peak * 0.98, 0.7) for r in after.violations
                 if r.name != 'min_turning_radius'}
        used = Limits(**{n: getattr(used, n) * scale.get(n, 1.0) for n in LIMIT_NAMES})
    return Retimed(new, before, after, traj.duration, T, spans, used, path)


def time_optimal_duration(path: PathFit, limits: Limits, *, ds: float = 0.005,
                          smooth: int = 1) -> float:
    """Duration (s) of the passes' timing of ``path`` under ``limits`` (no knots, no check).

    Parameters
    ----------
    path : PathFit
        A fitted path (:func:`fit_path`).
    limits : Limits
        The limits.
    ds : float
        Arc-length grid (m).
    smooth : int
        Moving average of the squared speed (1 = none: the passes' own optimum).

    Returns
    -------
    float
    """
    T = 0.0
    for piece in path.pieces:
        for span in piece.spans():
            g = _Grid.of(piece, limits, max(ds, path.length / MAX_GRID), span)
            T += float(_durations(np.sqrt(_passes(limits, g, smooth)), g.h, '').sum())
    return T


def _durations(sd: np.ndarray, h: float, source: str) -> np.ndarray:
    """Time of each grid step at the squared speeds' roots ``sd`` (error if one stops)."""
    both = sd[1:] + sd[:-1]
    if np.any(both <= 0):
        raise TrajectoryError(f'{source}: the path cannot be timed within the limits (it '
                              'would have to stop inside); check the limits')
    out: np.ndarray = 2 * h / both
    return out


def _timed(traj: Trajectory, path: PathFit, limits: Limits, *, h: float, knot_step: float,
           smooth: int) -> tuple[Trajectory, float, list[tuple[float, float]]]:
    """One timing of the fitted path: the trajectory, its duration and the slowed spans.

    Per piece the passes give ``x = s'^2`` on the grid; within a grid step the
    acceleration ``u`` is constant, so ``s(t)``, ``s'`` and ``s''`` are exact at any time.
    The knots every ``knot_step`` seconds get position ``p(s)``, velocity ``p_s s'`` and
    acceleration ``p_ss s'^2 + p_s s''`` (the quintic Hermite form,
    :func:`control.simulation.trajectory.from_states`).  At a cusp and where the plan
    rests the timing stops: two knots :data:`REST_KNOT` s apart, at rest, each with its
    side's acceleration (one knot with a mean acceleration would swing the velocity's
    direction around the stop).
    """
    t0 = traj.t_start
    T_all: list[np.ndarray] = []
    rows: list[np.ndarray] = []
    dirs: list[np.ndarray] = []
    spans: list[tuple[float, float]] = []
    for piece in path.pieces:
        for span in piece.spans():
            if T_all:                      # a stop or a cusp: at rest for REST_KNOT s
                t0 += REST_KNOT
            g = _Grid.of(piece, limits, h, span)
            xs = _passes(limits, g, smooth)
            sd = np.sqrt(xs)
            tg = t0 + np.concatenate([[0.0], np.cumsum(_durations(sd, g.h, traj.source))])
            u = (xs[1:] - xs[:-1]) / (2 * g.h)
            m = max(int(math.ceil((tg[-1] - tg[0]) / knot_step)), 2)
            tk = np.linspace(tg[0], tg[-1], m + 1)
            i = np.clip(np.searchsorted(tg, tk, side='right') - 1, 0, u.size - 1)
            tau = tk - tg[i]
            sk = np.clip(g.s[i] + sd[i] * tau + 0.5 * u[i] * tau ** 2, span[0], span[1])
            sdk = np.maximum(sd[i] + u[i] * tau, 0.0)
            sddk = u[i]
            sk[-1], sdk[-1] = span[1], sd[-1]
            p, p_s, p_ss, _, _ = piece.evaluate(sk)
            vel = p_s * sdk[:, None]
            acc = p_ss * (sdk ** 2)[:, None] + p_s * sddk[:, None]
            if rows:                       # the rest knots at one place
                p[0] = rows[-1][-1, 0:2]
            T_all.append(tk)
            rows.append(np.column_stack([p, vel, acc]))
            dirs.append(np.full(tk.size, piece.direction))
            slow = (g.cap > 1.01 * sd) & (g.cap > MOVING_SPEED)
            spans += _slowed_spans(slow, tg)
            t0 = float(tg[-1])
    tk = np.concatenate(T_all)
    R = np.concatenate(rows)
    new = Trajectory(pp=_quintic_hermite(tk, R), knots=tk, direction=np.concatenate(dirs),
                     source=f'{traj.source} (re-timed)', kind='quintic Hermite')
    return new, float(tk[-1] - tk[0]), spans


def _quintic_hermite(t: np.ndarray, R: np.ndarray) -> Any:
    """The quintic Hermite interpolant of positions, velocities and accelerations.

    The same curve as :func:`control.simulation.trajectory.from_states` (which builds it
    interval by interval through ``BPoly.from_derivatives``), in closed form for all
    intervals at once: on ``[t_i, t_i + H]`` with ``d = p_1 - p_0 - v_0 H - a_0 H^2 / 2``,
    ``e = v_1 - v_0 - a_0 H``, ``f = a_1 - a_0`` the local coefficients of
    ``tau^3, tau^4, tau^5`` are ``(10 d - 4 e H + f H^2 / 2) / H^3``, ``(-15 d + 7 e H -
    f H^2) / H^4``, ``(6 d - 3 e H + f H^2 / 2) / H^5``.

    Parameters
    ----------
    t : numpy.ndarray
        Knot times (s), increasing.
    R : numpy.ndarray
        Rows ``x, y, vx, vy, ax, ay`` per knot.

    Returns
    -------
    scipy.interpolate.PPoly
    """
    from scipy.interpolate import PPoly
    H = np.diff(t)[:, None]
    p0, p1 = R[:-1, 0:2], R[1:, 0:2]
    v0, v1 = R[:-1, 2:4], R[1:, 2:4]
    a0, a1 = R[:-1, 4:6], R[1:, 4:6]
    d = p1 - p0 - v0 * H - 0.5 * a0 * H ** 2
    e = v1 - v0 - a0 * H
    f = a1 - a0
    c = np.stack([(6 * d - 3 * e * H + 0.5 * f * H ** 2) / H ** 5,
                  (-15 * d + 7 * e * H - f * H ** 2) / H ** 4,
                  (10 * d - 4 * e * H + 0.5 * f * H ** 2) / H ** 3,
                  0.5 * a0, v0, p0])
    return PPoly(c, t)


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


def within_limits(traj: Trajectory, limits: Limits, accel_fraction: float = ACCEL_FRACTION
                  ) -> tuple[Trajectory, str]:
    """The trajectory a tracker follows: re-timed if it exceeds its share of ``limits``.

    Parameters
    ----------
    traj : Trajectory
        As received (analytic paths and trajectories within the limits pass unchanged).
    limits : Limits
        The base's limits (the tracker's parameters).
    accel_fraction : float, optional
        The share of the acceleration limits the trajectory may use, in
        [:data:`MIN_ACCEL_FRACTION`, 1] (:data:`ACCEL_FRACTION`; the rest is the feedback's).

    Returns
    -------
    (Trajectory, str)
        The trajectory to follow and what changed ('' when nothing did).  A path tighter
        than ``min_turning_radius`` raises :class:`.TrajectoryError` (place, curvature).
    """
    share = limits.accel_share(accel_fraction)
    if traj.is_analytic or not any(getattr(limits, n) for n in LIMIT_NAMES):
        return traj, ''
    r = retime(traj, share)
    if not r.changed:
        return traj, ''
    exceeded = '; '.join(v.describe() for v in r.before.violations)
    kept = (f'; the acceleration limits at {100 * accel_fraction:g} % '
            '(trajectory_accel_fraction: the rest is the feedback\'s)'
            if accel_fraction < 1 and (limits.max_linear_accel or limits.max_angular_accel)
            else '')
    return r.trajectory, f'{r.describe()}{kept} ({exceeded})'
