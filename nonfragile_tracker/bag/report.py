"""Tracking report of a recorded run: metrics, message counts, gaps and plots.

:func:`bag_report` reads a bag (:func:`~nonfragile_tracker.bag.reader.read_bag`), matches
the robot pose with the reference, computes the tracking metrics (and, for a real-time
run, its timing), finds stamp gaps and writes four PNG figures; :func:`format_report`
renders a :class:`Report` as a text table.

See doc/bags.md, section "``bag report``" (the matching, the timing, the figures).
"""
from __future__ import annotations

import math
import os
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from ..interface import topics
from ..control.simulation.metrics import TrackingMetrics, tracking_metrics
from .reader import MissingTopicsError, read_bag
from .errors import BagError

if TYPE_CHECKING:
    from ..control.identification.monitor import Certificate, MonitorSettings

__all__ = ['Gap', 'PhaseErrors', 'Report', 'TimingMetrics', 'bag_report', 'format_report',
           'find_gaps', 'timing_metrics', 'PLOTS', 'GAP_FACTOR', 'LOCKSTEP_MATCH',
           'CertificateCheck', 'certificate_source', 'certificate_check', 'format_certificate']

#: File names of the figures written by :func:`bag_report`.
PLOTS = ('xy.png', 'errors.png', 'xi.png', 'commands.png')
#: A stamp step larger than GAP_FACTOR x the median step is a gap.
GAP_FACTOR = 1.5
_SAME_CLOCK_NS = 60 * 1_000_000_000   # receive times within 60 s of the stamps: same clock


@dataclass(frozen=True)
class Gap:
    """A jump in the stamps of ``topic``: from ``t_before`` to ``t_after`` (s)."""

    topic: str
    index: int              # index of the sample after the gap
    t_before: float
    t_after: float
    median_step: float

    @property
    def step(self) -> float:
        """Length of the gap in s."""
        return self.t_after - self.t_before

    @property
    def missing_samples(self) -> int:
        """Samples missing in the gap at the median step (0 without a median)."""
        return max(0, int(round(self.step / self.median_step)) - 1) if self.median_step > 0 \
            else 0


@dataclass(frozen=True)
class TimingMetrics:
    """Real-time timing of a run, from header stamps and the recorder's receive times.

    Rates are messages per second; jitter is the standard deviation of the step
    between consecutive odometry messages; a *missing* command is an odometry interval
    (from one odometry receive time to the next) in which no command was received; a
    command is *late* when its latency exceeds ``late_threshold`` (default: the median
    odometry step).  Latency (input to command) is the receive time of a command minus
    the receive time of the last odometry received before it (both on the recorder's
    clock); ``stamp_latency`` uses that odometry's header stamp instead (only when the
    stamps are on the recorder's clock, else NaN).
    """

    odom_count: int
    odom_rate: float                 # from header stamps (1/s)
    odom_step_median: float          # s
    odom_jitter: float               # std of header-stamp steps (s)
    odom_step_max: float
    odom_receive_jitter: float       # std of receive-time steps (s)
    command_count: int
    command_rate: float              # from receive times (1/s)
    missing_commands: int            # odometry intervals without a command
    late_commands: int
    late_threshold: float            # s
    latency_median: float            # s
    latency_p95: float
    latency_max: float
    stamp_latency_median: float      # s; NaN when the clocks differ

    def as_dict(self) -> dict[str, Any]:
        """The timing figures as a plain dict (for JSON)."""
        return asdict(self)


@dataclass(frozen=True)
class Report:
    """Everything :func:`bag_report` found; times in s, distances in m.

    ``metrics`` is None when the bag has no reference (or no pose); ``timing`` is
    None without odometry; ``notes`` say what was missing and what is still reported.
    """

    bag: Path
    metrics: TrackingMetrics | None
    counts: dict[str, int]
    msgtypes: dict[str, str]
    duplicates: dict[str, int]
    pose_topic: str
    matched: int                    # pose samples compared with the reference
    pose_samples: int
    reference_samples: int
    command_samples: int
    t0_ns: int                      # stamp of t = 0
    median_step: float
    gaps: tuple[Gap, ...]
    plots: dict[str, Path] = field(default_factory=dict)
    out_dir: Path | None = None
    command_time_note: str = ''
    mode: str = 'lockstep'          # lockstep (stamps matched) or realtime (interpolated)
    timing: TimingMetrics | None = None
    notes: tuple[str, ...] = ()
    path_length: float = math.nan   # m, robot path in the x-y plane
    #: the errors while the trajectory is active and after its end (None when the
    #: reference has no end within the run, e.g. the analytic paths or reference samples)
    phases: PhaseErrors | None = None

    @property
    def tolerance(self) -> float:
        """Distance of "within tolerance" in m (NaN without tracking metrics)."""
        return self.metrics.tolerance if self.metrics is not None else math.nan


@dataclass(frozen=True)
class PhaseErrors:
    """Position errors (m) while the trajectory is active and after its end (s, m).

    *Active*: from the trajectory's start to its end (its own time, re-basing included);
    *after the end*: the robot holds the end point (at rest; a drift there is the plant's,
    e.g. the paper's ``A_tau`` term, not the tracking).
    """

    active_samples: int
    active_span: tuple[float, float]
    active_rms: float
    active_max: float
    after_samples: int
    error_at_end: float          # the error at the last active sample
    after_final: float           # the last error of the run
    after_max: float
    after_drift: float           # after_final - error_at_end

    @staticmethod
    def of(t: np.ndarray, err: np.ndarray, phase: np.ndarray) -> 'PhaseErrors | None':
        """The split of ``err`` by ``phase`` (0 before, 1 active, 2 after).

        None if no sample is after the end or none is active.

        Parameters
        ----------
        t : numpy.ndarray
            Sample times (s), increasing.
        err : numpy.ndarray
            Position error per sample (m).
        phase : numpy.ndarray
            Trajectory phase per sample (:attr:`ReferenceSeries.phase
            <nonfragile_tracker.bag.reader.ReferenceSeries.phase>`).
        """
        act = phase == 1
        after = phase == 2
        if not act.any() or not after.any():
            return None
        ea = err[act]
        end = float(ea[-1])
        final = float(err[after][-1])
        ta = t[act]
        return PhaseErrors(int(act.sum()), (float(ta[0]), float(ta[-1])),
                           float(np.sqrt(np.mean(ea ** 2))), float(ea.max()),
                           int(after.sum()), end, final, float(err[after].max()),
                           final - end)


def find_gaps(topic: str, t: np.ndarray, factor: float = GAP_FACTOR
              ) -> tuple[float, list[Gap]]:
    """Median step of the sorted times ``t`` and the steps larger than ``factor`` x median.

    Parameters
    ----------
    topic : str
        The topic the times are of (named in each :class:`Gap`).
    t : numpy.ndarray
        Message times (s), sorted.
    factor : float, optional
        A step longer than ``factor`` x the median step is a gap.
    """
    if t.size < 3:
        return (float(t[1] - t[0]) if t.size == 2 else math.nan), []
    dt = np.diff(t)
    med = float(np.median(dt))
    idx = np.flatnonzero(dt > factor * med)
    return med, [Gap(topic, int(i + 1), float(t[i]), float(t[i + 1]), med) for i in idx]


def _rate(ns: np.ndarray) -> float:
    if ns.size < 2 or ns[-1] == ns[0]:
        return math.nan
    return float((ns.size - 1) / ((ns[-1] - ns[0]) * 1e-9))


def timing_metrics(odom_stamp_ns: np.ndarray, odom_receive_ns: np.ndarray,
                   cmd_receive_ns: np.ndarray, *, late_threshold: float | None = None
                   ) -> TimingMetrics:
    """Timing of a real-time run (see :class:`TimingMetrics`); arrays in ns.

    Parameters
    ----------
    odom_stamp_ns, odom_receive_ns : numpy.ndarray
        Header stamp and bag receive time of each odometry message (sorted by stamp).
    cmd_receive_ns : numpy.ndarray
        Receive time of each command.
    late_threshold : float, optional
        Latency (s) above which a command is late (default: the median odometry step).
    """
    st = np.asarray(odom_stamp_ns, dtype=np.int64)
    rv = np.sort(np.asarray(odom_receive_ns, dtype=np.int64))
    cr = np.sort(np.asarray(cmd_receive_ns, dtype=np.int64))
    steps = np.diff(st) * 1e-9
    med = float(np.median(steps)) if steps.size else math.nan
    thr = float(late_threshold) if late_threshold is not None else med
    nan = math.nan
    if rv.size and cr.size:
        # commands per odometry interval [r_i, r_i+1) (the last interval is open-ended)
        per = np.diff(np.searchsorted(cr, rv, side='left'), append=cr.size)
        first_cmd = int(np.searchsorted(rv, cr[0], side='right')) - 1
        # intervals before the first command are start-up, not missing
        missing = int(np.count_nonzero(per[max(first_cmd, 0):] == 0))
        idx = np.searchsorted(rv, cr, side='right') - 1
        ok = idx >= 0
        lat = (cr[ok] - rv[idx[ok]]) * 1e-9
        order = np.argsort(odom_receive_ns, kind='stable')
        st_by_recv = np.asarray(odom_stamp_ns, dtype=np.int64)[order]
        slat = (cr[ok] - st_by_recv[idx[ok]]) * 1e-9
        same_clock = slat.size and abs(float(np.median(slat))) < 60.0
    else:
        missing, lat, slat, same_clock = (int(rv.size) if cr.size == 0 and rv.size else 0), \
            np.zeros(0), np.zeros(0), False
    late = int(np.count_nonzero(lat > thr)) if lat.size and math.isfinite(thr) else 0
    return TimingMetrics(
        odom_count=int(st.size), odom_rate=_rate(st), odom_step_median=med,
        odom_jitter=float(np.std(steps)) if steps.size else nan,
        odom_step_max=float(steps.max()) if steps.size else nan,
        odom_receive_jitter=float(np.std(np.diff(rv) * 1e-9)) if rv.size > 1 else nan,
        command_count=int(cr.size), command_rate=_rate(cr), missing_commands=missing,
        late_commands=late, late_threshold=thr,
        latency_median=float(np.median(lat)) if lat.size else nan,
        latency_p95=float(np.percentile(lat, 95)) if lat.size else nan,
        latency_max=float(lat.max()) if lat.size else nan,
        stamp_latency_median=float(np.median(slat)) if same_clock else nan)


#: Fraction of pose stamps that must equal a reference stamp for a lockstep match.
LOCKSTEP_MATCH = 0.5


def bag_report(path: str | os.PathLike[str], out_dir: str | os.PathLike[str] | None = None,
               *,
               tolerance: float = 0.01, plots: bool = True, namespace: str | None = None,
               overwrite: bool = False, topic_overrides: dict[str, str] | None = None,
               late_threshold: float | None = None) -> Report:
    """Metrics, timing, counts, gaps and (with ``plots``) the PNGs of the run in bag ``path``.

    Lockstep bags (most pose stamps equal a reference stamp) are matched by stamp;
    real-time bags get the reference interpolated (linearly) at each pose stamp within
    the reference's time span.  Figures go to ``out_dir`` (default ``<path>_report``;
    created); existing figures are never replaced unless ``overwrite``.  A bag without a
    reference still gets timing and the path (``notes`` say so); a bag with neither
    odometry/pose nor commands raises :class:`.MissingTopicsError`.

    Parameters
    ----------
    path : path-like
        The bag directory (or MCAP file).
    out_dir : path-like, optional
        Where the figures go (default ``<path>_report``).
    tolerance : float, optional
        Position tolerance of "settled" (m).
    plots : bool, optional
        Write the PNG figures.
    namespace : str, optional
        The namespace of the topic names (guessed when ``None``; :func:`read_bag
        <nonfragile_tracker.bag.reader.read_bag>`).
    overwrite : bool, optional
        Replace existing figures.
    topic_overrides : dict, optional
        ``{logical name: stored topic}`` (e.g. ``'odom'``, ``'cmd_vel'``) for topics
        under other names.
    late_threshold : float, optional
        Latency (s) above which a command is late (default: the median odometry step).

    Raises
    ------
    BagError
        If the bag cannot be read, the tolerance is bad, or figures exist and not
        ``overwrite``.
    """
    if not (isinstance(tolerance, (int, float)) and math.isfinite(tolerance) and tolerance > 0):
        raise BagError(f'tolerance must be a finite distance > 0 m, got {tolerance!r}')
    data = read_bag(path, strict=False, namespace=namespace, topic_overrides=topic_overrides)
    run = data.run
    pose, ref, cmd = run.pose, run.reference, run.commands
    if len(pose) == 0 and len(cmd) == 0:
        raise MissingTopicsError(
            f'bag {path} has no odometry ({topics.ODOM}, nav_msgs/Odometry, or {topics.POSE}) '
            f'and no commands ({topics.CMD_VEL}, Twist or TwistStamped): nothing to report '
            f'(topics: {data.counts or "none"}). Name them with --odom/--cmd if they are '
            'recorded under other names.', [topics.ODOM, topics.CMD_VEL])
    notes = _missing_notes(pose, ref, cmd)
    starts = [a[0] for a in (pose.stamp_ns, ref.stamp_ns) if a.size]
    t0 = int(min(starts)) if starts else int(cmd.receive_ns[0])
    metrics, phases = None, None
    mode, sel, (xd, yd, vxd, vyd), ph = _match(pose, ref, t0, notes)
    matched = int(sel.size)
    x = y = th = v = t = np.zeros(0)
    if matched:
        t = (pose.stamp_ns[sel] - t0) * 1e-9
        x, y, th, v = pose.x[sel], pose.y[sel], pose.th[sel], pose.v[sel]
        metrics = tracking_metrics(t, x, y, xd, yd, cmd.v, cmd.w, tolerance=tolerance)
        if ph.size == t.size:
            phases = PhaseErrors.of(t, np.hypot(x - xd, y - yd), ph)
    med, gaps = find_gaps(pose.topic, (pose.stamp_ns - t0) * 1e-9) if len(pose) \
        else (math.nan, [])
    timing = timing_metrics(pose.stamp_ns, pose.receive_ns, cmd.receive_ns,
                            late_threshold=late_threshold) if len(pose) else None
    if cmd.receive_ns.size and abs(int(cmd.receive_ns[0]) - t0) < _SAME_CLOCK_NS:
        tc, note = (cmd.receive_ns - t0) * 1e-9, ''
    elif cmd.receive_ns.size:
        tc = (cmd.receive_ns - cmd.receive_ns[0]) * 1e-9
        note = 'command times are receive times on another clock: shown from the first command'
    else:
        tc, note = np.zeros(0), ''
    length = float(np.sum(np.hypot(np.diff(pose.x), np.diff(pose.y)))) if len(pose) > 1 \
        else math.nan
    report = Report(bag=Path(path), metrics=metrics, counts=dict(data.counts),
                    msgtypes=dict(data.msgtypes), duplicates=dict(data.duplicates),
                    pose_topic=pose.topic, matched=matched, pose_samples=len(pose),
                    reference_samples=len(ref), command_samples=len(cmd), t0_ns=t0,
                    median_step=med, gaps=tuple(gaps), command_time_note=note, mode=mode,
                    timing=timing, notes=tuple(notes), path_length=length, phases=phases)
    if not plots:
        return report
    out = Path(out_dir) if out_dir is not None else Path(f'{Path(path)}_report')
    files: dict[str, Callable[[], Figure]] = {}
    if len(pose):
        files['xy.png'] = lambda: _plot_xy(pose.x if metrics is None else x,
                                           pose.y if metrics is None else y, xd, yd, ref.x,
                                           ref.y, pose.topic)
    if metrics is not None:
        files['errors.png'] = lambda: _plot_errors(t, x - xd, y - yd, tolerance)
        files['xi.png'] = lambda: _plot_xi(t, x, y, th, v, xd, yd, vxd, vyd, pose.topic)
    if len(cmd):
        files['commands.png'] = lambda: _plot_commands(tc, cmd.v, cmd.w, note)
    written = _write_figures(out, files, overwrite)
    return replace(report, plots=written, out_dir=out)


def _missing_notes(pose: Any, ref: Any, cmd: Any) -> list[str]:
    """What a report of a run without odometry, reference or commands leaves out."""
    notes = []
    if len(pose) == 0:
        notes.append(f'no odometry ({topics.ODOM} or {topics.POSE}): reporting commands only '
                     '(no tracking metrics, no timing of inputs)')
    if len(ref) == 0:
        notes.append(f'no reference ({topics.REF_POSE} + {topics.REF_TWIST} + '
                     f'{topics.REF_ACCEL}, or a nav_msgs/Path): reporting timing and the path '
                     'only (no tracking metrics)')
    if len(cmd) == 0:
        notes.append(f'no commands ({topics.CMD_VEL}): no command rate, latency or peaks')
    return notes


def _match(pose: Any, ref: Any, t0: int, notes: list[str]
           ) -> tuple[str, np.ndarray, tuple[np.ndarray, ...], np.ndarray]:
    """The poses compared with the reference, and the reference there.

    Returns the mode (lockstep: equal stamps; else the reference interpolated), the poses'
    indices, ``(xd, yd, vxd, vyd)`` at them and the reference's phases.
    """
    empty = np.zeros(0)
    if not (len(pose) and len(ref)):
        return 'realtime', np.zeros(0, dtype=np.intp), (empty,) * 4, np.zeros(0, dtype=np.int8)
    ph = np.zeros(0, dtype=np.int8)
    common, ip, ir = np.intersect1d(pose.stamp_ns, ref.stamp_ns, assume_unique=True,
                                    return_indices=True)
    if common.size >= LOCKSTEP_MATCH * len(pose):
        if ref.phase is not None:
            ph = ref.phase[ir]
        return 'lockstep', ip, (ref.x[ir], ref.y[ir], ref.vx[ir], ref.vy[ir]), ph
    sel = np.flatnonzero((pose.stamp_ns >= ref.stamp_ns[0])
                         & (pose.stamp_ns <= ref.stamp_ns[-1]))
    rt = (ref.stamp_ns - t0) * 1e-9
    pt = (pose.stamp_ns[sel] - t0) * 1e-9
    xi_d = tuple(np.interp(pt, rt, a) for a in (ref.x, ref.y, ref.vx, ref.vy))
    if ref.phase is not None and ref.phase.size:
        ph = ref.phase[np.clip(np.searchsorted(rt, pt), 0, rt.size - 1)]
    if sel.size == 0:
        notes.append(f'no pose stamp lies within the reference\'s time span (pose '
                     f'{pose.t[0]:.3f}..{pose.t[-1]:.3f} s, reference {ref.t[0]:.3f}..'
                     f'{ref.t[-1]:.3f} s): the stamps come from different clocks; no '
                     'tracking metrics')
    return 'realtime', sel, xi_d, ph


def _write_figures(out: Path, files: dict[str, Callable[[], Figure]], overwrite: bool
                   ) -> dict[str, Path]:
    """Draw and save each figure into ``out`` (created); never replace one unless told."""
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise BagError(f'cannot create report directory {out}: {exc.strerror or exc}') from None
    existing = [n for n in files if (out / n).exists()]
    if existing and not overwrite:
        raise BagError(f'{out} already holds {", ".join(existing)}; pass --force to replace '
                       'them or choose another --out')
    written: dict[str, Path] = {}
    for name, make in files.items():
        fig = make()
        FigureCanvasAgg(fig)
        fig.savefig(out / name, dpi=110)
        written[name] = out / name
    return written


# ---------------------------------------------------------------------------------------------
# Figures

def _plot_xy(x: np.ndarray, y: np.ndarray, xd: np.ndarray, yd: np.ndarray, rx: np.ndarray,
             ry: np.ndarray, pose_topic: str) -> Figure:
    fig = Figure(figsize=(6.4, 6.0))
    fig.subplots_adjust(left=0.13, right=0.97, top=0.93, bottom=0.09)
    ax = fig.add_subplot()
    if len(rx):
        ax.plot(rx, ry, 'k--', lw=1.2, label='reference $(x_d, y_d)$')
    ax.plot(x, y, 'C0-', lw=1.5, label=f'robot $(x, y)$ ({pose_topic})')
    ax.plot(x[:1], y[:1], 'C0o', label='robot start')
    if len(xd):
        ax.plot(xd[:1], yd[:1], 'ks', mfc='none', label='reference start')
    ax.set_aspect('equal', adjustable='datalim')
    ax.set_xlabel('x (m)')
    ax.set_ylabel('y (m)')
    ax.set_title('Path in the x-y plane (odom frame)')
    ax.grid(True, alpha=0.3)
    ax.legend(loc='best', fontsize='small')
    return fig


def _plot_errors(t: np.ndarray, ex: np.ndarray, ey: np.ndarray, tolerance: float) -> Figure:
    fig = Figure(figsize=(7.5, 7.0))
    fig.subplots_adjust(left=0.12, right=0.97, top=0.94, bottom=0.08, hspace=0.12)
    axes = fig.subplots(3, 1, sharex=True)
    err = np.hypot(ex, ey)
    for ax, val, lab, col in ((axes[0], ex, '$x - x_d$ (m)', 'C0'),
                              (axes[1], ey, '$y - y_d$ (m)', 'C1'),
                              (axes[2], err, r'$\|p - p_d\|$ (m)', 'C3')):
        ax.plot(t, val, col, lw=1.2, label=lab.split(' (')[0])
        ax.set_ylabel(lab)
        ax.grid(True, alpha=0.3)
    axes[2].axhline(tolerance, color='k', ls=':', lw=1,
                    label=f'tolerance {tolerance * 100:g} cm')
    for ax in axes:
        ax.legend(loc='upper right', fontsize='small')
    axes[2].set_xlabel('time (s)')
    axes[0].set_title('Tracking errors')
    return fig


def _plot_xi(t: np.ndarray, x: np.ndarray, y: np.ndarray, th: np.ndarray, v: np.ndarray,
             xd: np.ndarray, yd: np.ndarray, vxd: np.ndarray, vyd: np.ndarray,
             pose_topic: str) -> Figure:
    fig = Figure(figsize=(8.0, 8.0))
    fig.subplots_adjust(left=0.11, right=0.97, top=0.92, bottom=0.07, hspace=0.12)
    axes = fig.subplots(4, 1, sharex=True)
    have_v = bool(np.isfinite(v).any())
    xi = (x, v * np.cos(th), y, v * np.sin(th))
    xid = (xd, vxd, yd, vyd)
    labels = (('$x$', '$x_d$', '$\\xi_1$ (m)'),
              ('$v\\,\\cos\\theta$', '$\\dot x_d$', '$\\xi_2$ (m/s)'),
              ('$y$', '$y_d$', '$\\xi_3$ (m)'),
              ('$v\\,\\sin\\theta$', '$\\dot y_d$', '$\\xi_4$ (m/s)'))
    for i, (ax, a, b, (la, lb, unit)) in enumerate(zip(axes, xi, xid, labels)):
        if i % 2 == 0 or have_v:
            ax.plot(t, a, 'C0-', lw=1.4, label=la)
        ax.plot(t, b, 'k--', lw=1.1, label=lb)
        ax.set_ylabel(unit)
        ax.grid(True, alpha=0.3)
        ax.legend(loc='upper right', fontsize='small')
    axes[-1].set_xlabel('time (s)')
    title = r'State $\xi = [x, v\cos\theta, y, v\sin\theta]$ and reference $\xi_d$'
    if not have_v:
        title += f'\n(no speed: {pose_topic} has no twist; velocity rows show the reference)'
    axes[0].set_title(title)
    return fig


def _plot_commands(t: np.ndarray, v: np.ndarray, w: np.ndarray, note: str) -> Figure:
    fig = Figure(figsize=(7.5, 5.5))
    fig.subplots_adjust(left=0.12, right=0.97, top=0.93, bottom=0.1, hspace=0.12)
    axes = fig.subplots(2, 1, sharex=True)
    axes[0].plot(t, v, 'C0-', lw=1.2, label='v = cmd_vel.linear.x')
    axes[0].set_ylabel('v (m/s)')
    axes[1].plot(t, w, 'C2-', lw=1.2, label='w = cmd_vel.angular.z')
    axes[1].set_ylabel('w (rad/s)')
    for ax in axes:
        ax.grid(True, alpha=0.3)
        ax.legend(loc='upper right', fontsize='small')
    axes[1].set_xlabel('time since first command (s)' if note else 'time (s), receive time')
    axes[0].set_title('Commands (cmd_vel)')
    return fig


# ---------------------------------------------------------------------------------------------
# Text

def _fmt(value: float, unit: str, digits: int = 4) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return 'never' if unit == 's' else 'n/a'
    return f'{value:.{digits}g} {unit}'.rstrip()


def format_report(report: Report) -> str:
    """A readable summary: metrics table, timing, messages per topic, gaps and plot files.

    Parameters
    ----------
    report : Report
        What :func:`bag_report` found.
    """
    m = report.metrics
    rows = []
    if m is not None:
        tol = f'{m.tolerance * 100:g} cm'
        whole = ' (whole run)' if report.phases is not None else ''
        how = 'matched with' if report.mode == 'lockstep' else 'within the span of'
        rows += [
            (f'samples (pose {how} reference)', f'{report.matched} of {report.pose_samples}'),
            ('steps', str(m.steps)),
            ('duration', _fmt(m.duration, 's')),
            ('final position error' + whole, _fmt(m.final_error, 'm')),
            ('RMS position error' + whole, _fmt(m.rms_error, 'm')),
            (f'first within {tol}', _fmt(m.first_within, 's')),
            (f'enters and stays within {tol} at' + whole, _fmt(m.settling_time, 's')),
            ('RMS error after settling', _fmt(m.rms_error_settled, 'm')),
            ('max error after settling', _fmt(m.max_error_settled, 'm')),
            ('peak |v| (cmd_vel)', _fmt(m.peak_abs_v, 'm/s')),
            ('peak |w| (cmd_vel)', _fmt(m.peak_abs_w, 'rad/s')),
        ]
    ph = report.phases
    if ph is not None:
        a0, a1 = ph.active_span
        rows += [
            (f'while the trajectory is active ({a0:.2f}..{a1:.2f} s): RMS / max',
             f'{_fmt(ph.active_rms, "m")} / {_fmt(ph.active_max, "m")}'),
            ('after its end (at rest): error at the end / final',
             f'{_fmt(ph.error_at_end, "m")} / {_fmt(ph.after_final, "m")}'),
            ('after its end: max / drift since the end',
             f'{_fmt(ph.after_max, "m")} / {_fmt(ph.after_drift, "m")}'),
        ]
    if report.pose_samples:
        rows += [('path length', _fmt(report.path_length, 'm')),
                 ('pose step (median)', _fmt(report.median_step, 's'))]
    tm = report.timing
    if tm is not None and report.mode == 'realtime':
        rows += [
            ('odometry rate (stamps)', _fmt(tm.odom_rate, 'Hz')),
            ('odometry jitter (std of stamp step)', _fmt(tm.odom_jitter, 's')),
            ('odometry max step', _fmt(tm.odom_step_max, 's')),
            ('odometry receive jitter', _fmt(tm.odom_receive_jitter, 's')),
            ('command rate (receive)', _fmt(tm.command_rate, 'Hz')),
            ('odometry intervals without a command', str(tm.missing_commands)),
            (f'late commands (> {tm.late_threshold * 1e3:.3g} ms)', str(tm.late_commands)),
            ('input-to-command latency median', _fmt(tm.latency_median, 's')),
            ('input-to-command latency p95 / max',
             f'{_fmt(tm.latency_p95, "s")} / {_fmt(tm.latency_max, "s")}'),
            ('odom stamp to command latency median', _fmt(tm.stamp_latency_median, 's')),
        ]
    width = max((len(r[0]) for r in rows), default=6)
    lines = [f'Bag {report.bag} ({report.mode}; pose from {report.pose_topic or "none"})']
    lines += [f'note: {n}' for n in report.notes]
    lines += ['', f'{"metric":<{width}}  value', f'{"-" * width}  {"-" * 16}']
    lines += [f'{k:<{width}}  {v}' for k, v in rows]
    lines += ['', 'messages per topic:']
    tw = max((len(t) for t in report.counts), default=5)
    yw = max((len(report.msgtypes.get(t, '')) for t in report.counts), default=4)
    for topic in sorted(report.counts):
        dup = report.duplicates.get(topic, 0)
        extra = f'  ({dup} repeated stamps)' if dup else ''
        lines.append(f'  {topic:<{tw}}  {report.msgtypes.get(topic, ""):<{yw}}  '
                     f'{report.counts[topic]:>8}{extra}')
    if report.gaps:
        lines += ['', f'gaps on {report.pose_topic} (> {GAP_FACTOR}x median step): '
                  f'{len(report.gaps)}']
        for g in report.gaps[:10]:
            lines.append(f'  {g.t_before:.4f} s -> {g.t_after:.4f} s  (step {g.step:.4g} s, '
                         f'~{g.missing_samples} samples missing)')
        if len(report.gaps) > 10:
            lines.append(f'  ... and {len(report.gaps) - 10} more')
    elif report.pose_samples:
        lines += ['', f'gaps on {report.pose_topic}: none']
    if report.command_time_note:
        lines.append(f'note: {report.command_time_note}')
    if report.plots:
        lines += ['', f'plots in {report.out_dir}: ' + ', '.join(sorted(report.plots))]
    return '\n'.join(lines)


# ---------------------------------------------------------------------------------------------
# Certificate over the run (the tracker's monitor, offline)

@dataclass(frozen=True)
class CertificateCheck:
    """The certificate monitor run over a recorded run (:func:`certificate_check`).

    ``levels`` has one monitor level per window end ``t`` (s from the first odometry);
    ``inside`` is the fraction of windows whose estimate lies in the certified interval
    (OK or WARN), ``outside`` the fraction out of it (ERROR), ``unknown`` without an
    estimate (STALE); they sum to 1.
    """

    source: str
    certificate: Certificate | None
    predict_latency: float
    t: np.ndarray
    latency: np.ndarray             # estimate per window (NaN: none)
    levels: np.ndarray
    inside: float
    outside: float
    unknown: float
    first_outside: float            # s, NaN if never
    last_message: str
    notes: tuple[str, ...] = ()


def _tracker_section(path: Path) -> dict[str, Any]:
    from ..files import read_yaml
    data = read_yaml(path, 'parameter file', error=BagError)
    if isinstance(data, dict):
        for key in ('/**/tracker', 'tracker', '/tracker'):
            sec = data.get(key)
            if isinstance(sec, dict) and isinstance(sec.get('ros__parameters'), dict):
                return dict(sec['ros__parameters'])
    return {}


def certificate_source(bag: str | os.PathLike[str],
                       gains: str | os.PathLike[str] | None = None
                       ) -> tuple[Certificate | None, dict[str, Any], str] | None:
    """The certificate and tracker parameters to check a run against, and where they are from.

    ``gains`` (a gain file: its ``gain_design`` record and tracker section), else the run
    directory's ``params.yaml`` (the tracker parameters recorded with the run:
    ``certified_residual`` etc.).  None when neither gives one.

    Parameters
    ----------
    bag : path-like
        The run's bag (its directory's parent holds ``params.yaml`` for a run of ``run``).
    gains : path-like, optional
        A gain file to check against instead.

    Returns
    -------
    tuple or None
        ``(certificate, tracker parameters, source)``; the certificate is None when
        ``gains`` records none.
    """
    from ..control.simulation.gains import read_gain_design
    from ..control.identification.monitor import (certificate_from_design,
                                                  certificate_from_parameters)
    if gains is not None:
        params = _tracker_section(Path(gains))
        hold = float(params.get('dt', 0.0) or 0.0)   # 0: the odometry period (the check)
        cert = certificate_from_design(read_gain_design(gains), hold=hold, source=str(gains))
        if cert is None and params.get('certified_residual'):
            cert = certificate_from_parameters(params['certified_residual'],
                                               params.get('certified_lag', 0.0),
                                               params.get('certified_adapt_range'), hold=hold,
                                               source=str(gains))
        return cert, params, str(gains)
    recorded = Path(bag).parent / 'params.yaml'
    if not recorded.is_file():
        return None
    params = _tracker_section(recorded)
    if not params.get('certified_residual'):
        return None
    cert = certificate_from_parameters(params['certified_residual'],
                                       params.get('certified_lag', 0.0),
                                       params.get('certified_adapt_range'),
                                       hold=float(params.get('dt', 0.0) or 0.0),
                                       source=str(recorded))
    return cert, params, str(recorded)


def certificate_check(bag: str | os.PathLike[str], certificate: Certificate | None,
                      params: Mapping[str, Any], *, source: str = '', step: float = 1.0,
                      settings: MonitorSettings | None = None) -> CertificateCheck:
    """Run the tracker's certificate monitor over a recorded run, one window every ``step`` s.

    Parameters
    ----------
    bag : path-like
        The run's bag (commands and odometry with twist).
    certificate : control.identification.monitor.Certificate or None
        What the gain is certified for (None: estimates only, every window STALE).
    params : dict
        The tracker's parameters (``predict_latency``, limits, ``monitor_*``).
    source : str
        Where the certificate came from (printed).
    step : float
        Seconds between windows.
    settings : control.identification.monitor.MonitorSettings, optional
        Default: from ``params`` as the tracker node builds them.
    """
    from ..control.identification.monitor import ERROR, STALE, estimate_latency, evaluate
    from ..interface.tracker_inputs import monitor_settings
    from .motion import read_motion
    if settings is None:
        settings = monitor_settings(params)
    data = read_motion(bag)
    c, o = data.commands, data.odometry
    if o.v is None or o.w is None:
        raise BagError(f'{bag}: the odometry carries no twist; the certificate check needs '
                       'twist.linear.x and twist.angular.z')
    P = float(params.get('predict_latency', 0.0))
    if certificate is not None and not certificate.hold and o.t.size > 1:
        # the tracker took its step from the odometry: its hold is the odometry period
        certificate = replace(certificate, hold=float(np.median(np.diff(o.t))))
    notes = []
    if params.get('monitor_adapt'):
        notes.append('the run adapted predict_latency (monitor_adapt): checked against the '
                     f'configured {P:g} s, not the adapted values')
    ends = np.arange(o.t[0] + settings.window, o.t[-1] + 1e-9, step)
    lat, lev, msg = [], [], ''
    for end in ends:
        sel_o = o.t <= end
        sel_c = c.t <= end
        est = estimate_latency(c.t[sel_c], c.v[sel_c], c.w[sel_c], o.t[sel_o], o.v[sel_o],
                               o.w[sel_o], settings)
        st = evaluate(est, certificate, P, settings)
        lat.append(est.latency if est.valid else math.nan)
        lev.append(st.level)
        msg = st.message
    levels = np.array(lev, int)
    n = max(len(levels), 1)
    out = levels == ERROR
    unknown = levels == STALE
    t = ends - o.t[0]
    return CertificateCheck(source=source, certificate=certificate, predict_latency=P, t=t,
                            latency=np.array(lat, float), levels=levels,
                            inside=float(np.sum(~out & ~unknown)) / n,
                            outside=float(np.sum(out)) / n, unknown=float(np.sum(unknown)) / n,
                            first_outside=float(t[out][0]) if out.any() else math.nan,
                            last_message=msg, notes=tuple(notes))


def format_certificate(chk: CertificateCheck) -> str:
    """The certificate section of ``bag report``.

    Parameters
    ----------
    chk : CertificateCheck
        What :func:`certificate_check` found.
    """
    lines = ['', f'certificate ({chk.source}):']
    if chk.certificate is None:
        lines.append('  none recorded: latency estimates only')
    else:
        lo, hi = chk.certificate.interval(chk.predict_latency)
        lines.append(f'  certified latency [{lo:.4f}, {hi:.4f}] s with predict_latency '
                     f'{chk.predict_latency:.4f} s (lag {chk.certificate.lag:g} s)')
    valid = chk.latency[np.isfinite(chk.latency)]
    if valid.size:
        lines.append(f'  latency estimate: median {np.median(valid):.4f} s, range '
                     f'[{valid.min():.4f}, {valid.max():.4f}] s over {valid.size} of '
                     f'{chk.latency.size} windows')
    else:
        lines.append(f'  latency estimate: none in {chk.latency.size} windows')
    lines.append(f'  time inside the certified interval: {100 * chk.inside:.1f} %, outside: '
                 f'{100 * chk.outside:.1f} %, unknown: {100 * chk.unknown:.1f} %')
    if math.isfinite(chk.first_outside):
        lines.append(f'  first outside at t = {chk.first_outside:.1f} s')
    lines.append(f'  last window: {chk.last_message}')
    lines += [f'  note: {n}' for n in chk.notes]
    return '\n'.join(lines)
