"""The FOPDT fit of :func:`~nonfragile_tracker.control.identification.identify.identify_latency`.

One command-to-motion latency shared by the channels ``v`` and ``w``, a first-order lag
and a static gain per channel, fitted to the measurements on a fine time grid by linear
least squares for all delays at once, then polished together (:class:`Fit`); the models
of what real recordings add - speed saturation, acceleration limits (a rate-limited
response), gross errors left out, latency jitter (each command step fitted on its own).
The model and the estimation are in doc/theory.md, section "Latency identification".

Nothing here imports ROS; numpy and scipy only.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, cast

import numpy as np


__all__ = ['Fit', 'FitData', 'Measurement', 'binding_fraction', 'CHANNELS', 'NAMES',
           'UNITS', 'ACCEL_UNITS', 'MIN_BINDING', 'MIN_EVENTS', 'JITTER_REFIT_S',
           'RAMP_FIRST_GAIN', 'JITTER_GAIN']

#: An acceleration limit is identified only if it binds at least this fraction of the time.
MIN_BINDING = 0.02
#: A spread of the step latencies (2.5-97.5 %) above this (s) is jitter: the lags are
#: then refitted with every step at the time it acted.
JITTER_REFIT_S = 0.005
#: ... and kept only if it lowers the normalized residual below this fraction of the
#: one-delay fit's (a spread from noise does not).
JITTER_GAIN = 0.8
#: The limit is placed before the lag (the command ramped first) only if that lowers the
#: limited fit's residual below this fraction of the rate-limited lag's.
RAMP_FIRST_GAIN = 0.8
#: Fewest command steps fitted one by one for a measured latency range.
MIN_EVENTS = 10
#: The channels: linear speed and yaw rate.
CHANNELS = ('v', 'w')
#: Each channel's unit, its name in messages and its acceleration's unit.
UNITS = {'v': 'm/s', 'w': 'rad/s'}
NAMES = {'v': 'linear speed v', 'w': 'yaw rate w'}
ACCEL_UNITS = {'v': 'm/s^2', 'w': 'rad/s^2'}


#: One channel's measurements: (index a, index b or None, width or None, z, mid time) into
#: the odometry (a point sample reads index a; a pose window differences a and b).
Measurement = tuple[np.ndarray, np.ndarray | None, np.ndarray | None, np.ndarray, np.ndarray]


def _held_integral(tc: np.ndarray, u: np.ndarray, s: np.ndarray,
                   timeout: float | None) -> np.ndarray:
    """Integral from tc[0] to s of the zero-order hold of (tc, u) (0 after a timeout)."""
    if timeout is not None:
        gaps = np.diff(tc)
        ends = np.append(tc[:-1][gaps > timeout], tc[-1]) + timeout
        tc = np.concatenate([tc, ends])
        u = np.concatenate([u, np.zeros(ends.size)])
        order = np.argsort(tc, kind='stable')
        tc, u = tc[order], u[order]
    cum = np.concatenate([[0.0], np.cumsum(u[:-1] * np.diff(tc))])
    j = np.clip(np.searchsorted(tc, s, side='right') - 1, 0, tc.size - 1)
    return cast(np.ndarray, cum[j] + u[j] * (s - tc[j]))


class _Channel:
    """One channel: cell-averaged input on the grid and its measurements.

    ``pos`` are the grid positions (fractional steps) of the odometry times
    used; a point measurement ``i`` reads position ``ia[i]``, a window
    measurement the difference of the integral between ``ia[i]`` and ``ib[i]``
    divided by ``width[i]`` (s).
    """

    def __init__(self, name: str, source: str, u_avg: np.ndarray, h: float, z: np.ndarray,
                 pos: np.ndarray, ia: np.ndarray, ib: np.ndarray | None,
                 width: np.ndarray | None, t_mid: np.ndarray):
        self.name, self.source = name, source
        self.u_avg, self.h = u_avg, h
        self.z, self.pos, self.ia, self.ib = z, pos, ia, ib
        self.width, self.t_mid = width, t_mid
        self.sigma2 = 1.0
        self.accel = 0.0            # acceleration limit of the model (0: none, linear)
        #: The limit's place: False, the lag's rate saturates (a rate-limited lag); True, the
        #: command is ramped first and the ramp lagged (a firmware's setpoint ramp in front
        #: of its wheel-speed loop)
        self.ramp_first = False

    @classmethod
    def build(cls, name: str, source: str, u_avg: np.ndarray, h: float, z: np.ndarray,
              pos_all: np.ndarray, ia: np.ndarray, ib: np.ndarray | None,
              width: np.ndarray | None, t_mid: np.ndarray) -> '_Channel':
        """Keep only the positions the measurements use."""
        need = ia if ib is None else np.concatenate([ia, ib])
        keep, inv = np.unique(need, return_inverse=True)
        ja = inv[:ia.size]
        jb = None if ib is None else inv[ia.size:]
        return cls(name, source, u_avg, h, z, pos_all[keep], ja, jb, width, t_mid)

    def subset(self, stride: int) -> '_Channel':
        """Every ``stride``-th measurement (for the coarse search)."""
        sl = slice(None, None, stride)
        sub = _Channel.build(self.name, self.source, self.u_avg, self.h, self.z[sl], self.pos,
                             self.ia[sl], None if self.ib is None else self.ib[sl],
                             None if self.width is None else self.width[sl], self.t_mid[sl])
        sub.accel, sub.ramp_first = self.accel, self.ramp_first
        return sub

    def signals(self, tau: float) -> tuple[np.ndarray, np.ndarray]:
        """Forced (zero initial state) and free (unit initial state) responses on the grid.

        With an acceleration limit (``accel > 0``) the forced response is the
        rate-limited lag's (nonlinear; the free response stays the linear one).
        """
        from scipy.signal import lfilter      # here: scipy.signal costs ~0.8 s to import
        n = self.u_avg.size + 1
        a = math.exp(-self.h / tau) if tau > 0 else 0.0
        if self.accel > 0 and self.ramp_first:
            forced = np.empty(n)
            forced[0] = 0.0
            forced[1:] = lfilter([1.0 - a], [1.0, -a],
                                 _ramp_limited_input(self.u_avg, self.h, self.accel))
        elif self.accel > 0:
            forced = _rate_limited_response(self.u_avg, self.h, tau, self.accel)
        else:
            forced = np.empty(n)
            forced[0] = 0.0
            forced[1:] = lfilter([1.0 - a], [1.0, -a], self.u_avg)
        if a > 0:
            k = np.arange(n, dtype=float)
            with np.errstate(under='ignore'):
                free = np.exp(k * math.log(a))
        else:
            free = np.zeros(n)
            free[0] = 1.0
        if self.ib is not None:                 # window measurements: integrate on the grid
            forced = _cumtrapz(forced, self.h)
            free = _cumtrapz(free, self.h)
        return forced, free

    def regressors(self, sig: np.ndarray, shifts: np.ndarray, n: int | None = None
                   ) -> np.ndarray:
        """The measurement functional of ``sig`` delayed by ``shifts`` (grid steps), (nd, ns).

        With ``n``, only for the first ``n`` measurements.
        """
        ia = self.ia if n is None else self.ia[:n]
        ib = None if self.ib is None else (self.ib if n is None else self.ib[:n])
        last = int(max(ia.max(initial=-1), -1 if ib is None else ib.max(initial=-1))) + 1
        vals = _interp_shifted(sig, self.pos[:last], shifts)
        if ib is None:
            return vals[:, ia]
        width = cast(np.ndarray, self.width)     # set whenever ib is
        width = width if n is None else width[:n]
        return cast(np.ndarray, (vals[:, ib] - vals[:, ia]) / width)


def _cumtrapz(y: np.ndarray, h: float) -> np.ndarray:
    out = np.empty_like(y)
    out[0] = 0.0
    np.cumsum(0.5 * h * (y[1:] + y[:-1]), out=out[1:])
    return out


def _interp_shifted(sig: np.ndarray, pos: np.ndarray, shifts: np.ndarray) -> np.ndarray:
    """``sig`` linearly interpolated at ``pos - shift`` for every shift: (nd, ns)."""
    whole = np.floor(shifts)
    if np.all(whole == shifts):                      # integer shifts: one fraction per sample
        base = np.floor(pos)
        f = (pos - base)[None, :]
        i0 = base.astype(np.int64)[None, :] - whole.astype(np.int64)[:, None]
    else:
        p = pos[None, :] - shifts[:, None]
        i0 = np.floor(p)
        f = p - i0
        i0 = i0.astype(np.int64)
    np.clip(i0, 0, sig.size - 2, out=i0)
    lo = sig[i0]
    return cast(np.ndarray, lo + (sig[i0 + 1] - lo) * f)


def _stats(ch: _Channel, tau: float, shifts: np.ndarray, blocks: np.ndarray | None,
           n_blocks: int) -> np.ndarray:
    """Least-squares sufficient statistics per shift: (nd, 5[, n_blocks]).

    Entries: S11, S12, S22, S1z, S2z (regressor 1 = forced, 2 = free response).
    With ``blocks`` (block index per measurement, non-decreasing) they are summed per
    bootstrap block (last axis).  The free response decays as exp(-t / tau): it is
    evaluated only for the leading measurements where it is not yet below 1e-17.
    """
    forced, free = ch.signals(tau)
    m1 = ch.regressors(forced, shifts)
    k_cut = 1.0 if tau <= 0 else 40.0 * tau / ch.h        # exp(-40) ~ 4e-18
    n_free = int(np.searchsorted(ch.pos[ch.ia], k_cut + float(np.max(shifts)), side='right'))
    m2 = ch.regressors(free, shifts, n_free)
    z = ch.z[None, :]
    z2 = z[:, :n_free]
    m1f = m1[:, :n_free]
    prods = (m1 * m1, m1f * m2, m2 * m2, m1 * z, m2 * z2)
    if blocks is None:
        return np.stack([p.sum(axis=1) for p in prods], axis=1)
    bounds = np.searchsorted(blocks, np.arange(n_blocks + 1), side='left')
    return np.stack([_block_sums(p, np.minimum(bounds, p.shape[1])) for p in prods], axis=1)


def _block_sums(p: np.ndarray, bounds: np.ndarray) -> np.ndarray:
    """Sums of the columns of ``p`` between consecutive ``bounds``: (rows, len(bounds) - 1)."""
    cs = np.zeros((p.shape[0], p.shape[1] + 1))
    np.cumsum(p, axis=1, out=cs[:, 1:])
    return cs[:, bounds[1:]] - cs[:, bounds[:-1]]


def _sse(st: np.ndarray, zz: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
    """Residual sum of squares and gain of the 2-regressor fit from statistics (..., 5)."""
    s11, s12, s22, s1z, s2z = (st[..., i] for i in range(5))
    det = s11 * s22 - s12 * s12
    ok = det > 1e-12 * np.maximum(s11 * s22, 1e-300)
    with np.errstate(divide='ignore', invalid='ignore'):
        g2 = np.where(ok, (s22 * s1z - s12 * s2z) / np.where(ok, det, 1.0),
                      s1z / np.maximum(s11, 1e-300))
        c2 = np.where(ok, (s11 * s2z - s12 * s1z) / np.where(ok, det, 1.0), 0.0)
    sse = zz - g2 * s1z - c2 * s2z
    return np.maximum(sse, 0.0), g2


def _parabola_min(values: np.ndarray, i: int) -> float:
    """Sub-grid offset (in grid steps, within +-0.5) of the minimum at index ``i``."""
    if i <= 0 or i >= values.size - 1:
        return 0.0
    a, b, c = values[i - 1], values[i], values[i + 1]
    den = a - 2 * b + c
    if not den > 0:
        return 0.0
    return float(np.clip(0.5 * (a - c) / den, -0.5, 0.5))


def _rate_limited_response(u: np.ndarray, h: float, tau: float, accel: float) -> np.ndarray:
    """Grid values of ``s' = sat((u - s) / tau, accel)`` from rest, ``u`` held per cell.

    Exact (the closed form of :func:`.actuator.first_order_step`: a ramp at ``accel``
    while ``|u - s| > accel tau``, then the exponential approach).  The state is carried
    in Python from one run of equal inputs (to 1e-9 relative) to the next; the values
    inside the runs are filled in by numpy.
    """
    n = u.size
    out = np.empty(n + 1)
    out[0] = 0.0
    if n == 0:
        return out
    # runs of equal inputs: cell averages of one held command differ by round-off only
    # (differences of a cumulative integral), so equal means within 1e-9 relative
    tol = 1e-9 * max(1.0, float(np.max(np.abs(u))))
    starts = np.concatenate([[0], np.flatnonzero(np.abs(np.diff(u)) > tol) + 1])
    lens = np.diff(np.append(starts, n))
    cs = u[starts]
    runs = starts.size
    s0, sg, t1, s1 = np.empty(runs), np.empty(runs), np.empty(runs), np.empty(runs)
    band = accel * tau
    s = 0.0
    for r, (c, m) in enumerate(zip(cs.tolist(), lens.tolist())):
        span = m * h
        s0[r] = s
        d = c - s
        if d > band or d < -band:
            g = 1.0 if d > 0 else -1.0
            ramp = (abs(d) - band) / accel           # time to reach the linear band
            sg[r] = g
            if ramp >= span:
                t1[r], s1[r] = span, c
                s += g * accel * span
            else:
                t1[r], s1[r] = ramp, c - g * band
                s = c - g * band * (math.exp(-(span - ramp) / tau) if tau > 0 else 0.0)
        else:
            sg[r], t1[r], s1[r] = 0.0, 0.0, s
            s = c - d * (math.exp(-span / tau) if tau > 0 else 0.0)
    idx = np.repeat(np.arange(runs), lens)
    t = (np.arange(n) - starts[idx] + 1) * h
    end_ramp = t1[idx]
    level = cs[idx]
    if tau > 0:
        tail = level - (level - s1[idx]) * np.exp(-np.maximum(t - end_ramp, 0.0) / tau)
    else:
        tail = level
    out[1:] = np.where(t <= end_ramp, s0[idx] + sg[idx] * accel * t, tail)
    return out


def _ramp_limited_input(u: np.ndarray, h: float, accel: float) -> np.ndarray:
    """Cell averages of ``u`` (held per cell) through a rate limiter ``|r'| <= accel`` from rest.

    Per run of equal inputs the ramp is closed form (towards the run's value at ``accel``,
    then held); a cell's average is taken at its midpoint (exact but in the cell where the
    ramp ends).
    """
    n = u.size
    if n == 0:
        return np.empty(0)
    tol = 1e-9 * max(1.0, float(np.max(np.abs(u))))
    starts = np.concatenate([[0], np.flatnonzero(np.abs(np.diff(u)) > tol) + 1])
    lens = np.diff(np.append(starts, n))
    cs = u[starts]
    r0 = np.empty(starts.size)
    r = 0.0
    for i, (c, m) in enumerate(zip(cs.tolist(), lens.tolist())):
        r0[i] = r
        step = accel * m * h
        r = c if abs(c - r) <= step else r + math.copysign(step, c - r)
    idx = np.repeat(np.arange(starts.size), lens)
    t = (np.arange(n) - starts[idx] + 0.5) * h
    level, first = cs[idx], r0[idx]
    return cast(np.ndarray, first + np.clip(level - first, -accel * t, accel * t))


def _fit_gain(ch: _Channel, pos: float, tau: float) -> float:
    """The static gain of the channel's fit at grid position ``pos``."""
    return float(_sse(_stats(ch, tau, np.array([pos]), None, 0), float(ch.z @ ch.z))[1][0])


def _choose_limits(chans: dict[str, '_Channel'], latency: float, tau_hat: dict[str, float],
                   max_tau_s: float, max_latency_s: float
                   ) -> tuple[dict[str, float], dict[str, float]]:
    """Per channel, the acceleration limit of a rate-limited FOPDT, or 0 if none explains more.

    Candidates around a high percentile (99 %) of the measured ``|ds/dt|`` (over 40 ms),
    each fitted over a local grid of latencies (the linear fit's ``pos`` - 0.1 s to
    + 0.03 s: a binding limit makes the linear fit late) and time constants, in both places
    of the limit (``_Channel.ramp_first``: the lag's rate saturating, or the command ramped
    before the lag as a firmware ramps its wheel-speed setpoint - fitted as the other, such
    a base's limit comes out 25-30 % low); a limit is kept only if it lowers the residual by
    at least 5 % and binds at least :data:`MIN_BINDING` of the time; its value is refined by
    a parabola in ``log a`` through the best candidate and its neighbours.  Returns the
    limits of either place (0: none); :meth:`Fit.model_limits` chooses on the full fits.
    """
    out: dict[str, float] = {}
    first: dict[str, float] = {}
    for c, ch in chans.items():
        h = ch.h
        z, tm = ch.z, ch.t_mid
        dtm = float(np.median(np.diff(tm))) if tm.size > 1 else h
        lag = max(1, int(round(0.04 / max(dtm, 1e-9))))
        out[c] = first[c] = 0.0
        if z.size <= lag + 10:
            continue
        slope = np.abs(z[lag:] - z[:-lag]) / np.maximum(tm[lag:] - tm[:-lag], 1e-9)
        a0 = float(np.percentile(slope, 99))
        if not a0 > 0:
            continue
        sub = ch.subset(max(1, z.size // 800))
        zz = float(sub.z @ sub.z)
        lo = max(0, int(round((latency - 0.1) / h)))
        shifts = np.arange(lo, int(round(min(max_latency_s, latency + 0.03) / h)) + 1,
                           dtype=float)
        grid = np.concatenate([[0.0], np.geomspace(0.002,
                                                   min(max_tau_s, 1.5 * tau_hat[c] + 0.02), 8)])
        factors = 2.0 ** (np.arange(-4, 3) / 3.0)
        cands = np.concatenate([[0.0], a0 * factors])

        def fitted(a: float, ramp_first: bool) -> tuple[float, float]:
            sub.accel, sub.ramp_first = float(a), ramp_first
            per_tau = [float(_sse(_stats(sub, tau, shifts, None, 0), zz)[0].min())
                       for tau in grid]
            k = int(np.argmin(per_tau))
            return per_tau[k], float(grid[k])

        none = fitted(0.0, False)[0]
        for ramp_first in (False, True):
            res = [fitted(a, ramp_first) for a in cands[1:]]
            sse = np.array([none] + [r[0] for r in res])
            i = int(np.argmin(sse))
            if i == 0 or not sse[i] < 0.95 * none:
                continue
            la = np.log(cands[1:])
            j = i - 1
            off = _parabola_min(sse[1:], j) if 0 < j < la.size - 1 else 0.0
            a = float(np.exp(la[j] + off * (la[1] - la[0])))
            # a limit that binds for a moment only (the steepest steps of a plain lag) is
            # not one: at least MIN_BINDING of the time
            ch.accel, ch.ramp_first = a, ramp_first
            binds = binding_fraction(ch, float(res[j][1]), 0.0, 0.0, ch.u_avg.size * ch.h)
            ch.accel, ch.ramp_first = 0.0, False
            if binds >= MIN_BINDING:
                (first if ramp_first else out)[c] = a
        sub.accel, sub.ramp_first = 0.0, False
    return out, first


def _speed_saturation(chans: dict[str, _Channel], pos: float, tau_hat: dict[str, float]
                      ) -> dict[str, tuple[float, float, float]]:
    """Channels whose base saturates below the commands: ``{c: (low, high, fraction)}``.

    The measured range is the 0.5-99.5 % percentiles of the measured speed; a channel
    saturates when at least 2 % of the commands lie beyond it by more than a tenth of
    its width and clipping the commands to it lowers the residual by at least 5 %
    (fitted over latencies within 20 grid steps of ``pos`` and a grid of lags).
    """
    out = {}
    for c, ch in chans.items():
        lo, hi = (float(x) for x in np.percentile(ch.z, [0.5, 99.5]))
        margin = 0.1 * (hi - lo)
        u = ch.u_avg
        frac = float(np.mean((u > hi + margin) | (u < lo - margin)))
        if frac < 0.02:
            continue
        shifts = np.arange(max(0.0, round(pos) - 20), round(pos) + 21)
        grid = np.concatenate([[0.0], np.geomspace(0.002, max(2 * tau_hat[c], 0.02), 8)])
        sub = ch.subset(max(1, ch.z.size // 800))
        zz = float(sub.z @ sub.z)

        def best(chn: _Channel) -> float:
            return min(float(_sse(_stats(chn, tau, shifts, None, 0), zz)[0].min())
                       for tau in grid)

        clipped = _Channel.build(c, sub.source, np.clip(u, lo, hi), sub.h, sub.z, sub.pos,
                                 sub.ia, sub.ib, sub.width, sub.t_mid)
        if best(clipped) < 0.95 * best(sub):
            out[c] = (lo, hi, frac)
    return out


def binding_fraction(ch: _Channel, tau: float, pos: float, t0: float, t1: float) -> float:
    """Fraction of ``[t0, t1]`` (s after the first command) in which the limit binds.

    Parameters
    ----------
    ch : _Channel
        A channel of ``Fit.chans`` (its acceleration limit ``accel``; 0: none).
    tau : float
        Its time constant (s).
    pos : float
        The latency in grid steps.
    t0, t1 : float
        The span (s after the first command).

    Returns
    -------
    float
    """
    if ch.accel <= 0:
        return 0.0
    sig = (np.concatenate([[0.0], _ramp_limited_input(ch.u_avg, ch.h, ch.accel)])
           if ch.ramp_first else _rate_limited_response(ch.u_avg, ch.h, tau, ch.accel))
    rate = np.abs(np.diff(sig)) / ch.h
    a = max(0, int(t0 / ch.h - pos))
    b = max(a + 1, min(rate.size, int(t1 / ch.h - pos)))
    return float(np.mean(rate[a:b] >= 0.999 * ch.accel))


def _fitted(ch: _Channel, pos: float, tau: float) -> np.ndarray:
    """The fitted values of the channel's measurements (gain and free response fitted)."""
    forced, free = ch.signals(tau)
    m1 = ch.regressors(forced, np.array([pos]))[0]
    m2 = ch.regressors(free, np.array([pos]))[0]
    a = np.stack([m1, m2], axis=1)
    coef = np.linalg.lstsq(a, ch.z, rcond=None)[0]
    return cast(np.ndarray, a @ coef)


def _gross_errors(chans: dict[str, _Channel], pos: float, tau_hat: dict[str, float],
                  meas: dict[str, Measurement], keep: dict[str, np.ndarray] | None,
                  t_begin: float,
                  t_end: float, tau_max: float
                  ) -> tuple[dict[str, np.ndarray], list[tuple[float, float]]] | None:
    """Spans where the motion does not follow the fitted model at all, and the samples kept.

    A residual counts as gross when it exceeds both 6 robust standard deviations
    (1.4826 x MAD) and a quarter of the channel's measured standard deviation; each is
    widened by 0.2 s + 3 time constants either side (the base recovers through its
    lag).  None when there is none, or when the spans would cover more than 30 % of the
    fitted time (then the model, not a segment, is wrong: the fit figures say so).
    """
    times = []
    for c, ch in chans.items():
        r = ch.z - _fitted(ch, pos, tau_hat[c])
        mad = 1.4826 * float(np.median(np.abs(r - np.median(r))))
        thr = max(6.0 * mad, 0.25 * float(np.std(ch.z)))
        times.append(ch.t_mid[np.abs(r) > thr])
    flagged = np.sort(np.concatenate(times))
    if flagged.size == 0:
        return None
    pad = 0.2 + 3.0 * tau_max
    spans: list[list[float]] = []
    for t in flagged:
        if spans and t - pad <= spans[-1][1]:
            spans[-1][1] = t + pad
        else:
            spans.append([t - pad, t + pad])
    new_keep = {}
    for c in chans:
        ia, ib, wd, z, tm = meas[c]
        ok = np.ones(z.size, dtype=bool) if keep is None else keep[c].copy()
        half = 0.0 if wd is None else 0.5 * wd
        for a, b in spans:
            ok &= ~((tm + half >= a) & (tm - half <= b))
        new_keep[c] = ok
    excluded = _spans_of(meas, new_keep)
    total = sum(b - a for a, b in excluded)
    if total > 0.3 * (t_end - t_begin):
        return None
    if keep is not None and all(np.array_equal(new_keep[c], keep[c]) for c in chans):
        return None
    return new_keep, excluded


def _spans_of(meas: dict[str, Measurement], keep: dict[str, np.ndarray]
              ) -> list[tuple[float, float]]:
    """Time spans (between kept samples) that hold excluded samples.

    From the first channel (both channels exclude the same spans).
    """
    out: list[tuple[float, float]] = []
    for c in CHANNELS:
        tm = meas[c][4]
        k = keep[c]
        i = 0
        while i < k.size:
            if k[i]:
                i += 1
                continue
            j = i
            while j < k.size and not k[j]:
                j += 1
            a = tm[i - 1] if i > 0 else tm[i]
            b = tm[j] if j < k.size else tm[j - 1]
            out.append((float(a), float(b)))
            i = j
        break
    return out


def _event_latencies(chans: dict[str, _Channel], pos: float, tau_hat: dict[str, float],
                     tc: np.ndarray, cmd: dict[str, np.ndarray], t_begin: float,
                     t_end: float, excluded: list[tuple[float, float]]
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The latency (grid positions) of each distinct command step, fitted one by one.

    Returns the latencies and, per step, the index of its command and of the next step's
    (the commands ``first[k]:last[k]`` act with latency ``k``).

    A step is a command change of at least 20 % of the channel's 5-95 % range, at least
    max(0.15 s, 4 time constants) after the previous one; its latency minimizes the
    residual of the fitted model, shifted, over the samples from 40 ms before its
    expected response to the next step (at most 0.5 s), both channels where both step
    (each normalized by its noise variance).  Shifts within +-60 ms of ``pos``; a
    minimum at the edge of that window is not used.
    """
    h = chans['v'].h
    half = int(round(0.06 / h))
    centre = int(round(pos))
    shifts = np.arange(max(0, centre - half), centre + half + 1, dtype=float)
    res = {}
    for c, ch in chans.items():
        forced, _ = ch.signals(tau_hat[c])
        g = _fit_gain(ch, pos, tau_hat[c])
        r = ch.z[None, :] - g * ch.regressors(forced, shifts)
        res[c] = r * r / ch.sigma2
    sig = {}
    for c in CHANNELS:
        u = cmd[c]
        lo, hi = np.percentile(u, [5, 95])
        du = np.abs(np.diff(u, prepend=u[0]))
        sig[c] = du >= 0.2 * max(hi - lo, 1e-12)
    any_step = np.flatnonzero(sig['v'] | sig['w'])
    settle = max(0.15, 4 * max(tau_hat.values()))
    lat = pos * h
    out: list[float] = []
    first: list[int] = []
    last: list[int] = []
    for n, i in enumerate(any_step):
        t_i = tc[i]
        if n > 0 and t_i - tc[any_step[n - 1]] < settle:
            continue
        nxt = tc[any_step[n + 1]] if n + 1 < any_step.size else t_i + 0.5
        a, b = t_i + lat - 0.04, t_i + lat + min(nxt - t_i, 0.5)
        if a < t_begin or b > t_end or any(x < b and a < y for x, y in excluded):
            continue
        total = np.zeros(shifts.size)
        used = 0
        for c, ch in chans.items():
            if not sig[c][i]:
                continue
            sel = (ch.t_mid >= a) & (ch.t_mid <= b)
            if np.count_nonzero(sel) < 3:
                continue
            total += res[c][:, sel].sum(axis=1)
            used += 1
        if not used:
            continue
        k = int(np.argmin(total))
        if k == 0 or k == shifts.size - 1:
            continue
        out.append(float(shifts[k]) + _parabola_min(total, k))
        first.append(int(i))
        last.append(int(any_step[n + 1]) if n + 1 < any_step.size else tc.size)
    return np.array(out), np.array(first, dtype=np.int64), np.array(last, dtype=np.int64)


@dataclass
class FitData:
    """The samples of a run, sorted and gated into what the fit uses (see ``_gather``).

    ``tc``, ``cmd``: the commands by time; ``to``: the odometry times; ``use``: each
    channel's source (``twist`` or ``pose``); ``meas``: each channel's measurements in
    the fitted span ``[t_begin, t_end]`` (:data:`Measurement`); ``block_len``,
    ``n_blocks``: the bootstrap's blocks over it.
    """

    tc: np.ndarray
    cmd: dict[str, np.ndarray]
    to: np.ndarray
    odom_rate: float
    use: dict[str, str]
    meas: dict[str, Measurement]
    t_begin: float
    t_end: float
    duration: float
    block_len: float
    n_blocks: int
    notes: list[str] = field(default_factory=list)
    #: Channels whose twist does not integrate to the poses (-> the finding): measured from
    #: the poses instead (``source='auto'``).
    disagree: dict[str, str] = field(default_factory=dict)


class Fit:
    """The FOPDT fit of a run: the grid, the channels and the current estimate.

    The held commands are cell-averaged on a grid of step ``h`` (``u_grid``);
    ``_make_channels`` builds the channels (``_Channel``) from them and the
    measurements (``keep``: the samples left after exclusions), :meth:`search` fits
    ``(latency, tau_v, tau_w)`` on the current channels ``chans``.  The estimate is
    ``pos`` (the latency in grid steps), ``tau_hat``, ``lat_c`` (each channel's own
    latency) and ``accel`` (the acceleration limits); the ``model_*`` stages refit it
    where the recording needs a richer model and add their ``notes``.
    """

    def __init__(self, data: FitData, h: float, max_latency_s: float, max_tau_s: float,
                 command_timeout_s: float | None):
        """Build the grid and the channels of the linear model (no fit yet).

        Parameters
        ----------
        data : FitData
            The gathered samples.
        h : float
            Grid step (s).
        max_latency_s, max_tau_s : float
            Search limits of the latency and the time constants (s).
        command_timeout_s : float or None
            A command stops being held (input 0) this long (s) after it was sent
            without a newer one (a base with a cmd_vel watchdog); ``None``: held.
        """
        self.data, self.h = data, h
        self.notes = data.notes
        self.max_latency_s, self.max_tau_s = max_latency_s, max_tau_s
        self.command_timeout_s = command_timeout_s
        tc, t_end = data.tc, data.t_end
        # -- the grid: cell averages of the held commands
        n_cells = int(math.ceil((t_end - tc[0]) / h)) + 2
        self.s = tc[0] + h * np.arange(n_cells + 1)
        self.u_grid = {c: np.diff(_held_integral(tc, data.cmd[c], self.s, command_timeout_s))
                       / h for c in CHANNELS}
        self.odom_pos = (data.to - tc[0]) / h
        # the rate-limited model costs a Python pass over the grid per simulation: its
        # coarse stages run on a grid of at most 5 ms (the coarse latency step is 10 ms)
        self.hc = h * max(1, int(round(0.005 / h))) if h < 0.005 else h
        self.coarse_inputs: dict[str, np.ndarray] = {}
        self.no_limit = {c: 0.0 for c in CHANNELS}
        #: Each channel's place of its limit (``_Channel.ramp_first``).
        self.ramp_first: dict[str, bool] = {c: False for c in CHANNELS}
        self.keep: dict[str, np.ndarray] | None = None
        self.chans = self._make_channels(None, self.no_limit)
        self.d_max = int(round(max_latency_s / h))
        self.taus = np.concatenate([[0.0], np.geomspace(max(2 * h, 0.002), max_tau_s, 24)])
        self.step = max(1, int(round(0.01 / h)))
        self.coarse_all = np.arange(0, self.d_max + 1, self.step, dtype=float)
        self.clips: dict[str, tuple[float, float, float]] = {}
        self.pos = 0.0
        self.tau_hat: dict[str, float] = {}
        self.lat_c: dict[str, float] = {}
        self.accel: dict[str, float] = dict(self.no_limit)

    def _make_channels(self, keep: dict[str, np.ndarray] | None, accel: dict[str, float],
                      hh: float | None = None) -> dict[str, _Channel]:
        """The channels on the grid (``hh``: a coarser one) with the samples ``keep``."""
        h, data = self.h, self.data
        hh = h if hh is None else hh
        tc, cmd = data.tc, data.cmd
        out = {}
        if hh != h and not self.coarse_inputs:
            sc = tc[0] + hh * np.arange(int(math.ceil((data.t_end - tc[0]) / hh)) + 3)
            self.coarse_inputs.update(
                {c: np.diff(_held_integral(tc, cmd[c], sc, self.command_timeout_s)) / hh
                 for c in CHANNELS})
        for c in CHANNELS:
            ia, ib, wd, z, tm = data.meas[c]
            if keep is not None:
                k = keep[c]
                ia, z, tm = ia[k], z[k], tm[k]
                if ib is not None:
                    ib, wd = ib[k], cast(np.ndarray, wd)[k]
            if hh == h:
                ch = _Channel.build(c, data.use[c], self.u_grid[c], h, z, self.odom_pos, ia,
                                    ib, wd, tm)
            else:
                ch = _Channel.build(c, data.use[c], self.coarse_inputs[c], hh, z,
                                    (data.to - tc[0]) / hh, ia, ib, wd, tm)
            ch.accel = float(accel[c])
            ch.ramp_first = self.ramp_first[c]
            out[c] = ch
        return out

    def _around(self, centre: float, half: int | None = None) -> np.ndarray:
        """Grid positions within ``half`` (default three coarse steps) of ``centre``."""
        half = 3 * self.step if half is None else half
        return np.arange(max(0, centre - half), min(self.d_max, centre + half) + 1,
                         dtype=float)

    def _tau_range(self, k: int, n: int) -> np.ndarray:
        """``n`` time constants around the coarse grid's ``k``-th."""
        taus = self.taus
        return np.linspace(taus[max(0, k - 2)], taus[min(taus.size - 1, k + 2)], n)

    def local_taus(self, c: str, centre: float, spread: float) -> np.ndarray:
        """Time constants within a factor ``spread`` of ``centre`` (the bootstrap's grid).

        Parameters
        ----------
        c : str
            The channel, ``'v'`` or ``'w'``.
        centre : float
            The estimated time constant (s).
        spread : float
            The factor (> 1).

        Returns
        -------
        numpy.ndarray
        """
        h = self.h
        lo = max(0.0, centre / spread - 2 * h * spread)
        hi = min(self.max_tau_s, centre * spread + 2 * h * spread)
        return np.linspace(lo, hi, 13 if self.chans[c].accel > 0 else 25)

    def grid_fit(self, shifts: np.ndarray, grids: dict[str, np.ndarray], blocks: bool
                 ) -> dict[str, tuple[np.ndarray, Any]]:
        """Block statistics (nd, ntau, 5, nb) per channel and zz per block.

        Parameters
        ----------
        shifts : numpy.ndarray
            Latencies (grid steps).
        grids : dict
            Time constants (s) per channel.
        blocks : bool
            Per bootstrap block (else one block).

        Returns
        -------
        dict
            ``{c: (statistics, zz)}``.
        """
        data = self.data
        n_blocks = data.n_blocks
        out = {}
        for c, ch in self.chans.items():
            bl = np.minimum(((ch.t_mid - data.t_begin) // data.block_len).astype(int),
                            n_blocks - 1) if blocks else None
            st = np.stack([_stats(ch, tau, shifts, bl, n_blocks) for tau in grids[c]], axis=1)
            zzb = (np.bincount(cast(np.ndarray, bl), weights=ch.z * ch.z, minlength=n_blocks)
                   if blocks else float(ch.z @ ch.z))
            out[c] = (st, zzb)
        return out

    def estimate(self, stats: dict[str, tuple[np.ndarray, Any]], weights: np.ndarray | None,
                 shifts: np.ndarray, grids: dict[str, np.ndarray],
                 gains: dict[str, float] | None = None
                 ) -> tuple[float, dict[str, float], dict[str, float], Any]:
        """The estimate from (weighted) statistics.

        Parameters
        ----------
        stats : dict
            :meth:`grid_fit`'s statistics.
        weights : numpy.ndarray or None
            Block weights (a bootstrap replicate); ``None``: all blocks once.
        shifts : numpy.ndarray
            The latencies of ``stats`` (grid steps).
        grids : dict
            The time constants of ``stats`` per channel (s).
        gains : dict, optional
            Filled with each channel's static gain at the grid cell of the estimate (a
            bootstrap replicate's gain).

        Returns
        -------
        tuple
            (latency grid pos, {c: tau}, {c: channel latency pos}, the profile).
        """
        j: Any = 0.0                    # + the profiles: an array of the latency grid
        tau_hat, lat_c = {}, {}
        sse_all, gain_all = {}, {}
        for c in CHANNELS:
            st, zz = stats[c]
            if weights is not None:
                st, zz = st @ weights, zz @ weights
            sse, gain_all[c] = _sse(st, zz)                    # (nd, ntau) each
            sse_all[c] = sse
            prof = sse.min(axis=1)
            j = j + prof / self.chans[c].sigma2
            i = int(np.argmin(prof))
            lat_c[c] = float(shifts[i]) + _parabola_min(prof, i)
        i = int(np.argmin(j))
        pos = float(shifts[i]) + _parabola_min(j, i)
        for c in CHANNELS:
            row = sse_all[c][i]
            k = int(np.argmin(row))
            g = grids[c]
            tau_hat[c] = float(g[k] + _parabola_min(row, k) * (g[1] - g[0]))
            if gains is not None:
                gains[c] = float(gain_all[c][i, k])
        return pos, tau_hat, lat_c, j

    def search(self, near: float | None = None
               ) -> tuple[float, dict[str, float], dict[str, float]]:
        """Coarse, fine and polished fit of (latency, tau_v, tau_w) on ``chans``.

        Sets each channel's noise variance (``sigma2``); returns (latency grid position,
        time constants, each channel's own latency position).  With ``near`` (a grid
        position: a refit after a change of the model) the coarse grid spans +-0.1 s
        around it only.

        Parameters
        ----------
        near : float, optional
            A grid position to search around.

        Returns
        -------
        tuple
        """
        h, chans, step, taus = self.h, self.chans, self.step, self.taus
        coarse = self.coarse_all if near is None else \
            self.coarse_all[np.abs(self.coarse_all - near) <= 0.1 / h + step]
        # coarse: 10 ms steps, at most ~1500 samples per channel
        sse_c = {}
        rough = (self._make_channels(self.keep, {c: chans[c].accel for c in CHANNELS},
                                    self.hc)
                 if self.hc != h and any(ch.accel > 0 for ch in chans.values()) else chans)
        for c, ch in chans.items():
            stride = max(1, ch.z.size // 1500)
            sub = (ch if ch.accel <= 0 else rough[c]).subset(stride)
            zz = float(sub.z @ sub.z)
            shifts = coarse * (h / sub.h)
            sse_c[c] = np.stack([_sse(_stats(sub, tau, shifts, None, 0), zz)[0]
                                 for tau in taus], axis=1) * stride          # (nd, ntau)
        # each channel's noise variance: its own best fit at the grid resolution (a coarse
        # grid would inflate a noise-free channel's and let a noisy one dominate)
        prof_c = {c: sse_c[c].min(axis=1) for c in CHANNELS}
        kbest = {c: np.argmin(sse_c[c], axis=1) for c in CHANNELS}
        for c, ch in chans.items():
            i = int(np.argmin(prof_c[c]))
            zz = float(ch.z @ ch.z)
            best = min(float(_sse(_stats(ch, tau, self._around(coarse[i]), None, 0),
                                  zz)[0].min())
                       for tau in self._tau_range(int(kbest[c][i]), 9 if ch.accel > 0 else 17))
            ch.sigma2 = max(best / ch.z.size, 1e-12 * float(np.var(ch.z)), 1e-300)
        j_coarse = sum(prof_c[c] / chans[c].sigma2 for c in CHANNELS)
        i_c = int(np.argmin(j_coarse))
        # fine: grid resolution around the coarse minimum, local time-constant grids
        tau_grid = {c: self._tau_range(int(kbest[c][i_c]), 13 if chans[c].accel > 0 else 25)
                    for c in CHANNELS}
        fine = self._around(coarse[i_c])
        pos, tau0, lat_c, _ = self.estimate(self.grid_fit(fine, tau_grid, False), None, fine,
                                            tau_grid)
        if any(ch.accel > 0 for ch in chans.values()):
            p_l, t_l = self._polish_limited(pos, tau0, fine)
            return p_l, t_l, lat_c
        return self._polish(pos, tau0, lat_c)

    def _polish(self, pos: float, tau0: dict[str, float], lat_c: dict[str, float]
               ) -> tuple[float, dict[str, float], dict[str, float]]:
        """Polish (latency, tau_v, tau_w) together (Nelder-Mead, in grid steps)."""
        from scipy.optimize import minimize
        h, max_tau_s = self.h, self.max_tau_s
        x0 = np.array([pos, max(tau0['v'], 0.0) / h, max(tau0['w'], 0.0) / h])
        j0 = self._objective(x0)
        simplex = np.vstack([x0, x0 + [0.5, 0, 0], x0 + [0, 0.5, 0], x0 + [0, 0, 0.5]])
        polish = minimize(self._objective, x0, method='Nelder-Mead',
                          bounds=[(0.0, float(self.d_max)), (0.0, max_tau_s / h),
                                  (0.0, max_tau_s / h)],
                          options={'initial_simplex': simplex, 'xatol': 0.01,
                                   'fatol': 1e-7 * j0 + 1e-12, 'maxfev': 200})
        if polish.fun <= j0:
            return float(polish.x[0]), {'v': float(polish.x[1]) * h,
                                        'w': float(polish.x[2]) * h}, lat_c
        return pos, {c: max(tau0[c], 0.0) for c in CHANNELS}, lat_c

    def _polish_limited(self, pos: float, tau0: dict[str, float], fine: np.ndarray
                       ) -> tuple[float, dict[str, float]]:
        """Rate-limited channels: (tau, limit) polished per channel, then the latency.

        Each channel at the latency found (each simulation of the nonlinear model costs
        a pass over the grid, so the channels are polished one by one), then the latency
        again on the fine grid.
        """
        from scipy.optimize import minimize
        h = self.h
        tau_hat = {c: max(tau0[c], 0.0) for c in CHANNELS}
        for c, ch in self.chans.items():
            if ch.accel <= 0:
                continue
            a_start = ch.accel
            zz = float(ch.z @ ch.z)

            def f(x: np.ndarray, ch: _Channel = ch, zz: float = zz) -> float:
                tau, a = float(x[0]) * h, float(x[1])
                if tau < 0 or a <= 0:
                    return math.inf
                ch.accel = a
                return float(_sse(_stats(ch, tau, np.array([pos]), None, 0), zz)[0][0])

            x0 = np.array([tau_hat[c] / h, a_start])
            f0 = f(x0)
            simplex = np.vstack([x0, x0 * [1.1, 1.0] + [0.5, 0.0], x0 * [1.0, 1.03]])
            res = minimize(f, x0, method='Nelder-Mead',
                           options={'initial_simplex': simplex, 'xatol': 0.05,
                                    'fatol': 1e-7 * f0 + 1e-12, 'maxfev': 40})
            if res.fun <= f0 and float(res.x[0]) * h <= self.max_tau_s:
                tau_hat[c], ch.accel = float(res.x[0]) * h, float(res.x[1])
            else:
                ch.accel = a_start
        j: Any = 0.0
        for c, ch in self.chans.items():
            j = j + _sse(_stats(ch, tau_hat[c], fine, None, 0),
                         float(ch.z @ ch.z))[0] / ch.sigma2
        i = int(np.argmin(j))
        return float(fine[i]) + _parabola_min(j, i), tau_hat

    def channel_sse(self, c: str, p: float, tau: float) -> tuple[np.ndarray, np.ndarray]:
        """(residual sum of squares, gain) of channel ``c`` at latency ``p`` and ``tau``.

        Parameters
        ----------
        c : str
            The channel.
        p : float
            The latency (grid steps).
        tau : float
            The time constant (s).

        Returns
        -------
        tuple of numpy.ndarray
        """
        ch = self.chans[c]
        return _sse(_stats(ch, tau, np.array([p]), None, 0), float(ch.z @ ch.z))

    def _objective(self, x: np.ndarray) -> float:
        """The normalized residual of ``x = (latency, tau_v, tau_w)`` in grid steps."""
        p, tv, tw = (float(v) for v in x)
        return sum(float(self.channel_sse(c, p, t * self.h)[0][0]) / self.chans[c].sigma2
                   for c, t in (('v', tv), ('w', tw)))

    def _refit(self, keep: dict[str, np.ndarray] | None, accel: dict[str, float]) -> None:
        """New channels (samples ``keep``, limits ``accel``), refitted near the estimate."""
        self.chans = self._make_channels(keep, accel)
        self.pos, self.tau_hat, self.lat_c = self.search(self.pos)

    def model_saturation(self) -> None:
        """Model a base that cannot reach the commanded speeds.

        The commands are clipped to the range it reaches and the fit repeated.
        """
        self.clips = clips = _speed_saturation(self.chans, self.pos, self.tau_hat)
        if not clips:
            return
        for c, (lo_c, hi_c, frac) in clips.items():
            self.u_grid[c] = np.clip(self.u_grid[c], lo_c, hi_c)
            self.notes.append(f'the base does not reach the commanded {NAMES[c]}: it saturates '
                              f'at [{lo_c:.3g}, {hi_c:.3g}] {UNITS[c]} (commands beyond that '
                              f'{100 * frac:.0f} % of the time); modelled by clipping the '
                              'commands')
        self.coarse_inputs.clear()
        self._refit(None, self.no_limit)

    def model_limits(self) -> None:
        """Acceleration limits: a rate-limited FOPDT where it explains the motion better."""
        accel, ramped = _choose_limits(
            self._make_channels(None, self.no_limit, self.hc), self.pos * self.h,
            self.tau_hat, self.max_tau_s, self.max_latency_s)
        if any(ramped.values()):
            # the limit's place chosen per channel on the full fits (the coarse search's
            # subset and grid cannot tell them apart): the command ramped first where it
            # lowers the channel's residual below RAMP_FIRST_GAIN of the rate-limited lag's
            start = (self.pos, self.tau_hat, self.lat_c)
            fits = {}
            for place in (False, True):
                self.pos, self.tau_hat, self.lat_c = start
                self.ramp_first = {c: place and ramped[c] > 0 for c in CHANNELS}
                lim = {c: ramped[c] if self.ramp_first[c] else accel[c] for c in CHANNELS}
                self._refit(None, lim)
                fits[place] = (self.chans, self.pos, self.tau_hat, self.lat_c, {
                    c: float(self.channel_sse(c, self.pos, self.tau_hat[c])[0][0])
                    for c in CHANNELS})
            choice = {c: ramped[c] > 0 and (not accel[c] > 0 or fits[True][4][c] <
                                             RAMP_FIRST_GAIN * fits[False][4][c])
                      for c in CHANNELS}
            if all(choice[c] == (ramped[c] > 0) for c in CHANNELS):
                self.chans, self.pos, self.tau_hat, self.lat_c = fits[True][:4]
                self.ramp_first = {c: ramped[c] > 0 for c in CHANNELS}
            elif not any(choice.values()):
                self.chans, self.pos, self.tau_hat, self.lat_c = fits[False][:4]
                self.ramp_first = {c: False for c in CHANNELS}
            else:
                self.pos, self.tau_hat, self.lat_c = start
                self.ramp_first = choice
                self._refit(None, {c: ramped[c] if choice[c] else accel[c]
                                   for c in CHANNELS})
            accel = {c: self.chans[c].accel for c in CHANNELS}      # polished
        elif any(accel.values()):
            self._refit(None, accel)
            accel = {c: self.chans[c].accel for c in CHANNELS}      # polished
        self.accel = accel

    def drop_unseen_limits(self) -> None:
        """Drop a limit that no longer binds :data:`MIN_BINDING` of the time after the refits.

        The exclusions and polishes refit a limit chosen on all the data; where the spans
        it bound in were excluded (a closed loop's short binding steps look like a hiccup
        to a model with the limit too high), it drifts up unconstrained: one that binds
        for a moment at most is not seen (0), and the fit is repeated without it.
        """
        drop = [c for c, ch in self.chans.items() if ch.accel > 0 and binding_fraction(
            ch, self.tau_hat[c], self.pos, 0.0, ch.u_avg.size * ch.h) < MIN_BINDING]
        if not drop:
            return
        for c in drop:
            self.notes.append(f'the {"linear" if c == "v" else "angular"} acceleration limit '
                              f'refitted to {self.chans[c].accel:.3g} binds less than '
                              f'{100 * MIN_BINDING:.0f} % of the time: not seen')
        self.ramp_first = {c: self.ramp_first[c] and c not in drop
                           for c in CHANNELS}
        self._refit(self.keep, {c: 0.0 if c in drop else self.chans[c].accel
                                for c in CHANNELS})
        self.accel = {c: self.chans[c].accel for c in CHANNELS}

    def exclude_gross_errors(self) -> list[tuple[float, float]]:
        """Exclude the segments where the base did not follow the commands at all.

        A stall, a hiccup, a glitch of the odometry: excluded, and the fit repeated
        without them; returns the spans excluded (s).
        """
        data = self.data
        excluded: list[tuple[float, float]] = []
        for _ in range(2):
            found = _gross_errors(self.chans, self.pos, self.tau_hat, data.meas, self.keep,
                                  data.t_begin, data.t_end, max(self.tau_hat.values()))
            if found is None:
                break
            self.keep, excluded = found
            self._refit(self.keep, self.accel)
            self.accel = {c: self.chans[c].accel for c in CHANNELS}
        if excluded:
            excluded_s = float(sum(b - a for a, b in excluded))
            spans = ', '.join(f'{a:.2f}-{b:.2f} s' for a, b in excluded[:4])
            more = f' and {len(excluded) - 4} more' if len(excluded) > 4 else ''
            self.notes.append(f'excluded {excluded_s:.2f} s where the motion did not follow the '
                              f'commands at all ({spans}{more}): a stall or hiccup of the base, '
                              'slipping wheels or an odometry glitch; the fit uses the rest')
        return excluded

    def model_jitter(self, excluded: list[tuple[float, float]]
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Model latency jitter; returns the command steps' latencies (grid steps) and spans.

        Each distinct command step is timed on its own; when they spread, the commands
        are moved to the times they acted and the lags fitted again (a single delay would
        take the smear of the jitter for lag).

        Parameters
        ----------
        excluded : list of (float, float)
            Spans left out (s).

        Returns
        -------
        tuple of numpy.ndarray
            The steps' latencies (grid steps) and the first and last of the spans
            they were fitted over (``_event_latencies``).
        """
        data, h = self.data, self.h
        tc, cmd = data.tc, data.cmd
        pos = self.pos
        events, ev_first, ev_last = _event_latencies(self.chans, pos, self.tau_hat, tc, cmd,
                                                     data.t_begin, data.t_end, excluded)
        if events.size < MIN_EVENTS:
            return events, ev_first, ev_last
        e_lo, e_hi = np.percentile(events, [2.5, 97.5])
        if (e_hi - e_lo) * h <= JITTER_REFIT_S:
            return events, ev_first, ev_last
        shift = np.zeros(tc.size)
        for p_k, a_k, b_k in zip(events, ev_first, ev_last):
            shift[a_k:b_k] = (p_k - pos) * h
        tcw = np.maximum.accumulate(tc + shift)
        before = (dict(self.u_grid), self.chans, pos, self.tau_hat, self.lat_c, self.accel)
        j_before = self._objective(np.array([pos, self.tau_hat['v'] / h,
                                            self.tau_hat['w'] / h]))
        for c in CHANNELS:
            self.u_grid[c] = np.diff(_held_integral(tcw, cmd[c], self.s,
                                                    self.command_timeout_s)) / h
            if c in self.clips:
                self.u_grid[c] = np.clip(self.u_grid[c], self.clips[c][0], self.clips[c][1])
        self.coarse_inputs.clear()
        sig_before = {c: ch.sigma2 for c, ch in self.chans.items()}
        self._refit(self.keep, self.accel)
        self.accel = {c: self.chans[c].accel for c in CHANNELS}
        j_after = sum(float(self.channel_sse(c, self.pos, self.tau_hat[c])[0][0])
                      / sig_before[c] for c in CHANNELS)
        if j_after < JITTER_GAIN * j_before:
            self.notes.append(f'the latency jitters ({events.size} command steps over '
                              f'[{e_lo * h:.3f}, {e_hi * h:.3f}] s): the lags are fitted with '
                              'each step moved to the time it acted')
        else:                   # the steps' spread is noise: keep the one-delay fit
            self.u_grid.update(before[0])
            self.coarse_inputs.clear()
            self.chans, self.pos, self.tau_hat, self.lat_c, self.accel = before[1:]
        return events, ev_first, ev_last
