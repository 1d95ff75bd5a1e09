"""Command-to-motion latency and actuator lag identified from recorded commands and odometry.

Model: first order plus dead time (FOPDT) per channel ``v``, ``w``, one latency ``L``
shared by both, fitted on a fine time grid for all delays at once, then polished; the
intervals come from a block bootstrap over time; acceleration limits, stalls and glitches,
latency jitter and commands not driven by the odometry are modelled or named.  Refusals
(:class:`~.errors.IdentificationError`) name the likely cause.  The fit itself is
:mod:`.lag_fit`; the inputs, the result and the file are :mod:`.records`; ``latency-design
--identification FILE`` turns the result into the delay interval it certifies.  Nothing
here imports ROS; numpy and scipy only.

See doc/theory.md, section "Latency identification" (#latency-identification), and
doc/tutorial.md, section "Identify the latency (``identify``)" (the refusals).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, cast

import numpy as np

from ...errors import InputError
from .errors import (IdentificationError, InsufficientExcitationError, NotEnoughDataError,
                     PoorFitError)
from .lag_fit import (ACCEL_UNITS, NAMES, CHANNELS, MIN_EVENTS, UNITS, Fit, FitData,
                      Measurement, binding_fraction)
# the records, importable from here as before (explicit re-exports)
from .records import (FILE_KEY, CommandSamples, Identification, OdometrySamples,
                      read_identification, read_identification_text, with_source,
                      write_identification)

__all__ = ['IdentificationError', 'CommandSamples', 'OdometrySamples', 'Identification',
           'identify_latency', 'write_identification', 'read_identification',
           'read_identification_text', 'with_source', 'measurement_to_command_delay',
           'commands_follow_odometry', 'MIN_EVENTS', 'FILE_KEY', 'MIN_ODOM_SAMPLES', 'MIN_R2',
           'twist_disagreement']

#: Fewest odometry samples (after the overlap with the commands) a fit accepts.
MIN_ODOM_SAMPLES = 30
#: Fewest bootstrap blocks (time span / block length).
MIN_BLOCKS = 8
#: A channel's fit must explain at least this fraction of the measured variance.
MIN_R2 = 0.5


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
        (``auto``: per channel, if not all zero and it integrates to the poses,
        :func:`twist_disagreement`; else the poses, and a refusal names both when
        the poses do not fit either) or differences of poses over windows of
        ``window_s``.
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
    extended where the recording needs it (``Fit``: saturation, acceleration
    limits, excluded segments, jitter), the fit's quality checked
    (``_check_quality``), the block bootstrap (``_bootstrap``) and the
    :class:`.Identification` assembled (``_report``).
    """
    _check_options(max_latency_s, max_tau_s, resolution_s, window_s, confidence, bootstrap,
                   source, command_timeout_s)
    data = _gather(commands, odometry, max_latency_s, source, window_s)
    args = (max_latency_s, max_tau_s, resolution_s, confidence, bootstrap, seed,
            command_timeout_s, min_excitation)
    if not data.disagree:
        return _identify(commands, odometry, data, *args)
    # the twist does not integrate to the poses: the source whose fit is the base's motion
    try:
        by_pose = _identify(commands, odometry, data, *args)
    except IdentificationError as exc:
        raise type(exc)(f'{"; ".join(data.disagree.values())}; the poses alone do not '
                        f'identify the base either: {exc}. Neither source is fitted (the '
                        "twist is not the base's motion): check what the driver publishes "
                        "as the twist, or force one with source 'twist' / --source twist"
                        ) from None
    try:
        by_twist = _identify(commands, odometry, _gather(commands, odometry, max_latency_s,
                                                         source, window_s, check=False), *args)
    except IdentificationError:
        return by_pose
    return _choose_source(by_twist, by_pose, data.disagree)


#: The twist's and the poses' fits agree when the latencies are this close (s) and each lag
#: within this (s) or :data:`AGREE_LAG_REL` of the larger.
AGREE_LATENCY_S = 0.01
#: Absolute agreement of the two fits' lags (s).
AGREE_LAG_S = 0.01
#: Relative agreement of the two fits' lags (of the larger).
AGREE_LAG_REL = 0.2


def _choose_source(by_twist: Identification, by_pose: Identification,
                   disagree: dict[str, str]) -> Identification:
    """The twist's fit if the poses' gives the same timing, else the poses' fit (noted).

    The same timing: the disagreement does not bias it, and the twist is the less noisy
    measurement of the two.
    """
    def timing(r: Identification) -> str:
        return (f'latency {r.latency_s:.4f} s, lags {r.tau_v_s:.4f} / {r.tau_w_s:.4f} s, '
                f'gains {r.gain_v:.3f} / {r.gain_w:.3f}')
    agree = abs(by_twist.latency_s - by_pose.latency_s) <= AGREE_LATENCY_S and all(
        abs(a - b) <= max(AGREE_LAG_S, AGREE_LAG_REL * max(a, b))
        for a, b in ((by_twist.tau_v_s, by_pose.tau_v_s), (by_twist.tau_w_s, by_pose.tau_w_s)))
    if agree:
        notes = [n for n in by_twist.notes] + [
            f'{d}; the poses give the same timing ({timing(by_pose)}): the twist is kept'
            for d in disagree.values()]
        return replace(by_twist, notes=tuple(notes))
    return replace(by_pose, notes=tuple(by_pose.notes) + (
        f'the twist alone gives another timing ({timing(by_twist)}); the poses give '
        f'{timing(by_pose)}',))


def _identify(commands: CommandSamples, odometry: OdometrySamples, data: FitData,
              max_latency_s: float, max_tau_s: float, resolution_s: float, confidence: float,
              bootstrap: int, seed: int, command_timeout_s: float | None,
              min_excitation: tuple[float, float]) -> Identification:
    """The stages of :func:`identify_latency` after the samples are gathered."""
    _check_excitation(data, max_latency_s, min_excitation)
    fit = Fit(data, float(resolution_s), max_latency_s, max_tau_s, command_timeout_s)
    # 1. the linear FOPDT
    fit.pos, fit.tau_hat, fit.lat_c = fit.search()
    # 1b. a base that cannot reach the commanded speeds; 2. acceleration limits; 3. segments
    # the base did not follow at all; 4. latency jitter
    fit.model_saturation()
    fit.model_limits()
    excluded = fit.exclude_gross_errors()
    fit.drop_unseen_limits()
    events, _, _ = fit.model_jitter(excluded)
    quality = _check_quality(fit, excluded, max_latency_s, max_tau_s)
    replicates = _bootstrap(fit, np.random.default_rng(seed), int(bootstrap))
    return _report(commands, odometry, fit, quality, replicates, events,
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


def _check_times(name: str, t: np.ndarray) -> np.ndarray:
    if not np.all(np.isfinite(t)):
        raise InputError(f'{name}: time stamps must be finite')
    return np.argsort(t, kind='stable')


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


#: Window (s) over which the twist's integral is compared with the motion of the poses.
TWIST_CHECK_S = 0.25
#: A twist disagrees with the poses when this fraction of the windows (and at least
#: :data:`TWIST_CHECK_MIN_S` of them) differ beyond the noise.
TWIST_CHECK_FRACTION = 0.01
#: The least total time (s) of disagreeing windows that counts as a disagreement.
TWIST_CHECK_MIN_S = 0.1


def twist_disagreement(c: str, t: np.ndarray, x: np.ndarray, y: np.ndarray, yaw: np.ndarray,
                       twist: np.ndarray, t_first: float, t_last: float) -> str | None:
    """Whether channel ``c``'s twist integrates to the poses; ``None``, else what differs.

    Over windows of :data:`TWIST_CHECK_S` the trapezoidal integral of the twist is compared
    with the distance (``v``) or heading change (``w``) of the poses.  Pose noise enters a
    window only at its two ends, so the differences of one odometry interval give its scale
    (a robust one: their median absolute deviation).  A window differs when it is off by more
    than 5 of those plus 2 % of the motion plus 0.5 mm (mrad); the twist disagrees when
    :data:`TWIST_CHECK_FRACTION` of the windows (at least :data:`TWIST_CHECK_MIN_S` of them)
    differ: a twist that echoes the command or the firmware's setpoint, one stamped at
    another time, one that keeps reporting through a stall of the base.

    Parameters
    ----------
    c : {'v', 'w'}
        The channel.
    t, x, y, yaw, twist : numpy.ndarray
        The odometry (sorted, distinct stamps) and the channel's twist.
    t_first, t_last : float
        The span looked at (s).

    Returns
    -------
    str or None
    """
    sel = (t >= t_first - TWIST_CHECK_S) & (t <= t_last + TWIST_CHECK_S)
    t, x, y, th, tw = t[sel], x[sel], y[sel], np.unwrap(yaw[sel]), twist[sel]
    if t.size < 20:
        return None
    dt = np.diff(t)
    period = float(np.median(dt))
    span = max(2, int(math.ceil(TWIST_CHECK_S / period - 1e-9)))
    if t.size <= span + 10:
        return None
    dth = np.diff(th)
    if c == 'v':
        thm = 0.5 * (th[1:] + th[:-1])
        moved = (np.diff(x) * np.cos(thm) + np.diff(y) * np.sin(thm)) / np.sinc(
            dth / (2 * np.pi))
    else:
        moved = dth
    integral = 0.5 * (tw[1:] + tw[:-1]) * dt
    e1 = moved - integral
    sigma = 1.4826 * float(np.median(np.abs(e1 - np.median(e1))))
    pc = np.concatenate([[0.0], np.cumsum(moved)])
    tc = np.concatenate([[0.0], np.cumsum(integral)])
    by_twist = tc[span:] - tc[:-span]
    e = (pc[span:] - pc[:-span]) - by_twist
    tol = 5.0 * sigma + 0.02 * np.abs(by_twist) + 5e-4
    # a twist averaged over the interval before its stamp (or after it) is a convention,
    # not a disagreement: half an interval either way (the rectangle rules) is allowed
    # (they differ by half an interval times the change of the twist over the window)
    bad = np.abs(e) > tol + 0.5 * period * np.abs(tw[span:] - tw[:-span])
    n_bad = int(np.count_nonzero(bad))
    if n_bad < max(TWIST_CHECK_FRACTION * e.size, TWIST_CHECK_MIN_S / period):
        return None
    i = int(np.argmax(np.abs(e) - tol))
    unit, what = ('m', 'moved') if c == 'v' else ('rad', 'turned')
    return (f'the odometry twist ({NAMES[c]}) does not integrate to its poses: in '
            f'{100 * n_bad / e.size:.0f} % of the {TWIST_CHECK_S:g} s windows they differ '
            f'beyond the poses\' noise ({sigma:.2g} {unit} per sample), most over '
            f'{t[i]:.2f}-{t[i + span]:.2f} s, where the twist says the base {what} '
            f'{by_twist[i]:.3g} {unit} and the poses {by_twist[i] + e[i]:.3g} {unit}')


def _gather(commands: CommandSamples, odometry: OdometrySamples, max_latency_s: float,
            source: str, window_s: float, check: bool = True) -> FitData:
    """Sort the samples, choose each channel's source and keep the measurements fitted.

    ``check``: a twist is checked against the poses (:func:`twist_disagreement`).

    Raises :class:`IdentificationError` for too few commands or odometry samples or too
    short an overlap, :class:`InputError` for non-finite values or a missing twist.
    """
    # -- commands
    if len(commands) < 10:
        raise NotEnoughDataError(f'the run has {len(commands)} velocity commands; at least 10 '
                                 'are needed (record cmd_vel while the robot moves)')
    order = _check_times('command t', commands.t)
    tc = commands.t[order]
    cmd = {'v': commands.v[order], 'w': commands.w[order]}
    for c in CHANNELS:
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
        raise NotEnoughDataError(f'the run has {to.size} odometry samples; at least '
                                 f'{MIN_ODOM_SAMPLES} are needed')
    odom_period = float(np.median(np.diff(to)))
    odom_rate = 1.0 / odom_period

    t_first = tc[0] + max_latency_s            # earliest measurement with a known input
    t_last = tc[-1] + max(float(np.median(np.diff(tc))), 0.0)

    # -- channels and their measurements
    use = {}
    notes: list[str] = []
    disagree: dict[str, str] = {}
    for c in CHANNELS:
        if source == 'twist' and not _twist_present(twist[c]):
            raise InputError(f'source twist: the odometry has no {NAMES[c]} twist (missing or '
                             "all zero); use source 'pose' or 'auto'")
        use[c] = 'twist' if source != 'pose' and _twist_present(twist[c]) else 'pose'
        if use[c] == 'twist' and check:
            found = twist_disagreement(c, to, x, y, yaw, cast(np.ndarray, twist[c]),
                                       t_first, t_last)
            if found is not None and source == 'auto':
                use[c] = 'pose'
                disagree[c] = found
                notes.append(f'{found}: the {NAMES[c]} is measured from the poses (what the '
                             'base did, and what the tracker closes its loop on)')
            elif found is not None:
                notes.append(f'{found} (source twist: the twist is fitted as asked)')
    span = max(1, int(math.ceil(window_s / odom_period - 1e-9)))
    wa, wb, width, zv_pose, zw_pose = _window_measurements(to, x, y, yaw, span)

    def measurement(c: str) -> Measurement:
        """(index a, index b or None, width or None, z, mid time) into the odometry."""
        if use[c] == 'twist':
            ia = np.flatnonzero((to >= t_first) & (to <= t_last))
            return ia, None, None, cast(np.ndarray, twist[c])[ia], to[ia]
        sel = (to[wa] >= t_first) & (to[wb] <= t_last)
        z = (zv_pose if c == 'v' else zw_pose)[sel]
        return wa[sel], wb[sel], width[sel], z, 0.5 * (to[wa[sel]] + to[wb[sel]])

    meas = {c: measurement(c) for c in CHANNELS}
    n_used = {c: meas[c][3].size for c in CHANNELS}
    if min(n_used.values()) < MIN_ODOM_SAMPLES:
        raise NotEnoughDataError(
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
        raise NotEnoughDataError(
            f'commands and odometry overlap for {duration:.2f} s after the first '
            f'{max_latency_s:g} s; at least {MIN_BLOCKS * 0.25:g} s are needed for the '
            'uncertainty (block bootstrap): record a longer run')
    return FitData(tc, cmd, to, odom_rate, use, meas, t_begin, t_end, duration, block_len,
                   n_blocks, notes, disagree)


def _check_excitation(data: FitData, max_latency_s: float,
                      min_excitation: tuple[float, float]) -> None:
    """Refuse a channel whose commands hardly vary (:class:`IdentificationError`).

    The commands over the fitted span and the latency range before it are looked at.
    """
    tc, t_begin, t_end = data.tc, data.t_begin, data.t_end
    for c, lo in zip(CHANNELS, min_excitation):
        sel = (tc >= t_begin - max_latency_s) & (tc <= t_end)
        u = data.cmd[c][sel]
        ptp = float(np.ptp(u)) if u.size else 0.0
        changes = int(np.count_nonzero(np.diff(u))) if u.size > 1 else 0
        if ptp < lo or changes < 3:
            raise InsufficientExcitationError(
                f'the {NAMES[c]} command hardly varies in the fitted span ({t_begin:.2f} ... '
                f'{t_end:.2f} s): peak-to-peak {ptp:.3g} {UNITS[c]} (need >= {lo:g}), '
                f'{changes} changes; its lag and the latency cannot be seen. Record a run that '
                'varies both v and w (e.g. the figure eight), not a straight line or a hold')


def _poor_fit_cause(c: str, r2: float, source: str, z: np.ndarray, u: np.ndarray,
                    accel: float, excluded_s: float) -> str:
    """The message of a fit that explains too little, naming the likely cause."""
    head = (f'the model explains only {100 * max(r2, 0):.0f} % of the measured {NAMES[c]} '
            f'(from the odometry {source}; need >= {100 * MIN_R2:.0f} %)')
    tried = ('with a first-order lag' + (f', an acceleration limit {accel:.3g} {ACCEL_UNITS[c]}'
                                         if accel > 0 else ' (no acceleration limit binds)')
             + (f' and {excluded_s:.2f} s of stalls excluded' if excluded_s else ''))
    umax = float(np.percentile(np.abs(u), 99))
    zmax = float(np.percentile(np.abs(z), 99.5))
    if umax > 0 and zmax < 0.7 * umax:
        return (f'{head}, {tried}: the base does not reach the commanded {NAMES[c]} '
                f'(commands up to {umax:.3g} {UNITS[c]}, measured at most {zmax:.3g}): a '
                'speed limit of the base below the commands, or a wrong odometry scale. '
                'Record commands within the speed range of the base')
    if r2 < 0.1:
        return (f'{head}, {tried}: the odometry does not respond to these commands - check '
                'that both topics belong to the same robot and that the command times and '
                'odometry stamps are on one clock')
    return (f'{head}, {tried}: the base responds to the commands but not as a lag with '
            'dead time (a controller that overshoots or oscillates, wheel slip, long stalls); '
            'the latency of such a base is not identified here')


@dataclass(frozen=True)
class _Quality:
    """The final fit's figures per channel (see :func:`_check_quality`)."""

    gains: dict[str, float]
    resid: dict[str, float]
    r2: dict[str, float]
    binding: dict[str, float]
    excluded_s: float


def _check_quality(fit: Fit, excluded: list[tuple[float, float]], max_latency_s: float,
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
    binding = {c: binding_fraction(chans[c], tau_hat[c], pos, data.t_begin - tc[0],
                                    data.t_end - tc[0])
               for c in CHANNELS}

    for c in CHANNELS:
        if r2[c] < MIN_R2:
            raise PoorFitError(_poor_fit_cause(c, r2[c], data.use[c], chans[c].z,
                                               data.cmd[c], fit.accel[c], excluded_s))
    if pos >= fit.d_max - 0.5:
        raise PoorFitError(f'the latency estimate is at the search limit '
                           f'{max_latency_s:g} s: either the latency is longer (raise '
                           'max_latency_s, --max-latency) or the odometry does not '
                           'respond to these commands (another robot, another clock)')
    for c in CHANNELS:
        if tau_hat[c] >= 0.999 * max_tau_s:
            raise PoorFitError(
                f'the {NAMES[c]} time constant reaches the search limit {max_tau_s:g} s: the '
                f'measured {NAMES[c]} does not follow the commands through a lag. Real '
                'actuator lags are tens of milliseconds; a fit this slow means something the '
                'model lacks (a speed limit below the commands, a base controller that '
                'overshoots, a base that stalls for long) - a larger max_tau_s would only fit '
                'that as a lag, with a wrong latency. Record commands within the base\'s speed '
                'range (e.g. the figure eight at a lower rate)')
    return _Quality(gains, resid, r2, binding, excluded_s)


def _bootstrap(fit: Fit, rng: np.random.Generator, bootstrap: int
               ) -> tuple[np.ndarray, dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Block bootstrap on a local grid (widened while estimates pile at an edge).

    Returns the replicates' latency grid positions, time constants and static gains.
    """
    pos, tau_hat, d_max, n_blocks = fit.pos, fit.tau_hat, fit.d_max, fit.data.n_blocks
    half = max(10, fit.step)
    spread = 1.6
    for attempt in range(3):
        centre = int(round(pos))
        shifts = np.arange(max(0, centre - half), min(d_max, centre + half) + 1, dtype=float)
        grids = {c: fit.local_taus(c, tau_hat[c], spread) for c in CHANNELS}
        stats = fit.grid_fit(shifts, grids, True)
        pos_b, tau_b = np.empty(bootstrap), {c: np.empty(bootstrap) for c in CHANNELS}
        gain_b = {c: np.empty(bootstrap) for c in CHANNELS}
        for b in range(bootstrap):
            wts = np.bincount(rng.integers(0, n_blocks, n_blocks),
                              minlength=n_blocks).astype(float)
            gains: dict[str, float] = {}
            p, t_, _, _ = fit.estimate(stats, wts, shifts, grids, gains)
            pos_b[b] = p
            for c in CHANNELS:
                tau_b[c][b] = t_[c]
                gain_b[c][b] = gains[c]
        edge = np.mean((pos_b <= shifts[0] + 0.5) & (shifts[0] > 0)) + \
            np.mean((pos_b >= shifts[-1] - 0.5) & (shifts[-1] < d_max))
        tedge = max(np.mean((tau_b[c] >= grids[c][-1] - 1e-12) & (grids[c][-1] < fit.max_tau_s))
                    + np.mean((tau_b[c] <= grids[c][0] + 1e-12) & (grids[c][0] > 0))
                    for c in CHANNELS)
        if edge <= 0.01 and tedge <= 0.01:
            break
        if edge > 0.01:
            half *= 3
        if tedge > 0.01:
            spread = spread ** 2
    else:
        fit.notes.append('bootstrap estimates reach the edge of the local search grid: the '
                         'intervals may be too narrow')
    return pos_b, tau_b, gain_b


def _report(commands: CommandSamples, odometry: OdometrySamples, fit: Fit, q: _Quality,
            replicates: tuple[np.ndarray, dict[str, np.ndarray], dict[str, np.ndarray]],
            events: np.ndarray,
            confidence: float, bootstrap: int) -> Identification:
    """Assemble the :class:`.Identification`.

    Intervals at ``confidence`` from the bootstrap ``replicates``, the latency range from
    the command steps' ``events``, the commands' period and age, and the notes.
    """
    data, h, pos, tau_hat, lat_c, accel = fit.data, fit.h, fit.pos, fit.tau_hat, fit.lat_c, \
        fit.accel
    notes, tc, max_latency_s = fit.notes, data.tc, fit.max_latency_s
    pos_b, tau_b, gain_b = replicates
    latency = pos * h
    alpha = 0.5 * (1.0 - confidence)

    def interval(values: np.ndarray, point: float, floor: float = 0.0) -> tuple[float, float]:
        lo, hi = np.quantile(values, [alpha, 1.0 - alpha])
        lo = max(floor, min(float(lo), point) - h)
        return lo, max(float(hi), point) + h

    lat_lo, lat_hi = interval(pos_b * h, latency)
    tv_lo, tv_hi = interval(tau_b['v'], tau_hat['v'])
    tw_lo, tw_hi = interval(tau_b['w'], tau_hat['w'])
    # the gains' intervals: the replicates' quantiles, containing the point estimate
    gain_iv = {c: (min(float(np.quantile(gain_b[c], alpha)), q.gains[c]),
                   max(float(np.quantile(gain_b[c], 1.0 - alpha)), q.gains[c]))
               for c in CHANNELS}
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
            notes.append(f'{name} acceleration limit {accel[c]:.3g} {ACCEL_UNITS[c]} (binding '
                         f'{100 * q.binding[c]:.0f} % of the fitted time; rate-limited FOPDT)')
    return Identification(
        latency_s=latency, latency_low_s=lat_lo, latency_high_s=lat_hi,
        tau_v_s=tau_hat['v'], tau_v_low_s=tv_lo, tau_v_high_s=tv_hi,
        tau_w_s=tau_hat['w'], tau_w_low_s=tw_lo, tau_w_high_s=tw_hi,
        odom_rate_hz=data.odom_rate, samples=int(max(ch.z.size for ch in fit.chans.values())),
        residual_rms_v=q.resid['v'], residual_rms_w=q.resid['w'],
        gain_v=q.gains['v'], gain_w=q.gains['w'], gain_v_low=gain_iv['v'][0],
        gain_v_high=gain_iv['v'][1], gain_w_low=gain_iv['w'][0], gain_w_high=gain_iv['w'][1],
        r2_v=q.r2['v'], r2_w=q.r2['w'],
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
