"""Command-to-motion latency and actuator lag identified from recorded commands and odometry.

Model: first order plus dead time (FOPDT) per channel ``v``, ``w``, with one
command-to-motion latency ``L`` shared by both channels, the actuator time constants
``tau_v``, ``tau_w`` and static gains, fitted to the odometry twist (or to pose differences
over windows) on a fine time grid by linear least squares for all delays at once, then
polished together; the intervals come from a block bootstrap over time.  Speed saturation,
acceleration limits, stalls and glitches, latency jitter and commands not driven by the
odometry are detected and modelled or named.  The model, the measurements, the estimation,
the uncertainty and what is done about real recordings are in the documentation:
doc/theory.md, section "Latency identification" (#latency-identification).

Refusals (:class:`IdentificationError`, an :class:`~nonfragile_tracker.errors.InputError`):
too few samples or too short an overlap of commands and odometry, a channel whose command
hardly varies, a model that explains less than half of the measured variation or an
estimate at a search limit (the message names the likely cause: a base that does not
reach the commanded speeds, an odometry unrelated to the commands, or a response that is
not a lag; it never advises widening a search limit that would only fit a wrong model).

The file the latency-aware design reads (:func:`write_identification`,
:func:`read_identification`)::

    identification:
      source: runs/run_x/bag
      latency_s: 0.100
      latency_interval_s: [0.090, 0.110]
      tau_v_s: 0.050
      tau_v_interval_s: [0.045, 0.056]
      tau_w_s: 0.050
      tau_w_interval_s: [0.044, 0.057]
      odom_rate_hz: 50.0
      samples: 1234
      residual_rms: {v: 0.0012, w: 0.0031}
      command_period_s: 0.02          # optional: median period of the commands
      command_age_s: [0.0, 0.0]       # optional: age of the newest odometry at a command
                                      # (1st and 99th percentile; absent when the commands
                                      # were not driven by the odometry)
      latency_range_s: [0.119, 0.152] # optional: the range the latency VARIES over (per
                                      # command step, contains latency_interval_s)
      latency_range_from: 32 command steps (2.5-97.5 %)   # optional
      max_linear_accel: 1.0           # optional: m/s^2, 0 = not seen to bind (unknown)
      max_angular_accel: 3.0          # optional: rad/s^2, 0 = unknown
      accel_limits_from: rate-limited FOPDT fit (v binding 31 %, w binding 33 % ...)
      commands_follow_odometry: false # optional: a tracker (true) or a joystick (false)
      excluded_s: 0.33                # optional: seconds left out (stalls, glitches)

Two different latency figures: ``latency_interval_s`` is the uncertainty of the MEAN
latency (bootstrap: it shrinks with a longer recording); ``latency_range_s`` is the range
the latency actually takes from command to command (jitter: it does not shrink).  The
plan (:func:`.latency_design.plan_from_identification`) certifies the range.

``latency-design --identification FILE`` turns this into the delay interval it
certifies (:func:`.latency_design.plan_from_identification`).

Nothing here imports ROS; numpy, scipy and PyYAML only.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, cast

import numpy as np
import yaml

from ...errors import InputError
from ..validate import as_finite_float
from .errors import IdentificationError

__all__ = ['IdentificationError', 'CommandSamples', 'OdometrySamples', 'Identification',
           'identify_latency', 'write_identification', 'read_identification',
           'read_identification_text', 'with_source', 'measurement_to_command_delay',
           'commands_follow_odometry', 'MIN_EVENTS', 'FILE_KEY', 'MIN_ODOM_SAMPLES', 'MIN_R2']

#: Top-level key of the identification file.
FILE_KEY = 'identification'
#: Fewest odometry samples (after the overlap with the commands) a fit accepts.
MIN_ODOM_SAMPLES = 30
#: Fewest bootstrap blocks (time span / block length).
MIN_BLOCKS = 8
#: A channel's fit must explain at least this fraction of the measured variance.
MIN_R2 = 0.5
#: An acceleration limit is identified only if it binds at least this fraction of the time.
MIN_BINDING = 0.02
#: A spread of the step latencies (2.5-97.5 %) above this (s) is jitter: the lags are
#: then refitted with every step at the time it acted.
JITTER_REFIT_S = 0.005
#: ... and kept only if it lowers the normalized residual below this fraction of the
#: one-delay fit's (a spread from noise does not).
JITTER_GAIN = 0.8
#: Fewest command steps fitted one by one for a measured latency range.
MIN_EVENTS = 10
_CHANNELS = ('v', 'w')
_UNITS = {'v': 'm/s', 'w': 'rad/s'}
_NAMES = {'v': 'linear speed v', 'w': 'yaw rate w'}
_ACCEL_UNITS = {'v': 'm/s^2', 'w': 'rad/s^2'}


# ---------------------------------------------------------------------------------------------
# Data

def _series(name: str, value: Any, n: int | None = None) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f'{name} must be a sequence of numbers, got {value!r}') from None
    if arr.ndim != 1:
        raise InputError(f'{name} must be one-dimensional, got shape {arr.shape}')
    if n is not None and arr.size != n:
        raise InputError(f'{name} has {arr.size} samples, expected {n} (one per time stamp)')
    return arr


@dataclass(frozen=True)
class CommandSamples:
    """Velocity commands: time ``t`` (s), ``v`` (m/s) and ``w`` (rad/s), held until the next.

    ``t`` is the receive time (geometry_msgs/Twist) or the header stamp
    (TwistStamped), on the same clock as the odometry stamps.
    """

    t: np.ndarray
    v: np.ndarray
    w: np.ndarray

    def __post_init__(self) -> None:
        t = _series('command t', self.t)
        object.__setattr__(self, 't', t)
        object.__setattr__(self, 'v', _series('command v', self.v, t.size))
        object.__setattr__(self, 'w', _series('command w', self.w, t.size))

    def __len__(self) -> int:
        return int(self.t.size)


@dataclass(frozen=True)
class OdometrySamples:
    """Odometry by measurement time ``t`` (s): pose ``x``, ``y`` (m), ``yaw`` (rad).

    ``v`` (m/s) and ``w`` (rad/s) are the body twist (``twist.linear.x``,
    ``twist.angular.z``) or ``None`` when the source has none.
    """

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    yaw: np.ndarray
    v: np.ndarray | None = None
    w: np.ndarray | None = None

    def __post_init__(self) -> None:
        t = _series('odometry t', self.t)
        object.__setattr__(self, 't', t)
        for name in ('x', 'y', 'yaw', 'v', 'w'):
            val = getattr(self, name)
            if val is not None or name in ('x', 'y', 'yaw'):
                object.__setattr__(self, name, _series(f'odometry {name}', val, t.size))

    def __len__(self) -> int:
        return int(self.t.size)


@dataclass(frozen=True)
class Identification:
    """Identified latency and actuator lags with intervals (all times in s).

    The first block is what the identification file holds; the fields after
    ``source`` are diagnostics of :func:`identify_latency` (NaN, ``''`` or 0 when
    read back from a file).
    """

    latency_s: float
    latency_low_s: float
    latency_high_s: float
    tau_v_s: float
    tau_v_low_s: float
    tau_v_high_s: float
    tau_w_s: float
    tau_w_low_s: float
    tau_w_high_s: float
    odom_rate_hz: float
    samples: int
    residual_rms_v: float
    residual_rms_w: float
    source: str = ''
    #: static gains g_v, g_w (measured / commanded at steady state)
    gain_v: float = math.nan
    gain_w: float = math.nan
    #: fraction of the measured variance explained by the model
    r2_v: float = math.nan
    r2_w: float = math.nan
    #: 'twist' or 'pose' (what each channel was measured from)
    source_v: str = ''
    source_w: str = ''
    #: the latency each channel alone would give (a consistency check)
    latency_v_s: float = math.nan
    latency_w_s: float = math.nan
    confidence: float = math.nan
    resolution_s: float = math.nan
    duration_s: float = math.nan
    commands: int = 0
    bootstrap: int = 0
    notes: tuple[str, ...] = field(default=())
    #: median period of the commands (s; NaN: unknown) - the sample-and-hold of the loop
    command_period_s: float = math.nan
    #: age of the newest odometry when a command is sent, 1st / 99th percentile (s; NaN:
    #: unknown), see :func:`measurement_to_command_delay`
    command_age_low_s: float = math.nan
    command_age_high_s: float = math.nan
    #: the range the latency varies over from command to command (s; NaN: not measured,
    #: see :attr:`latency_range_s`) and what it was measured from
    latency_range_low_s: float = math.nan
    latency_range_high_s: float = math.nan
    latency_range_from: str = ''
    #: number of command steps whose latency was fitted one by one
    latency_events: int = 0
    #: acceleration limits of the base (m/s^2, rad/s^2; 0 = not seen to bind: unknown)
    max_linear_accel: float = 0.0
    max_angular_accel: float = 0.0
    #: fraction of the fitted time in which each limit binds (NaN: unknown)
    accel_binding_v: float = math.nan
    accel_binding_w: float = math.nan
    #: whether the commands were computed from the odometry (a tracker: True) or not (a
    #: joystick: False; their odometry age is then not recorded); None: unknown
    commands_follow_odometry: bool | None = None
    #: seconds excluded from the fit because the motion did not follow the commands
    excluded_s: float = 0.0

    @property
    def latency_interval_s(self) -> tuple[float, float]:
        """(low, high) of the latency interval (s): the uncertainty of the mean latency."""
        return (self.latency_low_s, self.latency_high_s)

    @property
    def latency_range_s(self) -> tuple[float, float]:
        """(low, high) the latency varies over (s), containing the interval of the mean.

        The interval of the mean (:attr:`latency_interval_s`) when the range was not
        measured (an older file, or too few distinct command steps).
        """
        lo, hi = self.latency_range_low_s, self.latency_range_high_s
        if not (math.isfinite(lo) and math.isfinite(hi)):
            return self.latency_interval_s
        return (min(lo, self.latency_low_s), max(hi, self.latency_high_s))


# ---------------------------------------------------------------------------------------------
# Model on the fine grid

#: One channel's measurements: (index a, index b or None, width or None, z, mid time) into
#: the odometry (a point sample reads index a; a pose window differences a and b).
_Measurement = tuple[np.ndarray, np.ndarray | None, np.ndarray | None, np.ndarray, np.ndarray]


def _check_times(name: str, t: np.ndarray) -> np.ndarray:
    if not np.all(np.isfinite(t)):
        raise InputError(f'{name}: time stamps must be finite')
    return np.argsort(t, kind='stable')


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
        sub.accel = self.accel
        return sub

    def signals(self, tau: float) -> tuple[np.ndarray, np.ndarray]:
        """Forced (zero initial state) and free (unit initial state) responses on the grid.

        With an acceleration limit (``accel > 0``) the forced response is the
        rate-limited lag's (nonlinear; the free response stays the linear one).
        """
        from scipy.signal import lfilter      # here: scipy.signal costs ~0.8 s to import
        n = self.u_avg.size + 1
        a = math.exp(-self.h / tau) if tau > 0 else 0.0
        if self.accel > 0:
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


def _fit_gain(ch: _Channel, pos: float, tau: float) -> float:
    """The static gain of the channel's fit at grid position ``pos``."""
    return float(_sse(_stats(ch, tau, np.array([pos]), None, 0), float(ch.z @ ch.z))[1][0])


def _choose_limits(chans: dict[str, '_Channel'], latency: float, tau_hat: dict[str, float],
                   max_tau_s: float, max_latency_s: float) -> dict[str, float]:
    """Per channel, the acceleration limit of a rate-limited FOPDT, or 0 if none explains more.

    Candidates around a high percentile (99 %) of the measured ``|ds/dt|`` (over 40 ms),
    each fitted over a local grid of latencies (the linear fit's ``pos`` - 0.1 s to
    + 0.03 s: a binding limit makes the linear fit late) and time constants; a limit is
    kept only if it lowers the residual by at least 5 % and binds at least
    :data:`MIN_BINDING` of the time; its value is refined by a parabola in ``log a``
    through the best candidate and its neighbours.
    """
    out = {}
    for c, ch in chans.items():
        h = ch.h
        z, tm = ch.z, ch.t_mid
        dtm = float(np.median(np.diff(tm))) if tm.size > 1 else h
        lag = max(1, int(round(0.04 / max(dtm, 1e-9))))
        if z.size <= lag + 10:
            out[c] = 0.0
            continue
        slope = np.abs(z[lag:] - z[:-lag]) / np.maximum(tm[lag:] - tm[:-lag], 1e-9)
        a0 = float(np.percentile(slope, 99))
        if not a0 > 0:
            out[c] = 0.0
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
        best_sse, best_tau = np.empty(cands.size), np.empty(cands.size)
        for i, a in enumerate(cands):
            sub.accel = float(a)
            per_tau = [float(_sse(_stats(sub, tau, shifts, None, 0), zz)[0].min())
                       for tau in grid]
            k = int(np.argmin(per_tau))
            best_sse[i], best_tau[i] = per_tau[k], grid[k]
        sub.accel = 0.0
        i = int(np.argmin(best_sse))
        if i == 0 or not best_sse[i] < 0.95 * best_sse[0]:
            out[c] = 0.0
            continue
        la = np.log(cands[1:])
        j = i - 1
        off = _parabola_min(best_sse[1:], j) if 0 < j < la.size - 1 else 0.0
        a = float(np.exp(la[j] + off * (la[1] - la[0])))
        # a limit that binds for a moment only (the steepest steps of a plain lag) is not
        # one: at least MIN_BINDING of the time
        ch.accel = a
        binds = _binding_fraction(ch, float(best_tau[i]), 0.0, 0.0, ch.u_avg.size * ch.h)
        ch.accel = 0.0
        out[c] = a if binds >= MIN_BINDING else 0.0
    return out


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


def _binding_fraction(ch: _Channel, tau: float, pos: float, t0: float, t1: float) -> float:
    """Fraction of ``[t0, t1]`` (s after the first command) in which the limit binds."""
    if ch.accel <= 0:
        return 0.0
    sig = _rate_limited_response(ch.u_avg, ch.h, tau, ch.accel)
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
                  meas: dict[str, _Measurement], keep: dict[str, np.ndarray] | None,
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


def _spans_of(meas: dict[str, _Measurement], keep: dict[str, np.ndarray]
              ) -> list[tuple[float, float]]:
    """Time spans (between kept samples) that hold excluded samples.

    From the first channel (both channels exclude the same spans).
    """
    out: list[tuple[float, float]] = []
    for c in _CHANNELS:
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
    for c in _CHANNELS:
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


def _poor_fit_cause(c: str, r2: float, source: str, ch: _Channel, u: np.ndarray, accel: float,
                    excluded_s: float) -> str:
    """The message of a fit that explains too little, naming the likely cause."""
    head = (f'the model explains only {100 * max(r2, 0):.0f} % of the measured {_NAMES[c]} '
            f'(from the odometry {source}; need >= {100 * MIN_R2:.0f} %)')
    tried = ('with a first-order lag' + (f', an acceleration limit {accel:.3g} {_ACCEL_UNITS[c]}'
                                         if accel > 0 else ' (no acceleration limit binds)')
             + (f' and {excluded_s:.2f} s of stalls excluded' if excluded_s else ''))
    umax = float(np.percentile(np.abs(u), 99))
    zmax = float(np.percentile(np.abs(ch.z), 99.5))
    if umax > 0 and zmax < 0.7 * umax:
        return (f'{head}, {tried}: the base does not reach the commanded {_NAMES[c]} '
                f'(commands up to {umax:.3g} {_UNITS[c]}, measured at most {zmax:.3g}): a '
                'speed limit of the base below the commands, or a wrong odometry scale. '
                'Record commands within the speed range of the base')
    if r2 < 0.1:
        return (f'{head}, {tried}: the odometry does not respond to these commands - check '
                'that both topics belong to the same robot and that the command times and '
                'odometry stamps are on one clock')
    return (f'{head}, {tried}: the base responds to the commands but not as a lag with '
            'dead time (a controller that overshoots or oscillates, wheel slip, long stalls); '
            'the latency of such a base is not identified here')


# ---------------------------------------------------------------------------------------------
# Measurements

def _window_measurements(t: np.ndarray, x: np.ndarray, y: np.ndarray, yaw: np.ndarray,
                         span: int) -> tuple[np.ndarray, ...]:
    """Window start/end indices, mean speed and mean yaw rate over windows of ``span`` samples."""
    th = np.unwrap(yaw)
    a = np.arange(t.size - span)
    b = a + span
    width = t[b] - t[a]
    dth = th[b] - th[a]
    thm = 0.5 * (th[a] + th[b])
    chord = (x[b] - x[a]) * np.cos(thm) + (y[b] - y[a]) * np.sin(thm)
    arc = chord / np.sinc(dth / (2 * np.pi))
    return a, b, width, arc / width, dth / width


def _twist_present(val: np.ndarray | None) -> bool:
    return val is not None and bool(np.all(np.isfinite(val))) and bool(np.any(val != 0.0))


# ---------------------------------------------------------------------------------------------
# Identification

def identify_latency(commands: CommandSamples, odometry: OdometrySamples, *,
                     max_latency_s: float = 1.0, max_tau_s: float = 1.0,
                     resolution_s: float = 0.001, source: str = 'auto',
                     window_s: float = 0.05, confidence: float = 0.95, bootstrap: int = 300,
                     seed: int = 0, command_timeout_s: float | None = None,
                     min_excitation: tuple[float, float] = (0.01, 0.01)) -> Identification:
    """Estimate the command-to-motion latency and the actuator time constants of a run.

    Parameters
    ----------
    commands : CommandSamples
        Velocity commands with their times (same clock as the odometry stamps).
    odometry : OdometrySamples
        Poses (and the body twist, if the source has one) by measurement time.
    max_latency_s, max_tau_s : float
        Search ranges ``[0, max]`` for the latency and the time constants.  The
        first ``max_latency_s`` of odometry after the first command is not fitted
        (its input is not known for every candidate latency).
    resolution_s : float
        Grid step of the model and of the latency search (sub-step refined).
    source : {'auto', 'twist', 'pose'}
        What the speeds are measured from: the odometry twist when present
        (``auto``: per channel, if not all zero) or differences of poses over
        windows of ``window_s``.
    window_s : float
        Shortest pose window (at least one odometry period) for ``source='pose'``.
    confidence : float
        Coverage of the bootstrap intervals (0.5 ... 0.999).
    bootstrap : int
        Number of block-bootstrap replicates (>= 50).
    seed : int
        Seed of the bootstrap resampling (the result is reproducible).
    command_timeout_s : float, optional
        If given, a command stops being held (input 0) this long after it was
        sent without a newer one, as a base with a cmd_vel watchdog does.
    min_excitation : (float, float)
        Smallest peak-to-peak command of ``v`` (m/s) and ``w`` (rad/s) accepted.

    Returns
    -------
    Identification
        Estimates, intervals, fit residuals, samples used and odometry rate.

    Raises
    ------
    IdentificationError
        Fewer than :data:`MIN_ODOM_SAMPLES` odometry samples overlap the commands
        (after the first ``max_latency_s``), or the overlap is too short for
        :data:`MIN_BLOCKS` bootstrap blocks.
        A channel's command varies less than ``min_excitation``.
        The model explains less than :data:`MIN_R2` of a channel's measured
        variance, or an estimate lies at a search limit.
    InputError
        Bad arguments (non-finite values, mismatched lengths, bad options).

    Notes
    -----
    The stages, each its own function: the options checked (``_check_options``),
    the samples sorted and gated into per-channel measurements (``_gather``), the
    commands' excitation checked (``_check_excitation``), the model fitted and
    extended where the recording needs it (``_Fit``: saturation, acceleration
    limits, excluded segments, jitter), the fit's quality checked
    (``_check_quality``), the block bootstrap (``_bootstrap``) and the
    :class:`Identification` assembled (``_report``).
    """
    _check_options(max_latency_s, max_tau_s, resolution_s, window_s, confidence, bootstrap,
                   source, command_timeout_s)
    data = _gather(commands, odometry, max_latency_s, source, window_s)
    _check_excitation(data, max_latency_s, min_excitation)
    fit = _Fit(data, float(resolution_s), max_latency_s, max_tau_s, command_timeout_s)
    # 1. the linear FOPDT
    fit.pos, fit.tau_hat, fit.lat_c = fit.search()
    # 1b. a base that cannot reach the commanded speeds; 2. acceleration limits; 3. segments
    # the base did not follow at all; 4. latency jitter
    fit.model_saturation()
    fit.model_limits()
    excluded = fit.exclude_gross_errors()
    events, _, _ = fit.model_jitter(excluded)
    quality = _check_quality(fit, excluded, max_latency_s, max_tau_s)
    pos_b, tau_b = _bootstrap(fit, np.random.default_rng(seed), int(bootstrap))
    return _report(commands, odometry, fit, quality, (pos_b, tau_b), events,
                   float(confidence), int(bootstrap))


def _check_options(max_latency_s: Any, max_tau_s: Any, resolution_s: Any, window_s: Any,
                   confidence: Any, bootstrap: Any, source: Any, command_timeout_s: Any
                   ) -> None:
    """Refuse bad options of :func:`identify_latency` (:class:`InputError`)."""
    for name, val, lo in (('max_latency_s', max_latency_s, 0.0), ('max_tau_s', max_tau_s, 0.0),
                          ('resolution_s', resolution_s, 0.0), ('window_s', window_s, 0.0)):
        if not (isinstance(val, (int, float)) and math.isfinite(val) and val > lo):
            raise InputError(f'{name} must be a finite number > {lo:g}, got {val!r}')
    if not 0.5 <= confidence <= 0.999:
        raise InputError(f'confidence must be in [0.5, 0.999], got {confidence!r}')
    if int(bootstrap) < 50:
        raise InputError(f'bootstrap must be at least 50 replicates, got {bootstrap!r}')
    if source not in ('auto', 'twist', 'pose'):
        raise InputError(f"source must be 'auto', 'twist' or 'pose', got {source!r}")
    if command_timeout_s is not None and not (math.isfinite(command_timeout_s)
                                              and command_timeout_s > 0):
        raise InputError(f'command_timeout_s must be > 0 s, got {command_timeout_s!r}')
    if resolution_s > 0.02:
        raise InputError(f'resolution_s must be at most 0.02 s, got {resolution_s!r}')


@dataclass
class _Data:
    """The samples of a run, sorted and gated into what the fit uses (see :func:`_gather`).

    ``tc``, ``cmd``: the commands by time; ``to``: the odometry times; ``use``: each
    channel's source (``twist`` or ``pose``); ``meas``: each channel's measurements in
    the fitted span ``[t_begin, t_end]`` (:data:`_Measurement`); ``block_len``,
    ``n_blocks``: the bootstrap's blocks over it.
    """

    tc: np.ndarray
    cmd: dict[str, np.ndarray]
    to: np.ndarray
    odom_rate: float
    use: dict[str, str]
    meas: dict[str, _Measurement]
    t_begin: float
    t_end: float
    duration: float
    block_len: float
    n_blocks: int
    notes: list[str] = field(default_factory=list)


def _gather(commands: CommandSamples, odometry: OdometrySamples, max_latency_s: float,
            source: str, window_s: float) -> _Data:
    """Sort the samples, choose each channel's source and keep the measurements fitted.

    Raises :class:`IdentificationError` for too few commands or odometry samples or too
    short an overlap, :class:`InputError` for non-finite values or a missing twist.
    """
    # -- commands
    if len(commands) < 10:
        raise IdentificationError(f'the run has {len(commands)} velocity commands; at least 10 '
                                  'are needed (record cmd_vel while the robot moves)')
    order = _check_times('command t', commands.t)
    tc = commands.t[order]
    cmd = {'v': commands.v[order], 'w': commands.w[order]}
    for c in _CHANNELS:
        if not np.all(np.isfinite(cmd[c])):
            raise InputError(f'command {c} has non-finite values')

    # -- odometry
    o = odometry
    order = _check_times('odometry t', o.t)
    to = o.t[order]
    first = np.concatenate([[True], np.diff(to) > 0])    # repeated stamps: keep the first
    idx = order[first]
    to = o.t[idx]
    x, y, yaw = o.x[idx], o.y[idx], o.yaw[idx]
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y)) and np.all(np.isfinite(yaw))):
        raise InputError('odometry poses have non-finite values')
    twist = {'v': None if o.v is None else o.v[idx], 'w': None if o.w is None else o.w[idx]}
    if to.size < MIN_ODOM_SAMPLES:
        raise IdentificationError(f'the run has {to.size} odometry samples; at least '
                                  f'{MIN_ODOM_SAMPLES} are needed')
    odom_period = float(np.median(np.diff(to)))
    odom_rate = 1.0 / odom_period

    t_first = tc[0] + max_latency_s            # earliest measurement with a known input
    t_last = tc[-1] + max(float(np.median(np.diff(tc))), 0.0)

    # -- channels and their measurements
    use = {}
    for c in _CHANNELS:
        if source == 'twist' and not _twist_present(twist[c]):
            raise InputError(f'source twist: the odometry has no {_NAMES[c]} twist (missing or '
                             "all zero); use source 'pose' or 'auto'")
        use[c] = 'twist' if source != 'pose' and _twist_present(twist[c]) else 'pose'
    span = max(1, int(math.ceil(window_s / odom_period - 1e-9)))
    wa, wb, width, zv_pose, zw_pose = _window_measurements(to, x, y, yaw, span)

    def measurement(c: str) -> _Measurement:
        """(index a, index b or None, width or None, z, mid time) into the odometry."""
        if use[c] == 'twist':
            ia = np.flatnonzero((to >= t_first) & (to <= t_last))
            return ia, None, None, cast(np.ndarray, twist[c])[ia], to[ia]
        sel = (to[wa] >= t_first) & (to[wb] <= t_last)
        z = (zv_pose if c == 'v' else zw_pose)[sel]
        return wa[sel], wb[sel], width[sel], z, 0.5 * (to[wa[sel]] + to[wb[sel]])

    meas = {c: measurement(c) for c in _CHANNELS}
    n_used = {c: meas[c][3].size for c in _CHANNELS}
    if min(n_used.values()) < MIN_ODOM_SAMPLES:
        raise IdentificationError(
            f'only {min(n_used.values())} odometry samples lie between {max_latency_s:g} s '
            f'after the first command and the last command (t = {tc[0]:.3f} ... {tc[-1]:.3f} '
            f's; odometry {to[0]:.3f} ... {to[-1]:.3f} s); at least {MIN_ODOM_SAMPLES} are '
            'needed: record a longer run, or lower max_latency_s (--max-latency)')
    t_end = max(float(to[np.max(m[1] if m[1] is not None else m[0])]) for m in meas.values())
    t_begin = min(float(to[np.min(m[0])]) for m in meas.values())
    duration = t_end - t_begin
    block_len = float(np.clip(duration / 20.0, 0.25, 2.0))
    n_blocks = int(duration // block_len) + 1
    if duration < MIN_BLOCKS * block_len:
        raise IdentificationError(
            f'commands and odometry overlap for {duration:.2f} s after the first '
            f'{max_latency_s:g} s; at least {MIN_BLOCKS * 0.25:g} s are needed for the '
            'uncertainty (block bootstrap): record a longer run')
    return _Data(tc, cmd, to, odom_rate, use, meas, t_begin, t_end, duration, block_len,
                 n_blocks)


def _check_excitation(data: _Data, max_latency_s: float,
                      min_excitation: tuple[float, float]) -> None:
    """Refuse a channel whose commands hardly vary (:class:`IdentificationError`).

    The commands over the fitted span and the latency range before it are looked at.
    """
    tc, t_begin, t_end = data.tc, data.t_begin, data.t_end
    for c, lo in zip(_CHANNELS, min_excitation):
        sel = (tc >= t_begin - max_latency_s) & (tc <= t_end)
        u = data.cmd[c][sel]
        ptp = float(np.ptp(u)) if u.size else 0.0
        changes = int(np.count_nonzero(np.diff(u))) if u.size > 1 else 0
        if ptp < lo or changes < 3:
            raise IdentificationError(
                f'the {_NAMES[c]} command hardly varies in the fitted span ({t_begin:.2f} ... '
                f'{t_end:.2f} s): peak-to-peak {ptp:.3g} {_UNITS[c]} (need >= {lo:g}), '
                f'{changes} changes; its lag and the latency cannot be seen. Record a run that '
                'varies both v and w (e.g. the figure eight), not a straight line or a hold')


class _Fit:
    """The FOPDT fit of a run: the grid, the channels and the current estimate.

    The held commands are cell-averaged on a grid of step ``h`` (``u_grid``);
    :meth:`make_channels` builds the channels (:class:`_Channel`) from them and the
    measurements (``keep``: the samples left after exclusions), :meth:`search` fits
    ``(latency, tau_v, tau_w)`` on the current channels ``chans``.  The estimate is
    ``pos`` (the latency in grid steps), ``tau_hat``, ``lat_c`` (each channel's own
    latency) and ``accel`` (the acceleration limits); the ``model_*`` stages refit it
    where the recording needs a richer model and add their ``notes``.
    """

    def __init__(self, data: _Data, h: float, max_latency_s: float, max_tau_s: float,
                 command_timeout_s: float | None):
        self.data, self.h = data, h
        self.notes = data.notes
        self.max_latency_s, self.max_tau_s = max_latency_s, max_tau_s
        self.command_timeout_s = command_timeout_s
        tc, t_end = data.tc, data.t_end
        # -- the grid: cell averages of the held commands
        n_cells = int(math.ceil((t_end - tc[0]) / h)) + 2
        self.s = tc[0] + h * np.arange(n_cells + 1)
        self.u_grid = {c: np.diff(_held_integral(tc, data.cmd[c], self.s, command_timeout_s))
                       / h for c in _CHANNELS}
        self.odom_pos = (data.to - tc[0]) / h
        # the rate-limited model costs a Python pass over the grid per simulation: its
        # coarse stages run on a grid of at most 5 ms (the coarse latency step is 10 ms)
        self.hc = h * max(1, int(round(0.005 / h))) if h < 0.005 else h
        self.coarse_inputs: dict[str, np.ndarray] = {}
        self.no_limit = {c: 0.0 for c in _CHANNELS}
        self.keep: dict[str, np.ndarray] | None = None
        self.chans = self.make_channels(None, self.no_limit)
        self.d_max = int(round(max_latency_s / h))
        self.taus = np.concatenate([[0.0], np.geomspace(max(2 * h, 0.002), max_tau_s, 24)])
        self.step = max(1, int(round(0.01 / h)))
        self.coarse_all = np.arange(0, self.d_max + 1, self.step, dtype=float)
        self.clips: dict[str, tuple[float, float, float]] = {}
        self.pos = 0.0
        self.tau_hat: dict[str, float] = {}
        self.lat_c: dict[str, float] = {}
        self.accel: dict[str, float] = dict(self.no_limit)

    def make_channels(self, keep: dict[str, np.ndarray] | None, accel: dict[str, float],
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
                 for c in _CHANNELS})
        for c in _CHANNELS:
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
            out[c] = ch
        return out

    def around(self, centre: float, half: int | None = None) -> np.ndarray:
        """Grid positions within ``half`` (default three coarse steps) of ``centre``."""
        half = 3 * self.step if half is None else half
        return np.arange(max(0, centre - half), min(self.d_max, centre + half) + 1,
                         dtype=float)

    def tau_range(self, k: int, n: int) -> np.ndarray:
        """``n`` time constants around the coarse grid's ``k``-th."""
        taus = self.taus
        return np.linspace(taus[max(0, k - 2)], taus[min(taus.size - 1, k + 2)], n)

    def local_taus(self, c: str, centre: float, spread: float) -> np.ndarray:
        """Time constants within a factor ``spread`` of ``centre`` (the bootstrap's grid)."""
        h = self.h
        lo = max(0.0, centre / spread - 2 * h * spread)
        hi = min(self.max_tau_s, centre * spread + 2 * h * spread)
        return np.linspace(lo, hi, 13 if self.chans[c].accel > 0 else 25)

    def grid_fit(self, shifts: np.ndarray, grids: dict[str, np.ndarray], blocks: bool
                 ) -> dict[str, tuple[np.ndarray, Any]]:
        """Block statistics (nd, ntau, 5, nb) per channel and zz per block."""
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
                 shifts: np.ndarray, grids: dict[str, np.ndarray]
                 ) -> tuple[float, dict[str, float], dict[str, float], Any]:
        """The estimate from (weighted) statistics.

        Returns (latency grid pos, {c: tau}, {c: channel latency pos}, the profile).
        """
        j: Any = 0.0                    # + the profiles: an array of the latency grid
        tau_hat, lat_c = {}, {}
        sse_all = {}
        for c in _CHANNELS:
            st, zz = stats[c]
            if weights is not None:
                st, zz = st @ weights, zz @ weights
            sse = _sse(st, zz)[0]                              # (nd, ntau)
            sse_all[c] = sse
            prof = sse.min(axis=1)
            j = j + prof / self.chans[c].sigma2
            i = int(np.argmin(prof))
            lat_c[c] = float(shifts[i]) + _parabola_min(prof, i)
        i = int(np.argmin(j))
        pos = float(shifts[i]) + _parabola_min(j, i)
        for c in _CHANNELS:
            row = sse_all[c][i]
            k = int(np.argmin(row))
            g = grids[c]
            tau_hat[c] = float(g[k] + _parabola_min(row, k) * (g[1] - g[0]))
        return pos, tau_hat, lat_c, j

    def search(self, near: float | None = None
               ) -> tuple[float, dict[str, float], dict[str, float]]:
        """Coarse, fine and polished fit of (latency, tau_v, tau_w) on ``chans``.

        Sets each channel's noise variance (``sigma2``); returns (latency grid position,
        time constants, each channel's own latency position).  With ``near`` (a grid
        position: a refit after a change of the model) the coarse grid spans +-0.1 s
        around it only.
        """
        h, chans, step, taus = self.h, self.chans, self.step, self.taus
        coarse = self.coarse_all if near is None else \
            self.coarse_all[np.abs(self.coarse_all - near) <= 0.1 / h + step]
        # coarse: 10 ms steps, at most ~1500 samples per channel
        sse_c = {}
        rough = (self.make_channels(self.keep, {c: chans[c].accel for c in _CHANNELS},
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
        prof_c = {c: sse_c[c].min(axis=1) for c in _CHANNELS}
        kbest = {c: np.argmin(sse_c[c], axis=1) for c in _CHANNELS}
        for c, ch in chans.items():
            i = int(np.argmin(prof_c[c]))
            zz = float(ch.z @ ch.z)
            best = min(float(_sse(_stats(ch, tau, self.around(coarse[i]), None, 0),
                                  zz)[0].min())
                       for tau in self.tau_range(int(kbest[c][i]), 9 if ch.accel > 0 else 17))
            ch.sigma2 = max(best / ch.z.size, 1e-12 * float(np.var(ch.z)), 1e-300)
        j_coarse = sum(prof_c[c] / chans[c].sigma2 for c in _CHANNELS)
        i_c = int(np.argmin(j_coarse))
        # fine: grid resolution around the coarse minimum, local time-constant grids
        tau_grid = {c: self.tau_range(int(kbest[c][i_c]), 13 if chans[c].accel > 0 else 25)
                    for c in _CHANNELS}
        fine = self.around(coarse[i_c])
        pos, tau0, lat_c, _ = self.estimate(self.grid_fit(fine, tau_grid, False), None, fine,
                                            tau_grid)
        if any(ch.accel > 0 for ch in chans.values()):
            p_l, t_l = self.polish_limited(pos, tau0, fine)
            return p_l, t_l, lat_c
        return self.polish(pos, tau0, lat_c)

    def polish(self, pos: float, tau0: dict[str, float], lat_c: dict[str, float]
               ) -> tuple[float, dict[str, float], dict[str, float]]:
        """Polish (latency, tau_v, tau_w) together (Nelder-Mead, in grid steps)."""
        from scipy.optimize import minimize
        h, max_tau_s = self.h, self.max_tau_s
        x0 = np.array([pos, max(tau0['v'], 0.0) / h, max(tau0['w'], 0.0) / h])
        j0 = self.objective(x0)
        simplex = np.vstack([x0, x0 + [0.5, 0, 0], x0 + [0, 0.5, 0], x0 + [0, 0, 0.5]])
        polish = minimize(self.objective, x0, method='Nelder-Mead',
                          bounds=[(0.0, float(self.d_max)), (0.0, max_tau_s / h),
                                  (0.0, max_tau_s / h)],
                          options={'initial_simplex': simplex, 'xatol': 0.01,
                                   'fatol': 1e-7 * j0 + 1e-12, 'maxfev': 200})
        if polish.fun <= j0:
            return float(polish.x[0]), {'v': float(polish.x[1]) * h,
                                        'w': float(polish.x[2]) * h}, lat_c
        return pos, {c: max(tau0[c], 0.0) for c in _CHANNELS}, lat_c

    def polish_limited(self, pos: float, tau0: dict[str, float], fine: np.ndarray
                       ) -> tuple[float, dict[str, float]]:
        """Rate-limited channels: (tau, limit) polished per channel, then the latency.

        Each channel at the latency found (each simulation of the nonlinear model costs
        a pass over the grid, so the channels are polished one by one), then the latency
        again on the fine grid.
        """
        from scipy.optimize import minimize
        h = self.h
        tau_hat = {c: max(tau0[c], 0.0) for c in _CHANNELS}
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
        """(residual sum of squares, gain) of channel ``c`` at latency ``p`` and ``tau``."""
        ch = self.chans[c]
        return _sse(_stats(ch, tau, np.array([p]), None, 0), float(ch.z @ ch.z))

    def objective(self, x: np.ndarray) -> float:
        """The normalized residual of ``x = (latency, tau_v, tau_w)`` in grid steps."""
        p, tv, tw = (float(v) for v in x)
        return sum(float(self.channel_sse(c, p, t * self.h)[0][0]) / self.chans[c].sigma2
                   for c, t in (('v', tv), ('w', tw)))

    def refit(self, keep: dict[str, np.ndarray] | None, accel: dict[str, float]) -> None:
        """New channels (samples ``keep``, limits ``accel``), refitted near the estimate."""
        self.chans = self.make_channels(keep, accel)
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
            self.notes.append(f'the base does not reach the commanded {_NAMES[c]}: it saturates '
                              f'at [{lo_c:.3g}, {hi_c:.3g}] {_UNITS[c]} (commands beyond that '
                              f'{100 * frac:.0f} % of the time); modelled by clipping the '
                              'commands')
        self.coarse_inputs.clear()
        self.refit(None, self.no_limit)

    def model_limits(self) -> None:
        """Acceleration limits: a rate-limited FOPDT where it explains the motion better."""
        accel = _choose_limits(self.make_channels(None, self.no_limit, self.hc),
                               self.pos * self.h, self.tau_hat, self.max_tau_s,
                               self.max_latency_s)
        if any(accel.values()):
            self.refit(None, accel)
            accel = {c: self.chans[c].accel for c in _CHANNELS}      # polished
        self.accel = accel

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
            self.refit(self.keep, self.accel)
            self.accel = {c: self.chans[c].accel for c in _CHANNELS}
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
        j_before = self.objective(np.array([pos, self.tau_hat['v'] / h,
                                            self.tau_hat['w'] / h]))
        for c in _CHANNELS:
            self.u_grid[c] = np.diff(_held_integral(tcw, cmd[c], self.s,
                                                    self.command_timeout_s)) / h
            if c in self.clips:
                self.u_grid[c] = np.clip(self.u_grid[c], self.clips[c][0], self.clips[c][1])
        self.coarse_inputs.clear()
        sig_before = {c: ch.sigma2 for c, ch in self.chans.items()}
        self.refit(self.keep, self.accel)
        self.accel = {c: self.chans[c].accel for c in _CHANNELS}
        j_after = sum(float(self.channel_sse(c, self.pos, self.tau_hat[c])[0][0])
                      / sig_before[c] for c in _CHANNELS)
        if j_after < JITTER_GAIN * j_before:
            self.notes.append(f'the latency jitters ({events.size} command steps over '
                              f'[{e_lo * h:.3f}, {e_hi * h:.3f}] s): the lags are fitted with '
                              'each step moved to the time it acted')
        else:                   # the steps' spread is noise: keep the one-delay fit
            self.u_grid.update(before[0])
            self.coarse_inputs.clear()
            self.chans, self.pos, self.tau_hat, self.lat_c, self.accel = before[1:]
        return events, ev_first, ev_last


@dataclass(frozen=True)
class _Quality:
    """The final fit's figures per channel (see :func:`_check_quality`)."""

    gains: dict[str, float]
    resid: dict[str, float]
    r2: dict[str, float]
    binding: dict[str, float]
    excluded_s: float


def _check_quality(fit: _Fit, excluded: list[tuple[float, float]], max_latency_s: float,
                   max_tau_s: float) -> _Quality:
    """Gains, residuals, R^2 and binding fractions of the final fit.

    Refuses a poor fit or an estimate at a search limit (:class:`IdentificationError`).
    """
    data, chans, pos, tau_hat = fit.data, fit.chans, fit.pos, fit.tau_hat
    tc = data.tc
    excluded_s = float(sum(b - a for a, b in excluded))
    gains, resid, r2 = {}, {}, {}
    for c, ch in chans.items():
        sse, g2 = fit.channel_sse(c, pos, tau_hat[c])
        gains[c] = float(g2[0])
        resid[c] = math.sqrt(float(sse[0]) / ch.z.size)
        var = float(np.var(ch.z))
        r2[c] = 1.0 - float(sse[0]) / (ch.z.size * var) if var > 0 else 0.0
    binding = {c: _binding_fraction(chans[c], tau_hat[c], pos, data.t_begin - tc[0],
                                    data.t_end - tc[0])
               for c in _CHANNELS}

    for c in _CHANNELS:
        if r2[c] < MIN_R2:
            raise IdentificationError(_poor_fit_cause(c, r2[c], data.use[c], chans[c],
                                                      data.cmd[c], fit.accel[c], excluded_s))
    if pos >= fit.d_max - 0.5:
        raise IdentificationError(f'the latency estimate is at the search limit '
                                  f'{max_latency_s:g} s: either the latency is longer (raise '
                                  'max_latency_s, --max-latency) or the odometry does not '
                                  'respond to these commands (another robot, another clock)')
    for c in _CHANNELS:
        if tau_hat[c] >= 0.999 * max_tau_s:
            raise IdentificationError(
                f'the {_NAMES[c]} time constant reaches the search limit {max_tau_s:g} s: the '
                f'measured {_NAMES[c]} does not follow the commands through a lag. Real '
                'actuator lags are tens of milliseconds; a fit this slow means something the '
                'model lacks (a speed limit below the commands, a base controller that '
                'overshoots, a base that stalls for long) - a larger max_tau_s would only fit '
                'that as a lag, with a wrong latency. Record commands within the base\'s speed '
                'range (e.g. the figure eight at a lower rate)')
    return _Quality(gains, resid, r2, binding, excluded_s)


def _bootstrap(fit: _Fit, rng: np.random.Generator, bootstrap: int
               ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Block bootstrap on a local grid (widened while estimates pile at an edge).

    Returns the replicates' latency grid positions and time constants.
    """
    pos, tau_hat, d_max, n_blocks = fit.pos, fit.tau_hat, fit.d_max, fit.data.n_blocks
    half = max(10, fit.step)
    spread = 1.6
    for attempt in range(3):
        centre = int(round(pos))
        shifts = np.arange(max(0, centre - half), min(d_max, centre + half) + 1, dtype=float)
        grids = {c: fit.local_taus(c, tau_hat[c], spread) for c in _CHANNELS}
        stats = fit.grid_fit(shifts, grids, True)
        pos_b, tau_b = np.empty(bootstrap), {c: np.empty(bootstrap) for c in _CHANNELS}
        for b in range(bootstrap):
            wts = np.bincount(rng.integers(0, n_blocks, n_blocks),
                              minlength=n_blocks).astype(float)
            p, t_, _, _ = fit.estimate(stats, wts, shifts, grids)
            pos_b[b] = p
            for c in _CHANNELS:
                tau_b[c][b] = t_[c]
        edge = np.mean((pos_b <= shifts[0] + 0.5) & (shifts[0] > 0)) + \
            np.mean((pos_b >= shifts[-1] - 0.5) & (shifts[-1] < d_max))
        tedge = max(np.mean((tau_b[c] >= grids[c][-1] - 1e-12) & (grids[c][-1] < fit.max_tau_s))
                    + np.mean((tau_b[c] <= grids[c][0] + 1e-12) & (grids[c][0] > 0))
                    for c in _CHANNELS)
        if edge <= 0.01 and tedge <= 0.01:
            break
        if edge > 0.01:
            half *= 3
        if tedge > 0.01:
            spread = spread ** 2
    else:
        fit.notes.append('bootstrap estimates reach the edge of the local search grid: the '
                         'intervals may be too narrow')
    return pos_b, tau_b


def _report(commands: CommandSamples, odometry: OdometrySamples, fit: _Fit, q: _Quality,
            replicates: tuple[np.ndarray, dict[str, np.ndarray]], events: np.ndarray,
            confidence: float, bootstrap: int) -> Identification:
    """Assemble the :class:`Identification`.

    Intervals at ``confidence`` from the bootstrap ``replicates``, the latency range from
    the command steps' ``events``, the commands' period and age, and the notes.
    """
    data, h, pos, tau_hat, lat_c, accel = fit.data, fit.h, fit.pos, fit.tau_hat, fit.lat_c, \
        fit.accel
    notes, tc, max_latency_s = fit.notes, data.tc, fit.max_latency_s
    pos_b, tau_b = replicates
    latency = pos * h
    alpha = 0.5 * (1.0 - confidence)

    def interval(values: np.ndarray, point: float, floor: float = 0.0) -> tuple[float, float]:
        lo, hi = np.quantile(values, [alpha, 1.0 - alpha])
        lo = max(floor, min(float(lo), point) - h)
        return lo, max(float(hi), point) + h

    lat_lo, lat_hi = interval(pos_b * h, latency)
    tv_lo, tv_hi = interval(tau_b['v'], tau_hat['v'])
    tw_lo, tw_hi = interval(tau_b['w'], tau_hat['w'])
    if abs(lat_c['v'] - lat_c['w']) * h > max(lat_hi - lat_lo, 2 * h) * 2:
        notes.append(f'the channels alone give different latencies (v {lat_c["v"] * h:.4f} s, '
                     f'w {lat_c["w"] * h:.4f} s)')

    # -- the range the latency varies over: one latency per distinct command step
    if events.size >= MIN_EVENTS:
        e_lo, e_hi = (float(x) for x in np.percentile(events * h, [2.5, 97.5]))
        # two grid steps either side for the sub-step error of one step's fit
        rng_lo, rng_hi = max(0.0, min(e_lo - 2 * h, lat_lo)), max(e_hi + 2 * h, lat_hi)
        range_from = f'{events.size} command steps (2.5-97.5 %)'
    else:
        rng_lo, rng_hi = lat_lo, lat_hi
        range_from = 'interval of the mean'
        notes.append(f'only {events.size} distinct command steps: how much the latency varies '
                     'from command to command is not measured (the range is the interval of '
                     'the mean); a joystick drive with steps in v and w measures it')

    fitted = (tc >= data.t_begin - max_latency_s) & (tc <= data.t_end)
    used = np.sort(tc[fitted])
    period = float(np.median(np.diff(used))) if used.size > 1 else math.nan
    age_lo, _, age_hi = measurement_to_command_delay(commands, odometry)
    driven = commands_follow_odometry(commands, odometry)
    if driven is False:
        notes.append('the commands are not driven by the odometry (a joystick or script: their '
                     'age since the newest odometry is spread over the odometry period); that '
                     'age is not the tracker\'s and is not recorded')
        age_lo = age_hi = math.nan
    for c, name in (('v', 'linear'), ('w', 'angular')):
        if accel[c] > 0:
            notes.append(f'{name} acceleration limit {accel[c]:.3g} {_ACCEL_UNITS[c]} (binding '
                         f'{100 * q.binding[c]:.0f} % of the fitted time; rate-limited FOPDT)')
    return Identification(
        latency_s=latency, latency_low_s=lat_lo, latency_high_s=lat_hi,
        tau_v_s=tau_hat['v'], tau_v_low_s=tv_lo, tau_v_high_s=tv_hi,
        tau_w_s=tau_hat['w'], tau_w_low_s=tw_lo, tau_w_high_s=tw_hi,
        odom_rate_hz=data.odom_rate, samples=int(max(ch.z.size for ch in fit.chans.values())),
        residual_rms_v=q.resid['v'], residual_rms_w=q.resid['w'],
        gain_v=q.gains['v'], gain_w=q.gains['w'], r2_v=q.r2['v'], r2_w=q.r2['w'],
        source_v=data.use['v'], source_w=data.use['w'],
        latency_v_s=lat_c['v'] * h, latency_w_s=lat_c['w'] * h,
        confidence=float(confidence), resolution_s=h, duration_s=data.duration,
        commands=int(np.count_nonzero(fitted)),
        bootstrap=int(bootstrap), notes=tuple(notes),
        command_period_s=period if period > 0 else math.nan,
        command_age_low_s=max(age_lo, 0.0) if math.isfinite(age_lo) else math.nan,
        command_age_high_s=max(age_hi, 0.0) if math.isfinite(age_hi) else math.nan,
        latency_range_low_s=rng_lo, latency_range_high_s=rng_hi,
        latency_range_from=range_from, latency_events=int(events.size),
        max_linear_accel=accel['v'], max_angular_accel=accel['w'],
        accel_binding_v=q.binding['v'], accel_binding_w=q.binding['w'],
        commands_follow_odometry=driven, excluded_s=q.excluded_s)


def commands_follow_odometry(commands: CommandSamples, odometry: OdometrySamples
                             ) -> bool | None:
    """Whether the commands were computed from the odometry (a tracker) or not (a joystick).

    A tracker sends each command a nearly constant time after the odometry it used:
    the age of the newest odometry at a command (see :func:`measurement_to_command_delay`)
    varies little.  Commands from a joystick or a script come at times of their own, so
    that age spreads over the odometry period.  The commands follow the odometry when
    the 10-90 % spread of the age is below a quarter of the odometry period.

    Parameters
    ----------
    commands, odometry : CommandSamples, OdometrySamples
        The recording.

    Returns
    -------
    bool or None
        None when fewer than 10 commands follow an odometry sample.
    """
    to = np.unique(np.asarray(odometry.t, dtype=float))
    tc = np.asarray(commands.t, dtype=float)
    if to.size < 2:
        return None
    j = np.searchsorted(to, tc, side='right') - 1
    age = tc[j >= 0] - to[j[j >= 0]]
    if age.size < 10:
        return None
    p10, p90 = np.percentile(age, [10, 90])
    return bool(p90 - p10 < 0.25 * float(np.median(np.diff(to))))


def measurement_to_command_delay(commands: CommandSamples, odometry: OdometrySamples
                                 ) -> tuple[float, float, float]:
    """How old the newest odometry sample is when each command is sent: (low, median, high).

    For each command, ``t_cmd - t_odom`` with ``t_odom`` the newest odometry stamp not
    after it (commands before the first odometry are skipped); low and high are the 1st
    and 99th percentiles.  A tracker triggered by odometry shows its transport and
    computation time here; a timer-driven one up to an odometry period.  With the
    latency ``L`` (from the command) the loop's delay from measurement to motion is
    this plus ``L``, plus up to one command period while a command is held.

    Parameters
    ----------
    commands : CommandSamples
        The commands with the times they were sent.
    odometry : OdometrySamples
        The odometry by measurement stamp.

    Returns
    -------
    (float, float, float)
        Seconds; NaN if no command follows an odometry sample.
    """
    to = np.sort(odometry.t)
    tc = np.asarray(commands.t, dtype=float)
    j = np.searchsorted(to, tc, side='right') - 1
    d = tc[j >= 0] - to[j[j >= 0]]
    if d.size == 0:
        return (math.nan, math.nan, math.nan)
    lo, med, hi = np.percentile(d, [1, 50, 99])
    return (float(lo), float(med), float(hi))


# ---------------------------------------------------------------------------------------------
# File

def _num(x: float) -> str:
    return f'{float(x):.6g}' if abs(x) >= 1e-4 or x == 0 else f'{float(x):.6e}'


def write_identification(path: str | os.PathLike[str], result: Identification, *,
                         overwrite: bool = True) -> Path:
    """Write ``result`` as the identification file the latency-aware design reads.

    Parameters
    ----------
    path : path-like
        File to write (YAML; the format is in the module docstring).
    result : Identification
        What :func:`identify_latency` returned (``source`` set by the caller, e.g.
        ``dataclasses.replace(result, source=str(bag))``).
    overwrite : bool
        If False, an existing file raises ``FileExistsError``.

    Returns
    -------
    pathlib.Path
        The path written.
    """
    p = Path(path)
    if not overwrite and p.exists():
        raise FileExistsError(f'{p} exists; pass --force to overwrite it')
    src = yaml.safe_dump(str(result.source), default_style=None).strip()
    if src.endswith('...'):
        src = src[:-3].strip()
    lines = [
        '# Command-to-motion latency and actuator lags identified by '
        '`nonfragile_tracker identify`',
        f'# (intervals: {100 * result.confidence:.0f} % block bootstrap; '
        f'tau_v/tau_w: first-order lag of v/w; residual_rms in m/s and rad/s)'
        if math.isfinite(result.confidence) else '# (intervals: as given)',
        f'{FILE_KEY}:',
        f'  source: {src}',
        f'  latency_s: {_num(result.latency_s)}',
        f'  latency_interval_s: [{_num(result.latency_low_s)}, {_num(result.latency_high_s)}]',
        f'  tau_v_s: {_num(result.tau_v_s)}',
        f'  tau_v_interval_s: [{_num(result.tau_v_low_s)}, {_num(result.tau_v_high_s)}]',
        f'  tau_w_s: {_num(result.tau_w_s)}',
        f'  tau_w_interval_s: [{_num(result.tau_w_low_s)}, {_num(result.tau_w_high_s)}]',
        f'  odom_rate_hz: {_num(result.odom_rate_hz)}',
        f'  samples: {int(result.samples)}',
        f'  residual_rms: {{v: {_num(result.residual_rms_v)}, w: {_num(result.residual_rms_w)}}}',
    ]
    if math.isfinite(result.command_period_s):
        lines.append(f'  command_period_s: {_num(result.command_period_s)}')
    if math.isfinite(result.command_age_low_s) and math.isfinite(result.command_age_high_s):
        lines.append(f'  command_age_s: [{_num(max(result.command_age_low_s, 0.0))}, '
                     f'{_num(max(result.command_age_high_s, 0.0))}]')
    if math.isfinite(result.latency_range_low_s) and math.isfinite(result.latency_range_high_s):
        lo, hi = result.latency_range_s
        lines.append(f'  latency_range_s: [{_num(lo)}, {_num(hi)}]   # the range the latency '
                     'varies over (latency_interval_s: the uncertainty of its mean)')
        if result.latency_range_from:
            lines.append(f'  latency_range_from: {_yaml_str(result.latency_range_from)}')
    lines.append(f'  max_linear_accel: {_num(result.max_linear_accel)}     # m/s^2, 0 = unknown')
    lines.append(f'  max_angular_accel: {_num(result.max_angular_accel)}    # rad/s^2, 0 = unknown')
    how = _accel_from(result)
    if how:
        lines.append(f'  accel_limits_from: {_yaml_str(how)}')
    if result.commands_follow_odometry is not None:
        lines.append('  commands_follow_odometry: '
                     f'{"true" if result.commands_follow_odometry else "false"}')
    if result.excluded_s > 0:
        lines.append(f'  excluded_s: {_num(result.excluded_s)}')
    text = '\n'.join(lines) + '\n'
    read_identification_text(text, str(p))            # never write what cannot be read back
    p.write_text(text)
    return p


_FIELDS = ('source', 'latency_s', 'latency_interval_s', 'tau_v_s', 'tau_v_interval_s',
           'tau_w_s', 'tau_w_interval_s', 'odom_rate_hz', 'samples', 'residual_rms')
_OPTIONAL = ('command_period_s', 'command_age_s', 'latency_range_s', 'latency_range_from',
             'max_linear_accel', 'max_angular_accel', 'accel_limits_from',
             'commands_follow_odometry', 'excluded_s')


def _yaml_str(text: str) -> str:
    out = yaml.safe_dump(str(text), default_style=None, width=1000).strip()
    return out[:-3].strip() if out.endswith('...') else str(out)


def _accel_from(result: Identification) -> str:
    parts = []
    for name, a, frac in (('v', result.max_linear_accel, result.accel_binding_v),
                          ('w', result.max_angular_accel, result.accel_binding_w)):
        if a > 0 and math.isfinite(frac):
            parts.append(f'{name} binding {100 * frac:.0f} %')
    if not parts:
        return ''
    return 'rate-limited FOPDT fit (' + ', '.join(parts) + ' of the fitted time)'


def _text(where: str, key: str, value: Any) -> str:
    if not isinstance(value, str):
        raise IdentificationError(f'{where}: {FILE_KEY}.{key} must be a string, got '
                                  f'{value!r}')
    return value


def _number(where: str, key: str, value: Any, *, positive: bool = False) -> float:
    return as_finite_float(value, f'{where}: {FILE_KEY}.{key}', low=0.0,
                           low_inclusive=not positive, error=IdentificationError)


def _pair(where: str, key: str, value: Any, point: float) -> tuple[float, float]:
    if not isinstance(value, (list, tuple)) or len(value) != 2:
        raise IdentificationError(f'{where}: {FILE_KEY}.{key} must be a list [low, high] '
                                  f'of two numbers, got {value!r}')
    lo = _number(where, f'{key}[0]', value[0])
    hi = _number(where, f'{key}[1]', value[1])
    if not lo <= point <= hi:
        raise IdentificationError(f'{where}: {FILE_KEY}.{key} = [{lo:g}, {hi:g}] must '
                                  f'contain the estimate {point:g} (low <= value <= high)')
    return lo, hi


def read_identification_text(text: str, where: str = '<text>') -> Identification:
    """Parse and validate the text of an identification file (see :func:`read_identification`).

    Parameters
    ----------
    text : str
        The YAML text.
    where : str
        What the text is, for the messages (a file name).

    Returns
    -------
    Identification

    Raises
    ------
    IdentificationError
        The text is not YAML, has no ``identification`` mapping, or a field is missing or
        out of range, or unknown (the message names it).
    """
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise IdentificationError(f'{where} is not valid YAML: {exc}') from None
    if not isinstance(data, dict) or not isinstance(data.get(FILE_KEY), dict):
        raise IdentificationError(f'{where}: expected a mapping with the key {FILE_KEY!r} '
                                  '(written by `nonfragile_tracker identify BAG -o FILE`)')
    d = data[FILE_KEY]
    missing = [k for k in _FIELDS if k not in d]
    if missing:
        raise IdentificationError(f'{where}: {FILE_KEY} lacks the field(s) '
                                  f'{", ".join(missing)}')
    unknown = sorted(set(map(str, d)) - set(_FIELDS) - set(_OPTIONAL))
    if unknown:
        raise IdentificationError(f'{where}: {FILE_KEY} has unknown field(s) '
                                  f'{", ".join(unknown)}; known: '
                                  f'{", ".join(_FIELDS + _OPTIONAL)}')
    if not isinstance(d['source'], str):
        raise IdentificationError(f'{where}: {FILE_KEY}.source must be a string (the bag '
                                  f'path), got {d["source"]!r}')
    lat = _number(where, 'latency_s', d['latency_s'])
    lat_lo, lat_hi = _pair(where, 'latency_interval_s', d['latency_interval_s'], lat)
    tv = _number(where, 'tau_v_s', d['tau_v_s'])
    tv_lo, tv_hi = _pair(where, 'tau_v_interval_s', d['tau_v_interval_s'], tv)
    tw = _number(where, 'tau_w_s', d['tau_w_s'])
    tw_lo, tw_hi = _pair(where, 'tau_w_interval_s', d['tau_w_interval_s'], tw)
    rate = _number(where, 'odom_rate_hz', d['odom_rate_hz'], positive=True)
    n = d['samples']
    if isinstance(n, bool) or not isinstance(n, int) or n <= 0:
        raise IdentificationError(f'{where}: {FILE_KEY}.samples must be a positive '
                                  f'integer, got {n!r}')
    rr = d['residual_rms']
    if not isinstance(rr, dict) or set(rr) != {'v', 'w'}:
        raise IdentificationError(f'{where}: {FILE_KEY}.residual_rms must be a mapping '
                                  f'{{v: ..., w: ...}}, got {rr!r}')
    rv = _number(where, 'residual_rms.v', rr['v'])
    rw = _number(where, 'residual_rms.w', rr['w'])
    period = (_number(where, 'command_period_s', d['command_period_s'], positive=True)
              if 'command_period_s' in d else math.nan)
    age = (math.nan, math.nan)
    if 'command_age_s' in d:
        a = d['command_age_s']
        if not isinstance(a, (list, tuple)) or len(a) != 2:
            raise IdentificationError(f'{where}: {FILE_KEY}.command_age_s must be a list '
                                      f'[low, high] of two numbers, got {a!r}')
        age = _pair(where, 'command_age_s', a, _number(where, 'command_age_s[0]', a[0]))
    rng = (math.nan, math.nan)
    if 'latency_range_s' in d:
        rng = _pair(where, 'latency_range_s', d['latency_range_s'], lat)
    _text(where, 'accel_limits_from', d.get('accel_limits_from', ''))
    driven = d.get('commands_follow_odometry')
    if driven is not None and not isinstance(driven, bool):
        raise IdentificationError(f'{where}: {FILE_KEY}.commands_follow_odometry must be '
                                  f'true or false, got {driven!r}')
    return Identification(lat, lat_lo, lat_hi, tv, tv_lo, tv_hi, tw, tw_lo, tw_hi, rate, n,
                          rv, rw, source=d['source'], command_period_s=period,
                          command_age_low_s=age[0], command_age_high_s=age[1],
                          latency_range_low_s=rng[0], latency_range_high_s=rng[1],
                          latency_range_from=_text(where, 'latency_range_from',
                                                   d.get('latency_range_from', '')),
                          max_linear_accel=_number(where, 'max_linear_accel',
                                                   d.get('max_linear_accel', 0.0)),
                          max_angular_accel=_number(where, 'max_angular_accel',
                                                    d.get('max_angular_accel', 0.0)),
                          commands_follow_odometry=driven,
                          excluded_s=_number(where, 'excluded_s', d.get('excluded_s', 0.0)))


def read_identification(path: str | os.PathLike[str]) -> Identification:
    """Read and validate an identification file written by :func:`write_identification`.

    Parameters
    ----------
    path : path-like
        The YAML file.

    Returns
    -------
    Identification
        The stored fields; diagnostics not stored in the file are NaN/empty.

    Raises
    ------
    IdentificationError
        Naming the field that is missing, unknown, of the wrong type, negative,
        non-finite, or an interval that does not contain its estimate.
    FileNotFoundError
        If ``path`` does not exist.
    """
    p = Path(path)
    if p.is_dir():
        raise IdentificationError(f'{p} is a directory; pass the identification YAML file '
                                  '(e.g. latency.yaml written by `identify -o`)')
    return read_identification_text(p.read_text(), str(p))


def with_source(result: Identification, source: str | os.PathLike[str]) -> Identification:
    """``result`` with its ``source`` (the bag path) set.

    Parameters
    ----------
    result : Identification
        An identification.
    source : str or os.PathLike
        Where its data came from (written to the file's ``source``).

    Returns
    -------
    Identification
    """
    return replace(result, source=str(source))
