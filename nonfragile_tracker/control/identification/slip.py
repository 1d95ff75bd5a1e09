"""Side slip identified: the slide a base's odometry does not see, from an external pose.

A base's encoders and gyro cannot see its body slide sideways in a turn; an external pose
(motion capture, a total station, a simulator's true pose) can.  :func:`identify_side_slip`
fits the side-slip table of :mod:`nonfragile_tracker.control.simulation.slip` (lateral speed
``-c(|w|) v w``, ``c`` piecewise linear in the turn rate) to what separates the two: over
windows of the recording, the external pose's displacement minus the odometry's, each in
its own frame at the window's start, is linear in the table's coefficients.  The result,
:class:`SideSlip`, has 95 % intervals and says whether the slide it explains matters.
Pure numpy, no ROS.

See doc/theory.md, section "Side slip".
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..simulation.slip import hat_basis
from .errors import InsufficientExcitationError, NotEnoughDataError
from .records import OdometrySamples

__all__ = ['SideSlip', 'identify_side_slip', 'DEFAULT_RATES', 'KNOT_REACH', 'WINDOW']

#: Turn rates (rad/s) the table may have: those the recording covers (up to
#: :data:`KNOT_REACH` times its 95th percentile of ``|w|``).  Below the first the
#: coefficient is the first's (the slide ``c v w`` vanishes with ``w`` and a coefficient at
#: 0 rad/s would be fitted from nothing).
DEFAULT_RATES = (0.25, 0.5, 1.0, 2.0, 4.0)
#: A rate up to this factor above the recording's 95th percentile of ``|w|`` is a knot: turns
#: at 0.8 of it weigh its coefficient by 0.6 (from the knot below at half the rate), so it
#: is measured, where the table would otherwise stop at half the turns driven.
KNOT_REACH = 1.25
#: Length (s) of the windows the displacements are compared over.
WINDOW = 0.5
#: Fewest windows to fit from.
MIN_WINDOWS = 12
#: A table is worth compensating if it explains this share of the drift (and a
#: coefficient's interval excludes 0).
MIN_EXPLAINED = 0.2


@dataclass(frozen=True)
class SideSlip:
    """An identified side-slip table (``TrackerConfig.side_slip_rates`` / ``side_slip``).

    ``rates`` (rad/s) and ``coefficients`` (s) with their 95 % intervals ``low``, ``high``;
    ``drift_rms`` and ``residual_rms`` (m): the windows' lateral drift before and after the
    table; ``windows`` fitted; ``significant``: the table explains at least
    :data:`MIN_EXPLAINED` of the drift and a coefficient's interval excludes 0 (worth
    compensating).
    """

    rates: tuple[float, ...]
    coefficients: tuple[float, ...]
    low: tuple[float, ...]
    high: tuple[float, ...]
    drift_rms: float
    residual_rms: float
    windows: int
    significant: bool

    def summary(self) -> str:
        """One line: the table and what it explains."""
        table = ', '.join(f'{r:g} rad/s: {c:.4f} s [{lo:.4f}, {hi:.4f}]' for r, c, lo, hi in
                          zip(self.rates, self.coefficients, self.low, self.high))
        return (f'side slip c(|w|) {table}; window drift {1e3 * self.drift_rms:.2f} -> '
                f'{1e3 * self.residual_rms:.2f} mm rms over {self.windows} windows'
                + ('' if self.significant else ' (not significant: not compensated)'))


def _twist(odometry: OdometrySamples) -> tuple[np.ndarray, np.ndarray]:
    """Body speed and yaw rate: the odometry's twist, else differences of its poses."""
    t, yaw = odometry.t, np.unwrap(odometry.yaw)
    if odometry.v is not None and odometry.w is not None:
        return np.asarray(odometry.v, float), np.asarray(odometry.w, float)
    dt = np.diff(t)
    dx, dy = np.diff(odometry.x), np.diff(odometry.y)
    mid = yaw[:-1] + 0.5 * np.diff(yaw)
    v = (dx * np.cos(mid) + dy * np.sin(mid)) / dt
    w = np.diff(yaw) / dt
    return np.r_[v[:1], v], np.r_[w[:1], w]


def identify_side_slip(odometry: OdometrySamples, truth: OdometrySamples, *,
                       window: float = WINDOW,
                       rates: tuple[float, ...] = DEFAULT_RATES) -> SideSlip:
    """Fit the side-slip table to the external pose ``truth`` against ``odometry``.

    Parameters
    ----------
    odometry : OdometrySamples
        The base's odometry (its twist if it has one, else its pose differences give speed
        and yaw rate).
    truth : OdometrySamples
        An external pose of the same base on the same clock (any rate; interpolated to the
        odometry's times; its frame may differ from the odometry's by a rigid motion).
    window : float
        Window length (s).
    rates : tuple of float
        Candidate turn rates of the table (rad/s, increasing); those up to
        :data:`KNOT_REACH` times the recording's 95th percentile of ``|w|`` are kept.

    Returns
    -------
    SideSlip

    Raises
    ------
    NotEnoughDataError
        If the two overlap for fewer than :data:`MIN_WINDOWS` windows.
    InsufficientExcitationError
        If the base turned too little (95 % of ``|w|`` below ``rates[0]``).
    """
    t = np.asarray(odometry.t, float)
    tt = np.asarray(truth.t, float)
    if t.size < 3 or tt.size < 3 or np.any(np.diff(t) <= 0) or np.any(np.diff(tt) <= 0):
        raise NotEnoughDataError('side slip: the odometry and the external pose need at least '
                                 '3 samples each, with increasing stamps')
    inside = (t >= tt[0]) & (t <= tt[-1])
    v, w = _twist(odometry)
    t, v, w = t[inside], v[inside], w[inside]
    x, y = np.asarray(odometry.x, float)[inside], np.asarray(odometry.y, float)[inside]
    th = np.unwrap(np.asarray(odometry.yaw, float))[inside]
    tx, ty = np.interp(t, tt, truth.x), np.interp(t, tt, truth.y)
    tth = np.interp(t, tt, np.unwrap(truth.yaw))
    span = float(t[-1] - t[0]) if t.size else 0.0
    n_win = int(span // window)
    if n_win < MIN_WINDOWS:
        raise NotEnoughDataError(f'side slip: the odometry and the external pose overlap for '
                                 f'{span:.2f} s, {n_win} windows of {window} s; record at '
                                 f'least {MIN_WINDOWS * window:g} s of driving with both')
    q95 = float(np.quantile(np.abs(w), 0.95))
    knots = tuple(r for r in rates if r <= KNOT_REACH * q95)
    if not knots:
        raise InsufficientExcitationError(
            f'side slip: the base turned too little (95 % of |w| below {q95:.3f} rad/s); '
            f'drive turns of at least {rates[0] / KNOT_REACH:g} rad/s while the external pose '
            'is recorded')
    # per interval, the lateral slide of a unit coefficient j, in the odometry frame
    dt = np.diff(t)
    mid = th[:-1] + 0.5 * np.diff(th)
    vw = 0.5 * (v[:-1] * w[:-1] + v[1:] * w[1:])
    basis = 0.5 * (hat_basis(knots, w[:-1]) + hat_basis(knots, w[1:]))
    lat = -(vw * dt)[:, None] * basis                            # (intervals, knots)
    gx, gy = -lat * np.sin(mid)[:, None], lat * np.cos(mid)[:, None]
    cgx = np.vstack([np.zeros(len(knots)), np.cumsum(gx, axis=0)])
    cgy = np.vstack([np.zeros(len(knots)), np.cumsum(gy, axis=0)])
    edges = np.searchsorted(t, t[0] + window * np.arange(n_win + 1))
    edges = np.minimum(edges, t.size - 1)
    i0, i1 = edges[:-1], edges[1:]
    keep = i1 > i0
    i0, i1 = i0[keep], i1[keep]
    c0, s0 = np.cos(th[i0]), np.sin(th[i0])
    ct, st = np.cos(tth[i0]), np.sin(tth[i0])
    dxo, dyo = x[i1] - x[i0], y[i1] - y[i0]
    dxt, dyt = tx[i1] - tx[i0], ty[i1] - ty[i0]
    # each displacement in its own frame at the window's start (a rigid offset cancels)
    b = np.r_[(ct * dxt + st * dyt) - (c0 * dxo + s0 * dyo),
              (-st * dxt + ct * dyt) - (-s0 * dxo + c0 * dyo)]
    mx, my = cgx[i1] - cgx[i0], cgy[i1] - cgy[i0]
    A = np.vstack([c0[:, None] * mx + s0[:, None] * my, -s0[:, None] * mx + c0[:, None] * my])
    coef, *_ = np.linalg.lstsq(A, b, rcond=None)
    resid = b - A @ coef
    dof = max(1, b.size - len(knots))
    s2 = float(resid @ resid) / dof
    cov = s2 * np.linalg.pinv(A.T @ A)
    half = 1.96 * np.sqrt(np.maximum(np.diag(cov), 0.0))
    drift = math.sqrt(float(np.mean(b[b.size // 2:] ** 2)))          # the lateral part
    res = math.sqrt(float(np.mean(resid[resid.size // 2:] ** 2)))
    significant = bool(res <= (1.0 - MIN_EXPLAINED) * drift and
                       np.any(np.abs(coef) > half))
    return SideSlip(rates=knots, coefficients=tuple(map(float, coef)),
                    low=tuple(map(float, coef - half)), high=tuple(map(float, coef + half)),
                    drift_rms=drift, residual_rms=res, windows=int(i0.size),
                    significant=significant)
