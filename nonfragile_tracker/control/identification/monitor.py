"""Runtime monitor of the latency certificate: is the robot inside what K was certified for.

A gain from ``latency-design`` is certified for a range of *residual* delay (the latency
minus what the predictor compensates, plus the command period's hold and the odometry
age's spread); latency drifts at run time.  :func:`estimate_latency` fits the
identification's model to the tracker's own command history and odometry over a sliding
window, with validity gates (STALE, with the reason, when too little is left or the
commands have not varied); :func:`evaluate` gives OK, WARN, ERROR or STALE against the
certified interval; :func:`adapted_prediction` moves the predictor's latency to the
estimate.  Nothing here imports ROS; numpy and scipy only.

See doc/theory.md, section "Latency monitor" (#latency-monitor).
"""
from __future__ import annotations

import math
import threading
import time
from collections import deque
from dataclasses import dataclass, field, replace
from typing import Any, Mapping

import numpy as np

from .errors import MonitorError

__all__ = ['OK', 'WARN', 'ERROR', 'STALE', 'LEVEL_NAMES', 'MonitorSettings', 'LatencyEstimate',
           'Certificate', 'MonitorStatus', 'estimate_latency', 'certificate_from_design',
           'certificate_from_parameters', 'evaluate', 'adapted_prediction', 'SampleWindow',
           'BRING_UP', 'MonitorWorker', 'MonitorError']

#: Levels, equal to diagnostic_msgs/DiagnosticStatus's (STALE = 3).
OK, WARN, ERROR, STALE = 0, 1, 2, 3
LEVEL_NAMES = {OK: 'OK', WARN: 'WARN', ERROR: 'ERROR', STALE: 'STALE'}
#: What to run when the certificate no longer holds (README "Bring up the tracker").
BRING_UP = ('record a run (nonfragile_tracker run ... or ros2 bag record odom cmd_vel), '
            'nonfragile_tracker identify BAG -o latency.yaml, nonfragile_tracker '
            'latency-design PROBLEM --identification latency.yaml -o gains.yaml')
_TAUS = (0.0, 0.01, 0.02, 0.03, 0.04, 0.05, 0.065, 0.08, 0.1, 0.13, 0.16, 0.2, 0.25, 0.3)


def _pos(name: str, value: Any, *, zero: bool = False) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise MonitorError(f'{name} must be a number, got {value!r}') from None
    if not math.isfinite(x) or x < 0 or (x == 0 and not zero):
        raise MonitorError(f'{name} must be a finite number {">=" if zero else ">"} 0, '
                           f'got {value!r}')
    return x


@dataclass(frozen=True)
class MonitorSettings:
    """Estimator and status settings (SI units); validated on construction.

    Parameters
    ----------
    window : float
        Length of the sliding window of odometry (s).
    max_latency, max_lag : float
        Search limits of the latency and of the lags (s).
    resolution : float
        Grid step of the model response and of the latency search (s).
    max_linear_speed, max_angular_speed : float
        The tracker's command limits: a command there is saturated.
    max_linear_accel, max_angular_accel : float
        The base's acceleration limits (0 = unknown: not gated).
    accel_fraction : float
        A measured acceleration at this fraction of a limit counts as binding.
    limit_guard : float
        Samples this long after a binding limit are excluded too (the response catches up, s).
    gap_factor : float
        An odometry interval longer than this times the median is a gap.
    min_excitation : (float, float)
        Least standard deviation of the valid commands of v (m/s) and w (rad/s).
    min_valid_fraction, min_r2 : float
        Least fraction of valid samples and least explained variance for an estimate.
    chi2_level : float
        Rise of the normalised cost that bounds the latency interval.
    max_interval : float
        Widest latency interval that counts as an estimate (s): a window that straddles a
        latency change fits neither latency well and its interval widens.
    min_information : float
        Least share of the model's slope (its sensitivity to the latency) on valid samples:
        a gate that removed the responses leaves data that cannot place the latency.
    warn_margin : float
        WARN when the latency is within this of the certified upper end (s).
    tolerance : float
        An estimate below the lower end by at most this is inside (estimator precision, s).
    lag_tolerance : float
        A lag estimate above ``(1 + lag_tolerance)`` times the certified lag (plus
        ``tolerance``) WARNs; the lag is less precise than the latency in closed loop.
    """

    window: float = 4.0
    max_latency: float = 0.5
    max_lag: float = 0.3
    resolution: float = 0.002
    max_linear_speed: float = math.inf
    max_angular_speed: float = math.inf
    max_linear_accel: float = 0.0
    max_angular_accel: float = 0.0
    accel_fraction: float = 0.9
    limit_guard: float = 0.2
    gap_factor: float = 3.0
    min_excitation: tuple[float, float] = (0.01, 0.02)
    min_valid_fraction: float = 0.3
    min_r2: float = 0.5
    chi2_level: float = 4.0
    min_information: float = 0.25
    max_interval: float = 0.03
    warn_margin: float = 0.02
    tolerance: float = 0.01
    lag_tolerance: float = 1.0

    def __post_init__(self) -> None:
        for name in ('window', 'max_latency', 'max_lag', 'resolution', 'max_linear_speed',
                     'max_interval',
                     'max_angular_speed', 'accel_fraction', 'gap_factor', 'chi2_level'):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and not isinstance(v, bool) and v > 0
                    and not math.isnan(v)):
                raise MonitorError(f'monitor {name} must be a number > 0, got {v!r}')
        for name in ('max_linear_accel', 'max_angular_accel', 'min_valid_fraction', 'min_r2',
                     'limit_guard', 'min_information',
                     'warn_margin', 'tolerance', 'lag_tolerance'):
            object.__setattr__(self, name, _pos(f'monitor {name}', getattr(self, name),
                                                zero=True))
        if self.resolution > 0.05:
            raise MonitorError(f'monitor resolution must be at most 0.05 s, got '
                               f'{self.resolution}')
        if self.window < 10 * self.resolution:
            raise MonitorError(f'monitor window ({self.window} s) must be at least ten grid '
                               f'steps ({self.resolution} s)')
        exc = tuple(self.min_excitation)
        if len(exc) != 2:
            raise MonitorError(f'min_excitation needs [v (m/s), w (rad/s)], got {exc!r}')
        object.__setattr__(self, 'min_excitation',
                           tuple(_pos('min_excitation', e, zero=True) for e in exc))
        if self.min_valid_fraction > 1 or self.min_r2 > 1:
            raise MonitorError('min_valid_fraction and min_r2 must be in [0, 1]')

    @property
    def memory(self) -> float:
        """How long a command can still act on the motion (s): ``max_latency + 3 max_lag``."""
        return self.max_latency + 3.0 * self.max_lag


@dataclass(frozen=True)
class LatencyEstimate:
    """One window's estimate; ``valid`` False means no estimate, ``reason`` says why."""

    valid: bool
    reason: str
    t_end: float = math.nan                  # last odometry stamp of the window (s)
    latency: float = math.nan                # command-to-motion latency (s)
    interval: tuple[float, float] = (math.nan, math.nan)   # its interval (s)
    lag_v: float = math.nan                  # first-order time constants (s); nan: unused
    lag_w: float = math.nan
    r2: float = math.nan                     # explained fraction of the motion (worst channel)
    confidence: float = 0.0                  # 0..1: r2 times the valid fraction's adequacy
    valid_fraction: float = 0.0
    excluded: dict[str, int] = field(default_factory=dict)   # reason -> samples excluded
    channels: tuple[str, ...] = ()
    information: dict[str, float] = field(default_factory=dict)   # channel -> slope share

    @property
    def lag(self) -> float:
        """The larger of the lags of the channels used (s)."""
        vals = [x for x in (self.lag_v, self.lag_w) if math.isfinite(x)]
        return max(vals) if vals else math.nan


def _lfilter(b: Any, a: Any, x: Any, zi: Any) -> Any:
    """:func:`scipy.signal.lfilter`, imported on first use.

    ``scipy.signal`` takes about 0.3 s to import; ``latency-design`` and the tracker import
    this module for the certificate record alone, and never filter.
    """
    from scipy.signal import lfilter
    return lfilter(b, a, x, zi=zi)


def _dilate(mask: np.ndarray, t: np.ndarray, before: float, after: float) -> np.ndarray:
    """Samples within ``[t_i - before, t_i + after]`` of a True sample (t sorted)."""
    if not mask.any():
        return mask
    hits = t[mask]
    lo = np.searchsorted(hits, t - after, side='left')
    hi = np.searchsorted(hits, t + before, side='right')
    return hi > lo


def estimate_latency(cmd_t: Any, cmd_v: Any, cmd_w: Any, odom_t: Any, odom_v: Any, odom_w: Any,
                     settings: MonitorSettings = MonitorSettings(),
                     t_end: float | None = None) -> LatencyEstimate:
    """Latency and lags from commands and odometry twist over the last ``settings.window``.

    Parameters
    ----------
    cmd_t, cmd_v, cmd_w : array_like
        Command times (s, when the base receives them) and values, increasing times.
    odom_t, odom_v, odom_w : array_like
        Odometry stamps (measurement time, s) and the measured twist.
    settings : MonitorSettings
        Window, search limits and gating.
    t_end : float, optional
        End of the window (default: the last odometry stamp).

    Returns
    -------
    LatencyEstimate
        ``valid`` False with the reason when the window cannot give one.

    Notes
    -----
    The stages: the window's samples, the gating (``_gate``), each channel's residual
    profile over the latency grid (``_channel_profile``), the latency and its interval
    from the normalised total (``_latency_from``), its identifiability
    (``_information``) and the verdict (``_verdict``).
    """
    s = settings
    ct = np.asarray(cmd_t, float)
    cu = (np.asarray(cmd_v, float), np.asarray(cmd_w, float))
    ot = np.asarray(odom_t, float)
    oy = (np.asarray(odom_v, float), np.asarray(odom_w, float))
    if ot.size < 10 or ct.size < 2:
        return LatencyEstimate(False, f'too little data ({ot.size} odometry, {ct.size} '
                                      'commands)')
    end = float(ot[-1] if t_end is None else t_end)
    start = max(end - s.window, float(ct[0]) + s.memory)
    sel = (ot >= start) & (ot <= end) & np.isfinite(oy[0]) & np.isfinite(oy[1])
    t = ot[sel]
    if t.size < 10 or end - start < 0.5 * s.window:
        return LatencyEstimate(False, f'window not filled yet ({max(end - start, 0.0):.1f} of '
                                      f'{s.window:g} s with commands before it)', t_end=end)
    y = (oy[0][sel], oy[1][sel])
    masks, excluded = _gate(s, t, y, ct, cu)
    grid = _Grid.of(s, start, end, t, ct)
    used: list[str] = []
    costs: list[np.ndarray] = []
    best_tau: list[list[float]] = []
    r2s: list[float] = []
    fracs: list[float] = []
    reasons = []
    recent = t >= end - 0.5 * s.window
    for c, name in enumerate(('v', 'w')):
        fitted = _channel_profile(s, grid, cu[c][grid.ci], y[c], masks[c], c, name)
        if isinstance(fitted, str):
            reasons.append(fitted)
            continue
        quiet = _quiet(s, grid, cu[c][grid.ci], masks[c] & recent, c, name)
        if quiet:
            reasons.append(quiet)
            continue
        used.append(name)
        costs.append(fitted[0])
        best_tau.append(fitted[1])
        r2s.append(fitted[2])
        fracs.append(fitted[3])
    if not used:
        return LatencyEstimate(False, 'no usable channel: ' + '; '.join(reasons), t_end=end,
                               excluded=excluded)
    nv = [int(masks[('v', 'w').index(name)].sum()) for name in used]
    L, i0, lo, hi = _latency_from(s, grid, costs, nv)
    info = _information(grid, cu, masks, used, best_tau, i0)
    r2 = min(r2s)
    lags = {name: float(bt[i0]) for name, bt in zip(used, best_tau)}
    frac = min(fracs)
    conf = max(0.0, min(1.0, r2)) * min(1.0, frac / max(s.min_valid_fraction, 1e-9) / 2.0 + 0.5)
    est = LatencyEstimate(True, '', t_end=end, latency=float(L), interval=(max(0.0, lo), hi),
                          lag_v=lags.get('v', math.nan), lag_w=lags.get('w', math.nan), r2=r2,
                          confidence=conf, valid_fraction=frac, excluded=excluded,
                          channels=tuple(used), information=info)
    return _verdict(est, s, i0 == grid.nL - 1, reasons)


def _gate(s: MonitorSettings, t: np.ndarray, y: tuple[np.ndarray, np.ndarray],
          ct: np.ndarray, cu: tuple[np.ndarray, np.ndarray]
          ) -> tuple[list[np.ndarray], dict[str, int]]:
    """Each channel's valid samples and the count excluded per reason.

    Excluded: odometry gaps (and the lag's reach after them), samples a saturated command
    can act on, and samples where the measured rate binds an acceleration limit.
    """
    n = t.size
    excluded: dict[str, int] = {}
    period = float(np.median(np.diff(t)))
    gap_mask = np.zeros(n, bool)
    d = np.diff(t)
    big = d > s.gap_factor * period
    if big.any():
        gap_mask[1:] |= big
        gap_mask = _dilate(gap_mask, t, 2 * period, 3 * s.max_lag + 2 * period)
        excluded['odometry gap'] = int(gap_mask.sum())
    limits = ((s.max_linear_speed, s.max_linear_accel), (s.max_angular_speed,
                                                         s.max_angular_accel))
    masks = []
    for c, name in enumerate(('v', 'w')):
        vmax, amax = limits[c]
        m = gap_mask.copy()
        sat = np.abs(cu[c]) >= vmax * (1 - 1e-9)
        if sat.any():
            # a sample is affected while a saturated command can still act on it
            # the commands in force over [t - memory, t] can act on the sample at t
            idx_hi = np.searchsorted(ct, t, side='right') - 1
            idx_lo = np.searchsorted(ct, t - s.memory, side='right') - 1
            csum = np.concatenate([[0], np.cumsum(sat)])
            hit = csum[np.maximum(idx_hi, 0) + 1] - csum[np.maximum(idx_lo, 0)] > 0
            excluded[f'{name} saturated'] = int((hit & ~m).sum())
            m |= hit
        if amax > 0:
            acc = np.abs(np.diff(y[c])) / np.maximum(d, 1e-9)
            bind = np.zeros(n, bool)
            bind[1:] = acc >= s.accel_fraction * amax
            bind[:-1] |= bind[1:]
            if bind.any():
                bind = _dilate(bind, t, 0.0, s.limit_guard)
                excluded[f'{name} acceleration limit'] = int((bind & ~m).sum())
                m |= bind
        masks.append(~m)
    return masks, excluded


@dataclass(frozen=True)
class _Grid:
    """The model's time grid of a window.

    Step ``res`` from the window start less the memory (``n`` cells); ``ci`` the command
    in force in each cell, ``nL`` latency candidates, ``base_idx`` each sample's cell and
    ``idx`` (nL, samples) the cells each candidate latency reads.
    """

    res: float
    n: int
    ci: np.ndarray
    nL: int
    base_idx: np.ndarray
    idx: np.ndarray

    @classmethod
    def of(cls, s: MonitorSettings, start: float, end: float, t: np.ndarray,
           ct: np.ndarray) -> _Grid:
        """The grid of the window ``[start, end]`` (samples ``t``, command times ``ct``)."""
        res = s.resolution
        g0 = start - s.memory
        grid_n = int(math.ceil((end - g0) / res)) + 2
        gt = g0 + res * np.arange(grid_n)
        ci = np.clip(np.searchsorted(ct, gt, side='right') - 1, 0, ct.size - 1)
        nL = int(math.floor(s.max_latency / res)) + 1
        base_idx = np.floor((t - g0) / res + 1e-9).astype(int)   # grid cell of each sample
        shift = np.arange(nL)[:, None]
        return cls(res, grid_n, ci, nL, base_idx, base_idx[None, :] - shift)


def _quiet(s: MonitorSettings, grid: _Grid, u: np.ndarray, recent: np.ndarray, c: int,
           name: str) -> str:
    """Why a channel without excitation in the window's latest half is not used ('' if it has).

    Data without excitation (the robot at rest, constant commands) says nothing about the
    latency or the lag: a window whose motion ended half a window ago or more is not
    fitted, so standing still gives STALE, never a WARN from a lag fitted on the stop.
    """
    vals = u[grid.base_idx[recent]]
    std = float(np.std(vals)) if vals.size else 0.0
    if std < s.min_excitation[c]:
        return (f'{name}: no excitation in the last {0.5 * s.window:g} s of the window '
                f'(command std {std:.3g} < {s.min_excitation[c]:g}: at rest or constant)')
    return ''


def _channel_profile(s: MonitorSettings, grid: _Grid, u: np.ndarray, yc: np.ndarray,
                     ok: np.ndarray, c: int, name: str
                     ) -> str | tuple[np.ndarray, list[float], float, float]:
    """One channel's residual over the latency grid (its best lag at each candidate).

    ``u``: the commands on the grid, ``yc`` the measured channel, ``ok`` its valid samples.
    Returns ``(cost, best lag per candidate, R^2, valid fraction)``, or why the channel
    is not used.
    """
    frac = float(ok.mean())
    if frac < max(s.min_valid_fraction, 1e-9):
        return f'{name}: {100 * (1 - frac):.0f} % of the window excluded'
    # excitation of the commands that act on the valid samples
    cmd_std = float(np.std(u[grid.base_idx[ok]]))
    if cmd_std < s.min_excitation[c]:
        return f'{name}: command varies too little ({cmd_std:.3g} < {s.min_excitation[c]:g})'
    yo = yc[ok]
    ss = float(np.sum((yo - yo.mean()) ** 2))
    if ss <= 0:
        return f'{name}: no measured motion'
    res, nL = grid.res, grid.nL
    taus = [tau for tau in _TAUS if tau <= s.max_lag]
    J = np.full((len(taus), nL), np.inf)
    ii = grid.idx[:, ok]
    up = np.concatenate([u[:1], u[:-1]])     # the command held over (gt[i-1], gt[i]]
    for k, tau in enumerate(taus):
        if tau == 0:
            ym = up
        else:
            a = math.exp(-res / tau)
            ym = _lfilter([1 - a], [1, -a], up, zi=[a * up[0]])[0]
        Y = ym[ii]                                            # (nL, n_ok)
        yy = np.einsum('ij,ij->i', Y, Y)
        yd = Y @ yo
        J[k] = float(yo @ yo) - np.where(yy > 0, yd * yd / np.where(yy > 0, yy, 1), 0)
    k_best = np.argmin(J, axis=0)
    j = J[k_best, np.arange(nL)]
    return (np.maximum(j, 1e-30), [taus[k] for k in k_best], 1.0 - float(j.min()) / ss,
            frac)


def _latency_from(s: MonitorSettings, grid: _Grid, costs: list[np.ndarray], nv: list[int]
                  ) -> tuple[float, int, float, float]:
    """``(latency, its grid index, interval low, high)`` from the channels' profiles.

    The normalised total cost: each channel by its own best residual per valid sample
    (``nv`` of them); the minimum refined by a parabola, the interval where the total is
    within ``chi2_level`` of it (one grid step wider either side).
    """
    res, nL = grid.res, grid.nL
    total = np.zeros(nL)
    for j, n_valid in zip(costs, nv):
        total += (j - j.min()) / (j.min() / max(n_valid - 3, 1))
    i0 = int(np.argmin(total))
    L = i0 * res
    if 0 < i0 < nL - 1:
        a, b, cc = total[i0 - 1], total[i0], total[i0 + 1]
        den = a - 2 * b + cc
        if den > 0:
            L += 0.5 * res * (a - cc) / den
    inside = np.nonzero(total <= total[i0] + s.chi2_level)[0]
    return L, i0, inside.min() * res - res, inside.max() * res + res


def _information(grid: _Grid, cu: tuple[np.ndarray, np.ndarray], masks: list[np.ndarray],
                 used: list[str], best_tau: list[list[float]], i0: int) -> dict[str, float]:
    """Identifiability per channel used.

    The share of the model's sensitivity to the latency (its slope) that falls on valid
    samples (a gate that removed the responses leaves flat data).
    """
    res = grid.res
    info = {}
    for name, bt in zip(used, best_tau):
        c = ('v', 'w').index(name)
        u = cu[c][grid.ci]
        up = np.concatenate([u[:1], u[:-1]])
        tau = bt[i0]
        if tau > 0:
            a = math.exp(-res / tau)
            up = _lfilter([1 - a], [1, -a], up, zi=[a * up[0]])[0]
        slope = np.gradient(up)[np.clip(grid.base_idx - i0, 0, grid.n - 1)]
        e_all = float(slope @ slope)
        info[name] = float(slope[masks[c]] @ slope[masks[c]]) / e_all if e_all > 0 else 0.0
    return info


def _verdict(est: LatencyEstimate, s: MonitorSettings, at_limit: bool, reasons: list[str]
             ) -> LatencyEstimate:
    """``est``, refused (``valid`` False, with the reason) where it must be.

    Refused when the fit is poor, the latency is not observable or not determined or at
    the search limit; else the channels left out are named.
    """
    r2, info = est.r2, est.information
    lo, hi = est.interval
    if r2 < s.min_r2:
        return replace(est, valid=False, reason=f'the model explains only {100 * r2:.0f} % of '
                       f'the motion (at least {100 * s.min_r2:.0f} % needed)')
    weak = [f'{k} {100 * v:.0f} %' for k, v in info.items() if v < s.min_information]
    if len(weak) == len(info):
        return replace(est, valid=False, reason='latency not observable in the valid samples '
                       '(share of the response slope outside the excluded segments: '
                       + ', '.join(weak) + f'; at least {100 * s.min_information:.0f} % '
                       'needed)')
    if hi - lo > s.max_interval:
        return replace(est, valid=False, reason=f'latency not determined: interval '
                       f'{1e3 * lo:.0f}-{1e3 * hi:.0f} ms is wider than '
                       f'{1e3 * s.max_interval:.0f} ms (the latency is changing, or the motion '
                       'hardly constrains it)')
    if at_limit:
        return replace(est, valid=False, reason=f'latency at the search limit '
                       f'{s.max_latency:g} s')
    if reasons:
        return replace(est, reason='only ' + ', '.join(est.channels) + ' used ('
                       + '; '.join(reasons) + ')')
    return est


# ------------------------------------------------------------------------------------------
# Certificate and status

@dataclass(frozen=True)
class Certificate:
    """What a gain is certified for, in terms the monitor measures.

    ``residual = [h_min, H]`` is the design's certified delay range (``H`` its certified
    upper end, with the actuator lag if it has one, less the odometry-age spread the plan
    allowed for); the delay the certificate bounds is ``L - predict_latency`` plus the
    sample-and-hold of the command period ``hold`` (0 to ``hold``), with ``L`` the
    command-to-motion latency as :func:`estimate_latency` measures it (command time to
    motion, the hold modelled).  So ``L`` is certified in
    ``[P + h_min, P + H - hold]`` (:meth:`interval`).  ``lag`` is the actuator time
    constant the certificate includes (0: none).  ``adapt_range`` is the range of
    ``predict_latency`` adaptation may use (the identified latency interval; None: the
    design records none).
    """

    residual: tuple[float, float]
    lag: float
    adapt_range: tuple[float, float] | None
    hold: float = 0.0
    source: str = ''

    def interval(self, predict_latency: float) -> tuple[float, float]:
        """Certified latency interval ``[P + h_min, P + H - hold]`` for the predictor's ``P``.

        Parameters
        ----------
        predict_latency : float
            The predictor's latency ``P`` (s).

        Returns
        -------
        (float, float)
            The interval (s).
        """
        return (predict_latency + self.residual[0],
                predict_latency + self.residual[1] - self.hold)

    def parameters(self) -> dict[str, Any]:
        """The tracker parameters carrying this certificate (see certificate_from_parameters)."""
        return {'certified_residual': [float(v) for v in self.residual],
                'certified_lag': float(self.lag),
                'certified_adapt_range': ([float(v) for v in self.adapt_range]
                                          if self.adapt_range else [])}


def _pair(rec: Mapping[str, Any], key: str) -> tuple[float, float] | None:
    val = rec.get(key)
    if val is None:
        return None
    try:
        a, b = (float(x) for x in val)
    except (TypeError, ValueError):
        raise MonitorError(f'design record {key!r} must be two numbers, got {val!r}') from None
    if not (math.isfinite(a) and math.isfinite(b) and a <= b):
        raise MonitorError(f'design record {key!r} must be two finite numbers lo <= hi, got '
                           f'{val!r}')
    return a, b


def certificate_from_design(design: Mapping[str, Any] | None, hold: float,
                            source: str = '') -> Certificate | None:
    """The certificate of a gain file's ``gain_design`` record (None: it certifies no latency).

    Parameters
    ----------
    design : mapping or None
        :func:`.gains.read_gain_design`'s record.
    hold : float
        The tracker's command period (s; its ``dt``): the sample-and-hold delay.
    source : str
        Where the record came from (for messages).

    Returns
    -------
    Certificate or None
        ``residual = [h_min, H - (a_hi - a_lo)]`` with ``H`` the record's
        ``lag_certified_h_max`` (with an ``actuator_lag``), else ``certified_h_max``, else
        ``certified_latency`` (Theorem 1 designs: ``h_min = 0``); ``a`` the
        ``identified_command_age``.  None if the record certifies no latency (or a lag
        without ``lag_certified_h_max``).
    """
    if not design:
        return None
    lag = _pos('design record actuator_lag', design.get('actuator_lag', 0.0), zero=True)
    if lag > 0 and design.get('lag_certified_h_max') is None:
        return None                    # a lag without its certificate: nothing certified
    H = None
    for key in (('lag_certified_h_max',) if lag > 0 else ()) + ('certified_h_max',
                                                                 'certified_latency'):
        if design.get(key) is not None:
            H = _pos(f'design record {key}', design[key], zero=True)
            break
    if H is None:
        return None
    interval = _pair(design, 'latency_interval')
    h_min = interval[0] if interval else 0.0
    age = _pair(design, 'identified_command_age')
    r_hi = H - (age[1] - age[0] if age else 0.0)
    if r_hi < h_min:
        return None
    return Certificate(residual=(float(h_min), float(r_hi)), lag=float(lag),
                       adapt_range=_pair(design, 'identified_latency_interval'),
                       hold=_pos('command period', hold, zero=True), source=source)


def certificate_from_parameters(residual: Any, lag: float, adapt_range: Any, hold: float = 0.0,
                                source: str = 'tracker parameters') -> Certificate | None:
    """The certificate carried by the tracker's ``certified_*`` parameters (None: unset).

    Parameters
    ----------
    residual : sequence of 2 floats or None
        ``certified_residual`` ``[h_min, H]`` (s); empty or None: no certificate.
    lag : float
        ``certified_lag`` (s).
    adapt_range : sequence of 2 floats or None
        ``certified_adapt_range`` (s); empty or None: adaptation has no range.
    hold : float
        The tracker's command period (s).
    source : str
        For messages.
    """
    res = list(residual or [])
    if not res:
        return None
    if len(res) != 2 or not all(math.isfinite(float(v)) for v in res) or res[0] > res[1]:
        raise MonitorError(f'certified_residual must be [lo, hi] with lo <= hi (s), got {res}')
    rng = list(adapt_range or [])
    if rng and (len(rng) != 2 or rng[0] > rng[1] or rng[0] < 0):
        raise MonitorError(f'certified_adapt_range must be [] or [lo, hi] with 0 <= lo <= hi '
                           f'(s), got {rng}')
    return Certificate(residual=(float(res[0]), float(res[1])),
                       lag=_pos('certified_lag', lag, zero=True),
                       adapt_range=(float(rng[0]), float(rng[1])) if rng else None,
                       hold=_pos('command period', hold, zero=True), source=source)


@dataclass(frozen=True)
class MonitorStatus:
    """The monitor's verdict: level, one-line message and the numbers behind it."""

    level: int
    message: str
    values: dict[str, Any]
    predict_latency: float          # the predictor latency the verdict is for

    @property
    def name(self) -> str:
        """``OK``, ``WARN``, ``ERROR`` or ``STALE``."""
        return LEVEL_NAMES[self.level]


def _ms(x: float) -> str:
    return f'{1e3 * x:.0f} ms' if math.isfinite(x) else 'n/a'


def evaluate(est: LatencyEstimate | None, cert: Certificate | None, predict_latency: float,
             settings: MonitorSettings = MonitorSettings(), *, adapting: bool = False
             ) -> MonitorStatus:
    """The status of an estimate against a certificate for the predictor latency ``P``.

    Parameters
    ----------
    est : LatencyEstimate or None
        The latest estimate (None: none yet).
    cert : Certificate or None
        The gain's certificate (None: unknown).
    predict_latency : float
        The predictor's latency in force (s).
    settings : MonitorSettings
        ``warn_margin``, ``tolerance``, ``lag_tolerance``.
    adapting : bool
        Adaptation is on (the message then says whether it can follow).
    """
    P = float(predict_latency)
    vals: dict[str, str] = {'predict_latency (s)': f'{P:.4f}'}
    if cert is not None:
        lo, hi = cert.interval(P)
        vals['certified latency (s)'] = f'[{lo:.4f}, {hi:.4f}]'
        vals['certified delay (s)'] = f'[{cert.residual[0]:.4f}, {cert.residual[1]:.4f}]'
        vals['command hold (s)'] = f'{cert.hold:.4f}'
        vals['certified lag (s)'] = f'{cert.lag:.4f}'
        if cert.adapt_range:
            vals['adaptation range (s)'] = f'[{cert.adapt_range[0]:.4f}, ' \
                                           f'{cert.adapt_range[1]:.4f}]'
    if est is not None:
        vals.update({'latency estimate (s)': f'{est.latency:.4f}',
                     'latency interval (s)': f'[{est.interval[0]:.4f}, {est.interval[1]:.4f}]',
                     'lag v (s)': f'{est.lag_v:.3f}', 'lag w (s)': f'{est.lag_w:.3f}',
                     'confidence': f'{est.confidence:.2f}',
                     'valid fraction': f'{est.valid_fraction:.2f}',
                     'window end (s)': f'{est.t_end:.3f}',
                     'excluded samples': ', '.join(f'{k}: {v}' for k, v in
                                                   est.excluded.items()) or 'none'})
    if cert is None:
        return MonitorStatus(STALE, 'no certified latency known for this gain (the gain file '
                             'records none): run ' + BRING_UP, vals, P)
    if est is None or not est.valid:
        why = 'no estimate yet' if est is None else est.reason
        return MonitorStatus(STALE, f'latency unknown: {why}', vals, P)
    L = est.latency
    lo, hi = cert.interval(P)
    where = f'latency {_ms(L)} (interval {_ms(est.interval[0])}-{_ms(est.interval[1])})'
    span = f'certified [{_ms(lo)}, {_ms(hi)}] with predict_latency {_ms(P)}'
    cannot = ''
    if adapting:
        if cert.adapt_range is None:
            cannot = '; cannot adapt: the gain file records no identified latency interval'
        else:
            a0, a1 = cert.adapt_range
            reach = (cert.interval(a0)[0], cert.interval(a1)[1])
            if L > reach[1] or L < reach[0] - settings.tolerance:
                cannot = (f'; cannot adapt: predict_latency is clamped to the identified '
                          f'interval [{_ms(a0)}, {_ms(a1)}], which certifies latencies in '
                          f'[{_ms(reach[0])}, {_ms(reach[1])}] only')
    if L > hi or L < lo - settings.tolerance:
        side = 'above' if L > hi else 'below (over-prediction)'
        return MonitorStatus(ERROR, f'{where} {side} the {span}: the certificate does not '
                             f'hold{cannot}; run the bring-up again: ' + BRING_UP, vals, P)
    notes = []
    if L > hi - settings.warn_margin:
        notes.append(f'{where} within {_ms(settings.warn_margin)} of the upper end of the '
                     f'{span}')
    lag = est.lag
    if math.isfinite(lag) and lag > cert.lag * (1 + settings.lag_tolerance) + settings.tolerance:
        notes.append(f'actuator lag {_ms(lag)} above the certified {_ms(cert.lag)}')
    if notes:
        return MonitorStatus(WARN, '; '.join(notes) + cannot, vals, P)
    return MonitorStatus(OK, _certified(L, P, cert, settings.tolerance, where, lo, hi), vals, P)


def _certified(L: float, P: float, cert: Certificate, tolerance: float, where: str, lo: float,
               hi: float) -> str:
    """The OK message, in the certificate's own terms: the residual delay plus the hold.

    The certificate bounds ``L - P`` plus the hold (0 to ``hold``) by ``[h_min, H]``, with
    ``tolerance`` below ``h_min`` (the estimator's precision), so a latency a few ms
    under ``P + h_min`` is certified: the message says so rather than "inside" an
    interval it is below.
    """
    r, h0, h1 = L - P, cert.residual[0], cert.residual[1]
    delay = (f'residual {_ms(r)} (latency - predict_latency {_ms(P)}) plus the hold 0 to '
             f'{_ms(cert.hold)}: {_ms(r)} to {_ms(r + cert.hold)},')
    span = f'the certified delay [{_ms(h0)}, {_ms(h1)}]'
    where_ok = (f'inside {span}' if L >= lo else
                f'{_ms(lo - L)} below the lower end of {span}, within the estimator\'s '
                f'tolerance {_ms(tolerance)}')
    return (f'{where}: {delay} {where_ok} (latency certified in [{_ms(lo)}, {_ms(hi)}])')


def adapted_prediction(est: LatencyEstimate, cert: Certificate, current: float,
                       settings: MonitorSettings = MonitorSettings()) -> float:
    """The predictor latency that keeps the estimated latency inside the certificate.

    ``P = L - min(r_lo + u, (r_lo + r_hi) / 2)`` with ``u`` the estimate's uncertainty
    (half its interval, at least ``tolerance``): the latency sits ``u`` above the
    certified lower end (under-prediction is the certified side) or, if the certified
    residual range is narrower than that, in its middle; clamped to ``cert.adapt_range``.
    Returns ``current`` if the estimate is not valid, the certificate has no range, the
    latency is inside the OK band for ``current`` (above ``current + r_lo - tolerance``,
    below the WARN margin: no change while nothing needs one) or the change is below half
    the tolerance (no chatter).

    Parameters
    ----------
    est : LatencyEstimate
        The monitor's latest estimate.
    cert : Certificate
        The gain's certificate (residual range, adaptation range).
    current : float
        The predictor's latency now (s).
    settings : MonitorSettings
        ``tolerance`` and ``warn_margin`` of the status.

    Returns
    -------
    float
        The predictor latency to use (s).
    """
    if not est.valid or cert.adapt_range is None:
        return current
    r0, r1 = cert.residual[0], cert.residual[1] - cert.hold
    if current + r0 - settings.tolerance <= est.latency <= current + r1 - settings.warn_margin:
        return current                   # OK as it is: the prediction stays (hysteresis)
    u = max(settings.tolerance, 0.5 * (est.interval[1] - est.interval[0]))
    target = est.latency - min(r0 + u, 0.5 * (r0 + r1))
    target = min(max(target, cert.adapt_range[0]), cert.adapt_range[1])
    if abs(target - current) < 0.5 * settings.tolerance:
        return current
    return float(target)


class SampleWindow:
    """Thread-safe bounded history of commands and odometry twist for the estimator.

    The tracker's callbacks append (one short lock each); a worker takes a snapshot
    (:meth:`arrays`) and runs :func:`estimate_latency` on it outside the lock.

    Parameters
    ----------
    span : float
        Keep this much history (s): the window plus the estimator's memory.
    """

    def __init__(self, span: float):
        self.span = float(span)
        self._lock = threading.Lock()
        self._cmd: deque[tuple[float, float, float]] = deque()
        self._odom: deque[tuple[float, float, float]] = deque()

    def add_command(self, t: float, v: float, w: float) -> None:
        """A command sent at ``t`` (s).

        Parameters
        ----------
        t : float
            Time it was sent (s).
        v, w : float
            Commanded speed (m/s) and yaw rate (rad/s).
        """
        with self._lock:
            self._cmd.append((t, v, w))
            while self._cmd and self._cmd[0][0] < t - self.span:
                self._cmd.popleft()

    def add_odometry(self, t: float, v: float, w: float) -> None:
        """An odometry twist measured at ``t`` (s).

        Parameters
        ----------
        t : float
            Measurement stamp (s).
        v, w : float
            Measured speed (m/s) and yaw rate (rad/s).
        """
        with self._lock:
            self._odom.append((t, v, w))
            while self._odom and self._odom[0][0] < t - self.span:
                self._odom.popleft()

    def __deepcopy__(self, memo: dict[int, Any]) -> SampleWindow:
        """A copy with the same samples and a lock of its own (a replay's trial forks)."""
        twin = SampleWindow(self.span)
        with self._lock:
            twin._cmd, twin._odom = deque(self._cmd), deque(self._odom)
        return twin

    def __getstate__(self) -> dict[str, Any]:
        """The samples without the lock (pickling: a replay's trials in other processes)."""
        with self._lock:
            return {'span': self.span, '_cmd': deque(self._cmd), '_odom': deque(self._odom)}

    def __setstate__(self, state: dict[str, Any]) -> None:
        """The samples, with a lock of their own."""
        self.__dict__.update(state)
        self._lock = threading.Lock()

    def clear(self) -> None:
        """Forget everything (e.g. after a stamp jump)."""
        with self._lock:
            self._cmd.clear()
            self._odom.clear()

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """Snapshot: commands ``(3, n)`` and odometry ``(3, m)`` as arrays."""
        with self._lock:
            c, o = list(self._cmd), list(self._odom)
        return (np.array(c, float).reshape(-1, 3).T, np.array(o, float).reshape(-1, 3).T)


class MonitorWorker:
    """A background thread that re-estimates the latency every ``period`` s (wall clock).

    The owner appends samples to ``window`` from its callbacks and reads
    ``latest`` whenever it reports; the estimate (a few milliseconds of numpy) never
    runs in the owner's callbacks.  :meth:`update` is the same work, synchronously (for
    simulations and tests).

    Parameters
    ----------
    settings : MonitorSettings
        Estimator settings (replace ``settings`` to change them at run time).
    period : float
        Seconds between estimates.
    """

    def __init__(self, settings: MonitorSettings, period: float = 1.0):
        self.settings = settings
        self.period = _pos('monitor period', period)
        self.window = SampleWindow(settings.window + settings.memory + 1.0)
        self.latest: LatencyEstimate | None = None
        self.estimates = 0
        self.compute_seconds = 0.0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def update(self) -> LatencyEstimate:
        """One estimate from the samples now in the window (stored in ``latest``)."""
        t0 = time.perf_counter()
        s = self.settings
        self.window.span = s.window + s.memory + 1.0
        c, o = self.window.arrays()
        try:
            est = estimate_latency(c[0], c[1], c[2], o[0], o[1], o[2], s)
        except (ValueError, FloatingPointError, MemoryError) as exc:   # never kill the thread
            est = LatencyEstimate(False, f'estimator failed: {exc}')
        self.latest = est
        self.estimates += 1
        self.compute_seconds += time.perf_counter() - t0
        return est

    def __getstate__(self) -> dict[str, Any]:
        """The settings, the window and the estimates, without the thread and its signal.

        A copy (``copy.deepcopy``, pickle: a replay's trial runs) has no thread running;
        :meth:`start` starts its own.
        """
        state = dict(self.__dict__)
        del state['_stop'], state['_thread']
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        """The state, with a stop signal of its own and no thread."""
        self.__dict__.update(state)
        self._stop = threading.Event()
        self._thread = None

    def _loop(self) -> None:
        while not self._stop.wait(self.period):
            self.update()

    def start(self) -> None:
        """Start the thread (daemon: it never keeps a process alive)."""
        if self._thread is None:
            self._thread = threading.Thread(target=self._loop, name='certificate-monitor',
                                            daemon=True)
            self._thread.start()

    def stop(self, timeout: float = 5.0) -> None:
        """Stop the thread and wait for it (at most one estimate) up to ``timeout`` s.

        An estimate still running then ends on its own (the thread is a daemon and only
        computes; the first estimate imports ``scipy.signal``, seconds on a busy machine).

        Parameters
        ----------
        timeout : float, optional
            Longest wait (s).
        """
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=timeout)
            self._thread = None
