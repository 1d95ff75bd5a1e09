"""Timed trajectories: position, velocity, acceleration and heading at any time.

One type, :class:`Trajectory`, with two kinds behind it: an analytic
:class:`~nonfragile_tracker.control.simulation.reference.Path` (circle, figure eight; its
samples are exactly the path's), or a piecewise polynomial from timed points (a cubic
spline through positions, a smoothing spline for noisy points, the quintic Hermite
interpolant when velocities and accelerations are given).  Before its first time it holds
its first point at rest, after its last time its last point.  The heading is the direction
of travel (driving backwards included).  Bad input raises :class:`~.errors.TrajectoryError`
naming the source, the index and the value.

See doc/trajectories.md, sections "Sources" (the fits, heading and driving backwards) and
"Start, end and bad input".
"""
from __future__ import annotations

import bisect
import csv
import io
import math
import os
from dataclasses import dataclass
from pathlib import Path as FsPath
from typing import Any, cast

import numpy as np

from .reference import Path, RefSample
from .errors import TrajectoryError

__all__ = ['TrajectoryError', 'Trajectory', 'TrajectorySamples',
           'from_waypoints', 'from_states', 'from_poses', 'load_waypoints',
           'read_waypoint_file', 'time_law', 'check_frame', 'describe', 'Waypoints',
           'analytic_knots', 'analytic_knot_times', 'path_samples', 'KNOT_ANGLE',
           'MAX_KNOTS']

#: Points a curve needs: the spline's order and clamped ends need at least 2 distinct times.
MIN_POINTS = 2


@dataclass(frozen=True)
class TrajectorySamples:
    """Vectorised samples: one entry per requested time (SI units, trajectory frame)."""

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    vx: np.ndarray
    vy: np.ndarray
    ax: np.ndarray
    ay: np.ndarray
    heading: np.ndarray


@dataclass(frozen=True)
class Waypoints:
    """Timed waypoints as read from a file: ``t, x, y`` and optional ``yaw``/``speed``."""

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    yaw: np.ndarray | None = None
    speed: np.ndarray | None = None
    source: str = 'waypoints'


class Trajectory:
    """A timed planar trajectory ``t -> (x, y, vx, vy, ax, ay, heading)``.

    Build it with :meth:`analytic`, :func:`from_waypoints`, :func:`from_states`,
    :func:`from_poses` or :func:`load_waypoints`; do not call the constructor directly.
    """

    def __init__(self, *, path: Path | None = None, pp: Any = None,
                 knots: np.ndarray | None = None, direction: np.ndarray | None = None,
                 source: str = 'trajectory', kind: str = 'analytic'):
        """Use the factories (:meth:`analytic`, :func:`from_waypoints`, ...), not this.

        Parameters
        ----------
        path : Path, optional
            The analytic path (``kind='analytic'``).
        pp : scipy.interpolate.PPoly, optional
            The piecewise polynomial of ``(x, y)`` (power basis, ``c`` of shape
            ``(k + 1, segments, 2)``); with it ``knots`` and ``direction``.
        knots : numpy.ndarray, optional
            Its breakpoints (s).
        direction : numpy.ndarray, optional
            Per segment, +1 forwards or -1 backwards.
        source : str
            Where the trajectory came from (for messages).
        kind : str
            What built it (``analytic``, ``cubic spline``, ``quintic Hermite`` ...).
        """
        self.path = path
        self.source = source
        self.kind = kind
        #: it continues a motion (a replanned path, :mod:`.replan`): a
        #: follower takes it without a new run (:meth:`~.follow.Follower.splice`)
        self.spliced = False
        self._pp = pp
        if pp is not None:
            knots = cast(np.ndarray, knots)            # given with pp by the factories
            direction = cast(np.ndarray, direction)
            # scalar fast path: local power-basis coefficients, highest power first
            self._bp = np.asarray(knots, float).tolist()
            c = np.asarray(pp.c)                 # shape (k+1, segments, 2)
            self._cx = list(map(tuple, c[:, :, 0].T.tolist()))
            self._cy = list(map(tuple, c[:, :, 1].T.tolist()))
            self._knots = np.asarray(knots, float)
            self._dir = np.asarray(direction, float)
            self._dir_list = self._dir.tolist()
            self.t_start = float(knots[0])
            self.t_end = float(knots[-1])
            self._start = self._eval_scalar(self.t_start, 0)
            self._end = self._eval_scalar(self.t_end, len(self._cx) - 1)
        else:
            self.t_start = -math.inf
            self.t_end = math.inf

    # ------------------------------------------------------------------ construction
    @classmethod
    def analytic(cls, path: Path) -> 'Trajectory':
        """The trajectory of an analytic path; ``sample`` returns ``path.sample`` exactly.

        Parameters
        ----------
        path : Path
            A :mod:`.control.simulation.reference` path.

        Returns
        -------
        Trajectory
        """
        return cls(path=path, source=f'path {path.name}', kind='analytic')

    @property
    def is_analytic(self) -> bool:
        """True for the exact analytic paths (unbounded in time)."""
        return self.path is not None

    @property
    def knots(self) -> np.ndarray:
        """Times of the defining points (empty for analytic paths)."""
        return self._knots if self._pp is not None else np.zeros(0)

    @property
    def duration(self) -> float:
        """``t_end - t_start`` (s); infinite for analytic paths."""
        return self.t_end - self.t_start

    # ------------------------------------------------------------------ evaluation
    def _eval_scalar(self, t: float, i: int) -> tuple[float, ...]:
        s = t - self._bp[i]
        out = []
        for c in (self._cx[i], self._cy[i]):
            p = d = a = 0.0
            for cj in c:                         # Horner for p, p', p''
                a = a * s + 2.0 * d
                d = d * s + p
                p = p * s + cj
            out.append((p, d, a))
        (x, vx, ax), (y, vy, ay) = out
        return x, y, vx, vy, ax, ay

    def _heading(self, vx: float, vy: float, i: int) -> float:
        d = self._dir_list[i]
        if vx * vx + vy * vy > 1e-24:
            return math.atan2(d * vy, d * vx)
        return math.nan

    def sample(self, t: float) -> RefSample:
        """Desired state at time ``t`` (s).

        Outside ``[t_start, t_end]`` the first/last point at rest (zero velocity and
        acceleration, heading of the nearest motion).

        Parameters
        ----------
        t : float
            Trajectory time (s).

        Returns
        -------
        RefSample
        """
        if self.path is not None:
            return self.path.sample(t)
        if t < self.t_start:
            x, y = self._start[0], self._start[1]
            return RefSample(t, x, y, 0.0, 0.0, 0.0, 0.0, self._rest_heading(0))
        if t > self.t_end:
            x, y = self._end[0], self._end[1]
            return RefSample(t, x, y, 0.0, 0.0, 0.0, 0.0,
                             self._rest_heading(len(self._bp) - 1))
        i = bisect.bisect_right(self._bp, t) - 1
        i = min(max(i, 0), len(self._cx) - 1)
        x, y, vx, vy, ax, ay = self._eval_scalar(t, i)
        h = self._heading(vx, vy, i)
        if math.isnan(h):               # at rest inside: heading of the nearer knot
            h = self._rest_heading(i + 1 if 2 * t >= self._bp[i] + self._bp[i + 1] else i)
        return RefSample(t, x, y, vx, vy, ax, ay, h)

    def _rest_heading(self, i: int) -> float:
        """Heading at rest near knot ``i``: the direction of travel of the nearest motion."""
        return self._rest_headings[i]

    @property
    def _rest_headings(self) -> list[float]:
        cached = self.__dict__.get('_rh')
        if cached is not None:
            return cast(list[float], cached)
        n = len(self._bp)
        # direction of travel just inside each knot interval, else the chord to the next
        # distinct point; carried forward/backward over stops
        h = [math.nan] * n
        for i in range(n):
            seg = min(i, len(self._cx) - 1)
            lo, hi = self._bp[seg], self._bp[seg + 1]
            for frac in (1e-6, 1e-3, 0.5):
                tt = lo + frac * (hi - lo) if i < n - 1 else hi - frac * (hi - lo)
                _, _, vx, vy, _, _ = self._eval_scalar(tt, seg)
                hh = self._heading(vx, vy, seg)
                if not math.isnan(hh):
                    h[i] = hh
                    break
        last = next((v for v in h if not math.isnan(v)), 0.0)
        for i in range(n):
            if math.isnan(h[i]):
                h[i] = last
            last = h[i]
        self.__dict__['_rh'] = h
        return h

    def evaluate(self, t: Any) -> TrajectorySamples:
        """Vectorised :meth:`sample` over an array of times (same values as ``sample``).

        Parameters
        ----------
        t : array_like
            Trajectory times (s).

        Returns
        -------
        TrajectorySamples
        """
        tt = np.atleast_1d(np.asarray(t, dtype=float))
        if self.path is not None:
            rows = np.array([self.path.sample(float(s)) for s in tt]).reshape(-1, 8)
            return TrajectorySamples(*(rows[:, i].copy() for i in range(8)))
        pp = self._pp
        inside = (tt >= self.t_start) & (tt <= self.t_end)
        tc = np.clip(tt, self.t_start, self.t_end)
        pos = pp(tc)
        vel = pp(tc, 1)
        acc = pp(tc, 2)
        vel[~inside] = 0.0
        acc[~inside] = 0.0
        seg = np.clip(np.searchsorted(self._knots, tc, side='right') - 1, 0,
                      len(self._cx) - 1)
        d = self._dir[seg]
        moving = vel[:, 0] ** 2 + vel[:, 1] ** 2 > 1e-24
        heading = np.arctan2(d * vel[:, 1], d * vel[:, 0])
        kb = self._knots
        nearer = seg + (2 * tc >= kb[seg] + kb[seg + 1])
        rest_idx = np.where(tt < self.t_start, 0,
                            np.where(tt > self.t_end, len(self._bp) - 1, nearer))
        rh = np.asarray(self._rest_headings)[rest_idx]
        heading = np.where(moving, heading, rh)
        return TrajectorySamples(tt, pos[:, 0], pos[:, 1], vel[:, 0], vel[:, 1], acc[:, 0],
                                 acc[:, 1], heading)

    def poses(self, times: Any = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(t, x, y, heading)`` at ``times`` (default: the knots) - e.g. for a nav_msgs/Path.

        Parameters
        ----------
        times : array_like, optional
            Trajectory times (s).

        Returns
        -------
        tuple of 4 numpy.ndarray
        """
        if times is None:
            if self.path is not None:
                raise TrajectoryError(f'{self.source}: an analytic path has no knots; '
                                      'give the sample times')
            times = self._knots
        s = self.evaluate(times)
        return s.t, s.x, s.y, s.heading

    def __repr__(self) -> str:
        if self.path is not None:
            return f'Trajectory(analytic {self.path.name} {dict(self.path.params)})'
        return (f'Trajectory({self.kind} from {self.source}, {len(self._bp)} points, '
                f't = {self.t_start:g}..{self.t_end:g} s)')


# ------------------------------------------------------------------------- validation

def _array(name: str, values: Any, n: int | None, source: str) -> np.ndarray:
    try:
        arr = np.asarray(values, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise TrajectoryError(f'{source}: {name} must be numbers, got {values!r}') from None
    if n is not None and arr.size != n:
        raise TrajectoryError(f'{source}: {name} has {arr.size} values, expected {n} '
                              '(one per point)')
    bad = np.flatnonzero(~np.isfinite(arr))
    if bad.size:
        i = int(bad[0])
        raise TrajectoryError(f'{source}: point {i}: {name} = {arr[i]} is not finite; '
                              'every value must be a finite number')
    return arr


def _check_times(t: np.ndarray, source: str) -> None:
    if t.size < MIN_POINTS:
        raise TrajectoryError(f'{source}: {t.size} point(s); a trajectory needs at least '
                              f'{MIN_POINTS} points with increasing times')
    dt = np.diff(t)
    bad = np.flatnonzero(~(dt > 0))
    if bad.size:
        i = int(bad[0]) + 1
        raise TrajectoryError(f'{source}: point {i}: time t = {float(t[i])!r} s is not after the '
                              f'previous point\'s t = {float(t[i - 1])!r} s; times must increase '
                              'strictly')


def _direction(vx: np.ndarray, vy: np.ndarray, yaw: np.ndarray | None,
               speed: np.ndarray | None, n: int) -> np.ndarray:
    d = np.ones(n)
    if speed is not None:
        d = np.where(speed < 0, -1.0, 1.0)
    elif yaw is not None:
        dot = vx * np.cos(yaw) + vy * np.sin(yaw)
        d = np.where(dot < 0, -1.0, 1.0)
    return d


def _direction_from_yaw_chord(t: np.ndarray, x: np.ndarray, y: np.ndarray, yaw: np.ndarray,
                              speed: np.ndarray | None) -> np.ndarray:
    n = t.size
    if speed is not None:
        return np.where(speed < 0, -1.0, 1.0)
    if yaw is None:
        return np.ones(n)
    # chord direction of each segment (last point: previous segment) against the yaw
    dx = np.diff(x)
    dy = np.diff(y)
    dx = np.append(dx, dx[-1])
    dy = np.append(dy, dy[-1])
    return _direction(dx, dy, yaw, None, n)


# ------------------------------------------------------------------------- builders

def from_waypoints(t: Any, x: Any, y: Any, yaw: Any = None, speed: Any = None, *,
                   ends: str = 'rest', smoothing: float = 0.0,
                   source: str = 'waypoints',
                   start_velocity: tuple[float, float] | None = None) -> Trajectory:
    """Twice-differentiable trajectory through timed waypoints.

    Parameters
    ----------
    t, x, y : array_like
        Times (s, strictly increasing) and positions (m) in the odometry frame.
    yaw : array_like, optional
        Heading at each point (rad); decides forward/backward travel (see module doc).
    speed : array_like, optional
        Signed speed at each point (m/s): its sign gives the direction; with ``ends='rest'``
        the first and last speeds are the clamped end speeds (along ``yaw`` if given, else
        along the end chord).
    ends : {'rest', 'natural'}
        ``'rest'``: clamped ends (velocity = end speed, default 0); ``'natural'``: zero
        second derivative at the ends.
    smoothing : float
        0 interpolates; ``> 0`` fits a cubic smoothing spline with this penalty ``lam``.
    source : str
        File or topic name for error messages.
    start_velocity : (float, float), optional
        With ``ends='rest'`` and no smoothing: the clamped velocity ``(vx, vy)`` (m/s) at the
        first point instead (a path spliced onto a motion, :mod:`.replan`).

    Returns
    -------
    Trajectory

    Raises
    ------
    TrajectoryError
        Fewer than 2 points, non-increasing times, non-finite values, bad options.
    """
    from scipy.interpolate import CubicSpline, PPoly, make_smoothing_spline
    t = _array('t', t, None, source)
    n = t.size
    x = _array('x', x, n, source)
    y = _array('y', y, n, source)
    yaw = None if yaw is None else _array('yaw', yaw, n, source)
    speed = None if speed is None else _array('speed', speed, n, source)
    _check_times(t, source)
    if ends not in ('rest', 'natural'):
        raise TrajectoryError(f'{source}: ends must be rest or natural, got {ends!r}')
    if not (isinstance(smoothing, (int, float)) and math.isfinite(smoothing)
            and smoothing >= 0):
        raise TrajectoryError(f'{source}: smoothing must be a finite number >= 0, '
                              f'got {smoothing!r}')
    P = np.column_stack([x, y])
    if smoothing > 0:
        if n < 5:
            raise TrajectoryError(f'{source}: {n} points; a smoothing spline needs at '
                                  'least 5')
        spl = [make_smoothing_spline(t, P[:, j], lam=float(smoothing)) for j in range(2)]
        ppx, ppy = (PPoly.from_spline(s) for s in spl)
        # the B-spline's breakpoints include repeated end knots: keep the data range
        c = np.stack([ppx.c, ppy.c], axis=-1)
        brk = ppx.x
        keep = np.flatnonzero(np.diff(brk) > 0)
        pp = PPoly(c[:, keep, :], np.append(brk[keep], brk[keep[-1] + 1]))
        knots = pp.x
        kind = 'smoothing spline'
    else:
        if ends == 'rest':
            v0 = np.zeros(2)
            v1 = np.zeros(2)
            if speed is not None:
                for v, i, j in ((v0, 0, 1), (v1, n - 1, n - 2)):
                    if yaw is not None:       # signed speed along the given heading
                        v[:] = speed[i] * np.array([math.cos(yaw[i]), math.sin(yaw[i])])
                    else:                     # |speed| along the end chord (direction of travel)
                        ch = P[max(i, j)] - P[min(i, j)]
                        nrm = float(np.hypot(*ch))
                        v[:] = abs(speed[i]) * ch / nrm if nrm > 0 else 0.0
            if start_velocity is not None:
                v0[:] = start_velocity
            bc: str | tuple[tuple[int, np.ndarray], tuple[int, np.ndarray]] = ((1, v0), (1, v1))
        else:
            bc = 'natural'
        if n == 2 and bc == 'natural':
            bc = 'not-a-knot'           # two points: the straight line
        pp = CubicSpline(t, P, bc_type=bc)
        knots = t
        kind = 'cubic spline'
    seg_t = knots
    direction = _direction_from_yaw_chord(t, x, y, yaw, speed)
    if seg_t.size != t.size:             # smoothing spline: direction of the nearest point
        idx = np.clip(np.searchsorted(t, seg_t, side='right') - 1, 0, n - 1)
        direction = direction[idx]
    return Trajectory(pp=pp, knots=knots, direction=direction, source=source, kind=kind)


class _Pieces:
    """A piecewise polynomial in scipy's ``PPoly`` layout, evaluated with numpy.

    ``c`` of shape ``(k + 1, m, 2)`` (highest power first), breakpoints ``x`` (``m + 1``);
    ``pieces(t, nu)`` is the ``nu``-th derivative at ``t`` like ``PPoly(c, x)(t, nu)``
    (each point in the interval starting at or before it, the end ones extrapolated).
    :func:`from_states` needs nothing else of scipy: importing ``scipy.interpolate``
    costs 0.5-1 s, most of the reference node's start-up.
    """

    def __init__(self, c: np.ndarray, x: np.ndarray):
        self.c = c
        self.x = x

    def __call__(self, t: Any, nu: int = 0) -> np.ndarray:
        """The ``nu``-th derivative at ``t`` (shape ``t.shape + (2,)``)."""
        t = np.asarray(t, dtype=float)
        c, k = self.c, self.c.shape[0] - 1
        i = np.clip(np.searchsorted(self.x, t, side='right') - 1, 0, c.shape[1] - 1)
        s = (t - self.x[i])[..., None]
        if nu > k:
            return np.zeros(t.shape + c.shape[2:])
        out: np.ndarray = math.perm(k, nu) * c[0][i]
        for j in range(1, k + 1 - nu):          # Horner over the derivative's coefficients
            out *= s
            out += math.perm(k - j, nu) * c[j][i]
        return out


def _hermite_coefficients(t: np.ndarray, p: np.ndarray, v: np.ndarray,
                          a: np.ndarray | None) -> np.ndarray:
    """Power-basis coefficients of the Hermite interpolant, all intervals at once.

    Highest power first, shape ``(k + 1, n - 1)``: the cubic matching ``p, v`` or the
    quintic matching ``p, v, a`` at both ends of each interval - what
    ``PPoly.from_bernstein_basis(BPoly.from_derivatives(t, ...))`` gives (to round-off),
    in closed form.
    """
    h = np.diff(t)
    dp = np.diff(p)
    v0, v1 = v[:-1], v[1:]
    if a is None:
        c3 = (-2.0 * dp + (v0 + v1) * h) / h**3
        c2 = (3.0 * dp - (2.0 * v0 + v1) * h) / h**2
        return np.stack([c3, c2, v0, p[:-1]])
    a0, a1 = a[:-1], a[1:]
    h2 = h * h
    c5 = (12.0 * dp - 6.0 * (v0 + v1) * h + (a1 - a0) * h2) / (2.0 * h2 * h2 * h)
    c4 = (-30.0 * dp + (16.0 * v0 + 14.0 * v1) * h + (3.0 * a0 - 2.0 * a1) * h2) \
        / (2.0 * h2 * h2)
    c3 = (20.0 * dp - (12.0 * v0 + 8.0 * v1) * h + (a1 - 3.0 * a0) * h2) / (2.0 * h2 * h)
    return np.stack([c5, c4, c3, 0.5 * a0, v0, p[:-1]])


def from_states(t: Any, x: Any, y: Any, vx: Any, vy: Any, ax: Any = None, ay: Any = None,
                yaw: Any = None, *, source: str = 'trajectory') -> Trajectory:
    """C2 trajectory matching given positions, velocities (and accelerations) at each time.

    The quintic Hermite interpolant (``BPoly.from_derivatives``) matches position,
    velocity and acceleration at every point (cubic Hermite if no accelerations are given,
    then only C1).  This is the form of trajectory_msgs/MultiDOFJointTrajectory and
    nav2_msgs/Trajectory points; velocities and accelerations are in the trajectory frame.

    Parameters
    ----------
    t : array_like
        Times (s), strictly increasing.
    x, y : array_like
        Positions (m).
    vx, vy : array_like
        Velocities (m/s).
    ax, ay : array_like, optional
        Accelerations (m/s^2); both or neither.
    yaw : array_like, optional
        Headings (rad): where the velocity points against it the robot drives backwards.
    source : str
        Where the points came from (for messages).

    Returns
    -------
    Trajectory

    Raises
    ------
    TrajectoryError
        Non-finite values, mismatched lengths or times not increasing.
    """
    t = _array('t', t, None, source)
    n = t.size
    x = _array('x', x, n, source)
    y = _array('y', y, n, source)
    vx = _array('vx', vx, n, source)
    vy = _array('vy', vy, n, source)
    have_acc = ax is not None and ay is not None
    if have_acc:
        ax = _array('ax', ax, n, source)
        ay = _array('ay', ay, n, source)
    yaw = None if yaw is None else _array('yaw', yaw, n, source)
    _check_times(t, source)
    # the Hermite pieces in closed form, all intervals at once (scipy's
    # BPoly.from_derivatives builds them one interval at a time in Python: 4 s for the
    # 48,000 knots of an hour of the reference's analytic path, in a node's start-up)
    c = np.stack([_hermite_coefficients(t, x, vx, ax if have_acc else None),
                  _hermite_coefficients(t, y, vy, ay if have_acc else None)], axis=-1)
    pp = _Pieces(c, t)
    direction = _direction(vx, vy, yaw, None, n)
    return Trajectory(pp=pp, knots=t, direction=direction, source=source,
                      kind='quintic Hermite' if have_acc else 'cubic Hermite')


#: Angle (rad) the fastest harmonic of an analytic path turns between two knots of its
#: sampled form (:func:`analytic_knots`).  The quintic Hermite interpolant's position error
#: scales like ``radius * angle**6 / 46080``: below 1e-13 m for a 0.5 m path at 0.03 rad
#: (measured: 1e-14 m over an hour of the paper's circle and figure eight,
#: test/control/test_analytic_knots.py).
KNOT_ANGLE = 0.03
#: Most knots :func:`analytic_knots` gives (a trajectory message of about 200 bytes each).
MAX_KNOTS = 50_000


def analytic_knots(path: Path, horizon: float, *, angle: float = KNOT_ANGLE,
                   max_knots: int = MAX_KNOTS) -> tuple[np.ndarray, TrajectorySamples]:
    """Knots sampling an analytic path over ``[0, horizon]`` for the quintic Hermite form.

    The knots are equally spaced in whole nanoseconds (a message's ``time_from_start``),
    ``angle / (|rate| * harmonic)`` seconds apart (one interval if the path rests); the last
    knot is at or after ``horizon``.  :func:`from_states` on the returned samples (position,
    velocity, acceleration, heading: exact path values) reproduces the path to round-off.

    Parameters
    ----------
    path : Path
        The analytic path.
    horizon : float
        Length of time covered (s).
    angle : float
        Angle (rad) its fastest harmonic turns between two knots.
    max_knots : int
        Most knots given.

    Returns
    -------
    (numpy.ndarray, TrajectorySamples)
        Knot times in integer nanoseconds from the path's time 0, and the exact samples.
    """
    t_ns = analytic_knot_times(path, horizon, angle=angle, max_knots=max_knots)
    return t_ns, path_samples(path, t_ns)


def analytic_knot_times(path: Path, horizon: float, *, angle: float = KNOT_ANGLE,
                        max_knots: int = MAX_KNOTS) -> np.ndarray:
    """The knot times of :func:`analytic_knots` (integer ns), without sampling the path.

    Parameters
    ----------
    path : Path
        The analytic path.
    horizon : float
        Length of time covered (s).
    angle : float
        Angle (rad) its fastest harmonic turns between two knots.
    max_knots : int
        Most knots given.

    Returns
    -------
    numpy.ndarray
        Knot times in integer nanoseconds from the path's time 0.
    """
    if not (math.isfinite(horizon) and horizon > 0):
        raise TrajectoryError(f'{path.name}: horizon must be a finite time > 0 s, got {horizon!r}')
    speed = abs(float(path.params.get('rate', 0.0))) * path.harmonic
    horizon_ns = int(math.ceil(horizon * 1e9))
    step_ns = horizon_ns if speed == 0 else max(1, min(horizon_ns,
                                                       int(angle / speed * 1e9)))
    n = -(-horizon_ns // step_ns)
    if n + 1 > max_knots:
        raise TrajectoryError(f'{path.name}: {n + 1} knots needed for a horizon of {horizon} s '
                              f'at rate {path.params.get("rate")} rad/s (at most {max_knots}); '
                              'shorten the horizon')
    return np.arange(n + 1, dtype=np.int64) * step_ns


def path_samples(path: Path, t_ns: Any) -> TrajectorySamples:
    """The exact samples of an analytic path at integer-nanosecond times.

    Parameters
    ----------
    path : Path
        The analytic path.
    t_ns : array_like of int
        Times [ns] from the path's time 0.

    Returns
    -------
    TrajectorySamples
    """
    t = np.asarray(t_ns, dtype=np.int64) * 1e-9
    f = path.kinematics
    rows = np.fromiter((v for s in t.tolist() for v in f(s)), float, 6 * t.size).reshape(-1, 6)
    x, y, vx, vy, ax, ay = (rows[:, i].copy() for i in range(6))
    # Path.sample's heading rule over all times (numpy's arctan2)
    heading = np.where(vx * vx + vy * vy > 1e-24, np.arctan2(vy, vx), path.rest_heading)
    return TrajectorySamples(t, x, y, vx, vy, ax, ay, heading)


def time_law(x: Any, y: Any, cruise_speed: float, max_accel: float, *,
             source: str = 'path', start_speed: float = 0.0) -> np.ndarray:
    """Times for untimed points: trapezoidal speed profile along the polyline's arc length.

    Accelerates at ``max_accel`` from rest to ``cruise_speed``, cruises, and brakes to rest
    at the last point (a triangle if the path is too short to reach the cruise speed).
    Consecutive duplicate points must be removed first.  With ``start_speed > 0`` (a path
    spliced onto a motion, :mod:`.replan`) the profile starts at that
    speed instead: it accelerates (or brakes) from it to the cruise speed at ``max_accel``;
    a path too short to stop from it at ``max_accel`` brakes over its whole length, harder.

    Parameters
    ----------
    x, y : array_like
        The points (m).
    cruise_speed : float
        Speed between the ramps (m/s), > 0.
    max_accel : float
        Acceleration and braking (m/s^2), > 0.
    source : str
        Where the points came from (for messages).
    start_speed : float, optional
        Speed at the first point (m/s, >= 0; default 0: from rest).

    Returns
    -------
    numpy.ndarray
        Times (s) from 0.
    """
    for name, v in (('cruise_speed', cruise_speed), ('max_accel', max_accel)):
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
            raise TrajectoryError(f'{source}: {name} must be a finite number > 0, got {v!r}')
    if not (math.isfinite(start_speed) and start_speed >= 0):
        raise TrajectoryError(f'{source}: start_speed must be a finite number >= 0, got '
                              f'{start_speed!r}')
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    seg = np.hypot(np.diff(x), np.diff(y))
    s = np.concatenate([[0.0], np.cumsum(seg)])
    L = float(s[-1])
    if start_speed > 0:
        return _moving_time_law(s, float(cruise_speed), float(max_accel), float(start_speed))
    v, a = float(cruise_speed), float(max_accel)
    s_acc = v * v / (2 * a)
    if 2 * s_acc > L:                     # triangle profile
        v = math.sqrt(a * L)
        s_acc = L / 2
    t_acc = v / a
    t_cruise = (L - 2 * s_acc) / v
    out = np.empty_like(s)
    for i, si in enumerate(s):
        if si <= s_acc:
            out[i] = math.sqrt(2 * si / a)
        elif si <= L - s_acc:
            out[i] = t_acc + (si - s_acc) / v
        else:
            rem = max(L - si, 0.0)
            out[i] = 2 * t_acc + t_cruise - math.sqrt(2 * rem / a)
    return out


def _moving_time_law(s: np.ndarray, cruise: float, a: float, v0: float) -> np.ndarray:
    """Times at arc lengths ``s`` of the profile from ``v0``: ramp, cruise, brake to rest.

    Three phases of constant acceleration (the ramp's ``+-a``, 0, the braking's ``-ab``);
    within a phase from speed ``va`` at ``sa`` and ``ta``, ``v(s) = sqrt(va^2 + 2 A (s -
    sa))`` and ``t = ta + (v - va) / A`` (``ta + (s - sa) / va`` when ``A = 0``).
    """
    L = float(s[-1])
    if v0 * v0 > 2 * a * L:             # cannot stop at a: brake over the whole length
        phases = [(0.0, v0, -v0 * v0 / (2 * L))]
    else:
        # from v0 to the cruise speed and down to rest needs max(v0, cruise)^2 ... : a
        # triangle when it does not fit (only when v0 < cruise: above it, v0^2 / 2a <= L)
        vp = cruise
        if v0 < cruise and (2 * cruise ** 2 - v0 * v0) / (2 * a) > L:
            vp = math.sqrt((2 * a * L + v0 * v0) / 2)
        s1 = abs(vp * vp - v0 * v0) / (2 * a)
        s2 = max(L - vp * vp / (2 * a), s1)
        phases = [(0.0, v0, a if vp >= v0 else -a), (s1, vp, 0.0), (s2, vp, -a)]
    out = np.empty_like(s)
    ta = 0.0
    bounds = [p[0] for p in phases[1:]] + [math.inf]
    for (sa, va, A), sb in zip(phases, bounds):
        sel = (s >= sa) & (s < sb) if sb < math.inf else s >= sa
        ds = s[sel] - sa
        if A == 0.0:
            out[sel] = ta + ds / va
            tb = ta + (sb - sa) / va if sb < math.inf else ta
        else:
            v = np.sqrt(np.maximum(va * va + 2 * A * ds, 0.0))
            out[sel] = ta + (v - va) / A
            vb = math.sqrt(max(va * va + 2 * A * (sb - sa), 0.0)) if sb < math.inf else 0.0
            tb = ta + (vb - va) / A
        ta = tb
    return out


def from_poses(t: Any, x: Any, y: Any, yaw: Any, *, cruise_speed: float | None = None,
               max_accel: float | None = None, source: str = 'path') -> Trajectory:
    """Trajectory from the poses of a nav_msgs/Path (times from its stamps).

    ``t`` are the poses' stamps relative to the first (s).  If all stamps are zero the
    times come from :func:`time_law` with ``cruise_speed`` and ``max_accel`` (then
    consecutive duplicate points are dropped).  The yaw decides forward/backward.

    Parameters
    ----------
    t : array_like
        Stamps (s) relative to the first.
    x, y : array_like
        Positions (m).
    yaw : array_like
        Headings (rad).
    cruise_speed, max_accel : float, optional
        The time law's speed (m/s) and acceleration (m/s^2), for unstamped poses.
    source : str
        Where the poses came from (for messages).

    Returns
    -------
    Trajectory

    Raises
    ------
    TrajectoryError
        Bad values, or unstamped poses without ``cruise_speed`` and ``max_accel``.
    """
    t = _array('stamp', t, None, source)
    n = t.size
    x = _array('x', x, n, source)
    y = _array('y', y, n, source)
    yaw = _array('yaw', yaw, n, source)
    if n and np.all(t == 0):
        if cruise_speed is None or max_accel is None:
            raise TrajectoryError(f'{source}: all pose stamps are zero; give cruise_speed and '
                                  'max_accel for a time law, or stamp the poses')
        keep = np.concatenate([[True], np.hypot(np.diff(x), np.diff(y)) > 0])
        x, y, yaw = x[keep], y[keep], yaw[keep]
        if x.size < MIN_POINTS:
            raise TrajectoryError(f'{source}: {x.size} distinct point(s); a trajectory '
                                  f'needs at least {MIN_POINTS}')
        t = time_law(x, y, cruise_speed, max_accel, source=source)
    return from_waypoints(t, x, y, yaw=yaw, source=source)


# ------------------------------------------------------------------------- files

_COLUMNS = ('t', 'x', 'y', 'yaw', 'speed')


def _rows_to_waypoints(rows: list[dict[str, Any]], source: str) -> Waypoints:
    if not rows:
        raise TrajectoryError(f'{source}: no waypoints')
    cols: dict[str, list[float]] = {}
    names = set(rows[0])
    for req in ('t', 'x', 'y'):
        if req not in names:
            raise TrajectoryError(f'{source}: missing column {req!r}; waypoints need t, x, y '
                                  f'(optional yaw, speed), got {sorted(names)}')
    unknown = names - set(_COLUMNS)
    if unknown:
        raise TrajectoryError(f'{source}: unknown column(s) {sorted(unknown)}; expected '
                              f'{", ".join(_COLUMNS)}')
    for i, row in enumerate(rows):
        if set(row) != names:
            raise TrajectoryError(f'{source}: point {i}: has fields {sorted(row)}, the first '
                                  f'point has {sorted(names)}')
        for k, v in row.items():
            try:
                if isinstance(v, bool):
                    raise ValueError
                f = float(v)
            except (TypeError, ValueError):
                raise TrajectoryError(f'{source}: point {i}: {k} = {v!r} is not a number') \
                    from None
            if not math.isfinite(f):
                raise TrajectoryError(f'{source}: point {i}: {k} = {v!r} is not finite')
            cols.setdefault(k, []).append(f)
    arr = {k: np.asarray(v) for k, v in cols.items()}
    return Waypoints(arr['t'], arr['x'], arr['y'], arr.get('yaw'), arr.get('speed'), source)


def read_waypoint_file(path: str | os.PathLike[str]) -> Waypoints:
    """Read timed waypoints from CSV (header ``t,x,y[,yaw][,speed]``) or YAML.

    YAML: a list of mappings ``{t: .., x: .., y: ..}`` or a mapping with key
    ``waypoints`` holding that list (optional ``frame_id``, which must be ``odom``).
    Lines starting with ``#`` in CSV are comments.

    Parameters
    ----------
    path : str or os.PathLike
        The file (``.csv``, ``.yaml`` or ``.yml``).

    Returns
    -------
    Waypoints

    Raises
    ------
    TrajectoryError
        The file cannot be read or parsed, or a value is bad (the message names it).
    """
    p = FsPath(path)
    source = str(p)
    try:
        text = p.read_text()
    except UnicodeDecodeError:
        raise TrajectoryError(f'{source}: not a text file') from None
    suffix = p.suffix.lower()
    if suffix in ('.yaml', '.yml'):
        import yaml
        try:
            data = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            raise TrajectoryError(f'{source}: not valid YAML: {exc}') from None
        if isinstance(data, dict):
            frame = data.get('frame_id', 'odom')
            if frame != 'odom':
                raise TrajectoryError(f'{source}: frame_id {frame!r}; waypoints must be in the '
                                      'odometry frame \'odom\'')
            data = data.get('waypoints')
        if not isinstance(data, list) or not all(isinstance(r, dict) for r in data):
            raise TrajectoryError(f'{source}: expected a list of {{t, x, y}} mappings (or '
                                  '`waypoints:` holding one)')
        return _rows_to_waypoints(data, source)
    if suffix == '.csv':
        lines = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith('#')]
        reader = csv.reader(io.StringIO('\n'.join(lines)))
        try:
            table = [[c.strip() for c in r] for r in reader]
        except csv.Error as exc:
            raise TrajectoryError(f'{source}: not valid CSV: {exc}') from None
        if not table:
            raise TrajectoryError(f'{source}: empty file; expected a header t,x,y[,yaw][,speed]')
        head = table[0]
        rows = []
        for i, r in enumerate(table[1:]):
            if len(r) != len(head):
                raise TrajectoryError(f'{source}: point {i}: {len(r)} values, the header has '
                                      f'{len(head)} ({",".join(head)})')
            rows.append(dict(zip(head, r)))
        return _rows_to_waypoints(rows, source)
    raise TrajectoryError(f'{source}: unknown waypoint file type {suffix!r}; use .csv or .yaml')


def load_waypoints(path: str | os.PathLike[str], *, ends: str = 'rest',
                   smoothing: float = 0.0) -> Trajectory:
    """Read a waypoint file (:func:`read_waypoint_file`) and build its trajectory.

    Parameters
    ----------
    path : str or os.PathLike
        The file.
    ends : {'rest', 'natural'}
        End conditions of the spline (:func:`from_waypoints`).
    smoothing : float
        Smoothing weight (0: interpolate the points).

    Returns
    -------
    Trajectory
    """
    w = read_waypoint_file(path)
    return from_waypoints(w.t, w.x, w.y, yaw=w.yaw, speed=w.speed, ends=ends,
                          smoothing=smoothing, source=w.source)


def check_frame(frame_id: str, expected: str, source: str) -> None:
    """Raise :class:`.TrajectoryError` unless ``frame_id == expected``.

    Parameters
    ----------
    frame_id : str
        The frame the points are in.
    expected : str
        The frame they must be in.
    source : str
        Where they came from (for the message).
    """
    if frame_id != expected:
        raise TrajectoryError(f'{source}: frame_id {frame_id!r}; the trajectory must be in the '
                              f'odometry frame {expected!r} (no tf here)')


def describe(traj: Trajectory, samples: int = 2001) -> dict[str, Any]:
    """Summary of a bounded trajectory: points, duration, peaks and direction.

    Parameters
    ----------
    traj : Trajectory
        A bounded trajectory.
    samples : int
        Number of samples of the peaks.

    Returns
    -------
    dict
        ``points``, ``kind``, ``t_start``, ``t_end``, ``duration`` (s), ``length`` (m,
        path length), ``peak_speed`` (m/s), ``peak_accel`` (m/s^2), ``peak_turn_rate``
        (rad/s, heading rate while moving faster than 1 cm/s), ``backwards`` (fraction of
        the time driven in reverse), start and end pose.
    """
    if traj.is_analytic:
        raise TrajectoryError(f'{traj.source}: analytic paths are unbounded; nothing to '
                              'summarise')
    ts = np.linspace(traj.t_start, traj.t_end, samples)
    s = traj.evaluate(ts)
    speed = np.hypot(s.vx, s.vy)
    moving = speed[1:] > 0.01
    rate = np.abs(np.diff(np.unwrap(s.heading)) / np.diff(ts))
    seg = np.clip(np.searchsorted(traj.knots, ts, side='right') - 1, 0, len(traj.knots) - 2)
    back = float(np.mean(traj._dir[seg] < 0))
    return dict(points=len(traj.knots), kind=traj.kind, t_start=traj.t_start,
                t_end=traj.t_end, duration=traj.duration,
                length=float(np.sum(np.hypot(np.diff(s.x), np.diff(s.y)))),
                peak_speed=float(speed.max()), peak_accel=float(np.hypot(s.ax, s.ay).max()),
                peak_turn_rate=float(rate[moving].max()) if moving.any() else 0.0,
                backwards=back, start=(float(s.x[0]), float(s.y[0]), float(s.heading[0])),
                end=(float(s.x[-1]), float(s.y[-1]), float(s.heading[-1])))
