"""Tracking report of a recorded run: metrics, message counts, gaps and plots.

:func:`bag_report` reads a bag (:func:`~nonfragile_tracker.bag.reader.read_bag`),
matches the robot pose (``odom``, else ``pose``) with the reference by header
stamp and computes :func:`nonfragile_tracker.control.metrics.tracking_metrics`
on the matched samples (peak ``|v|``, ``|w|`` from ``cmd_vel``).  Times are
seconds since the first pose or reference stamp, so a simulated (sim time)
run keeps its own time axis.  It finds stamp gaps on the pose topic and
writes four PNG figures (matplotlib, Agg, no pyplot state):

* ``xy.png`` - path in the x-y plane against the reference (paper Fig. 6);
* ``errors.png`` - x, y and position error against time;
* ``xi.png`` - ``xi = [x, v cos th, y, v sin th]`` against
  ``xi_d = [x_d, vx_d, y_d, vy_d]`` (``v`` = odom twist.linear.x);
* ``commands.png`` - commanded v and w against time.

:func:`format_report` renders a :class:`Report` as a text table.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from .. import topics
from ..control.metrics import TrackingMetrics, tracking_metrics
from .reader import BagData, MissingTopicsError, read_bag
from .writer import BagError

__all__ = ['Gap', 'Report', 'bag_report', 'format_report', 'find_gaps', 'PLOTS',
           'GAP_FACTOR']

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
        return self.t_after - self.t_before

    @property
    def missing_samples(self) -> int:
        return max(0, int(round(self.step / self.median_step)) - 1) if self.median_step > 0 \
            else 0


@dataclass(frozen=True)
class Report:
    """Everything :func:`bag_report` found; times in s, distances in m."""

    bag: Path
    metrics: TrackingMetrics
    counts: dict[str, int]
    msgtypes: dict[str, str]
    duplicates: dict[str, int]
    pose_topic: str
    matched: int                    # pose samples with a reference at the same stamp
    pose_samples: int
    reference_samples: int
    command_samples: int
    t0_ns: int                      # stamp of t = 0
    median_step: float
    gaps: tuple[Gap, ...]
    plots: dict[str, Path] = field(default_factory=dict)
    out_dir: Path | None = None
    command_time_note: str = ''

    @property
    def tolerance(self) -> float:
        return self.metrics.tolerance


def find_gaps(topic: str, t: np.ndarray, factor: float = GAP_FACTOR
              ) -> tuple[float, list[Gap]]:
    """Median step of the sorted times ``t`` and the steps larger than ``factor`` x median."""
    if t.size < 3:
        return (float(t[1] - t[0]) if t.size == 2 else math.nan), []
    dt = np.diff(t)
    med = float(np.median(dt))
    idx = np.flatnonzero(dt > factor * med)
    return med, [Gap(topic, int(i + 1), float(t[i]), float(t[i + 1]), med) for i in idx]


def _require(data: BagData) -> None:
    run = data.run
    missing = []
    if len(run.pose) == 0:
        missing.append(f'{topics.ODOM} (or {topics.POSE})')
    if len(run.reference) == 0:
        missing.append(f'{topics.REF_POSE} + {topics.REF_TWIST} + {topics.REF_ACCEL} '
                       'with common stamps')
    if len(run.commands) == 0:
        missing.append(topics.CMD_VEL)
    if missing:
        raise MissingTopicsError(
            f'bag {data.path} has no messages on {", ".join(missing)}; a report needs the pose, '
            'the reference and the commands of a run (message counts: '
            f'{data.counts or "none"})', missing)


def bag_report(path: str | os.PathLike, out_dir: str | os.PathLike | None = None, *,
               tolerance: float = 0.01, plots: bool = True, namespace: str | None = None,
               overwrite: bool = False) -> Report:
    """Metrics, counts, gaps and (with ``plots``) the four PNGs of the run in bag ``path``.

    Figures go to ``out_dir`` (default ``<path>_report``; created).  Existing
    figures are never replaced unless ``overwrite`` (:class:`BagError` otherwise).  Raises :class:`BagError` subclasses: for a bag
    without odom/pose, reference or cmd_vel a :class:`MissingTopicsError`
    naming the missing topics.
    """
    if not (isinstance(tolerance, (int, float)) and math.isfinite(tolerance) and tolerance > 0):
        raise ValueError(f'tolerance must be a finite distance > 0 m, got {tolerance!r}')
    data = read_bag(path, strict=True, namespace=namespace)
    _require(data)
    run = data.run
    pose, ref, cmd = run.pose, run.reference, run.commands
    common, ip, ir = np.intersect1d(pose.stamp_ns, ref.stamp_ns, assume_unique=True,
                                    return_indices=True)
    if common.size == 0:
        raise BagError(f'bag {path}: no pose stamp equals a reference stamp (pose '
                       f'{pose.t[0]:.3f}..{pose.t[-1]:.3f} s, reference {ref.t[0]:.3f}..'
                       f'{ref.t[-1]:.3f} s); the report matches samples by header stamp, so '
                       'record a lockstep run or stamp both from the same clock')
    t0 = int(min(pose.stamp_ns[0], ref.stamp_ns[0]))
    t = (common - t0) * 1e-9
    x, y, th, v = pose.x[ip], pose.y[ip], pose.th[ip], pose.v[ip]
    xd, yd, vxd, vyd = ref.x[ir], ref.y[ir], ref.vx[ir], ref.vy[ir]
    metrics = tracking_metrics(t, x, y, xd, yd, cmd.v, cmd.w, tolerance=tolerance)
    med, gaps = find_gaps(pose.topic, (pose.stamp_ns - t0) * 1e-9)
    if cmd.receive_ns.size and abs(int(cmd.receive_ns[0]) - t0) < _SAME_CLOCK_NS:
        tc, note = (cmd.receive_ns - t0) * 1e-9, ''
    else:
        tc = (cmd.receive_ns - cmd.receive_ns[0]) * 1e-9
        note = 'command times are receive times on another clock: shown from the first command'
    report = Report(bag=Path(path), metrics=metrics, counts=dict(data.counts),
                    msgtypes=dict(data.msgtypes), duplicates=dict(data.duplicates),
                    pose_topic=pose.topic, matched=int(common.size), pose_samples=len(pose),
                    reference_samples=len(ref), command_samples=len(cmd), t0_ns=t0,
                    median_step=med, gaps=tuple(gaps), command_time_note=note)
    if not plots:
        return report
    out = Path(out_dir) if out_dir is not None else Path(f'{Path(path)}_report')
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise BagError(f'cannot create report directory {out}: {exc.strerror or exc}') from None
    names = ('xy.png', 'errors.png', 'xi.png', 'commands.png')
    existing = [n for n in names if (out / n).exists()]
    if existing and not overwrite:
        raise BagError(f'{out} already holds {", ".join(existing)}; pass --force to replace '
                       'them or choose another --out')
    files = {
        'xy.png': _plot_xy(x, y, xd, yd, ref.x, ref.y, pose.topic),
        'errors.png': _plot_errors(t, x - xd, y - yd, tolerance),
        'xi.png': _plot_xi(t, x, y, th, v, xd, yd, vxd, vyd, pose.topic),
        'commands.png': _plot_commands(tc, cmd.v, cmd.w, note),
    }
    written = {}
    for name, fig in files.items():
        target = out / name
        FigureCanvasAgg(fig)
        fig.savefig(target, dpi=110)
        written[name] = target
    return replace(report, plots=written, out_dir=out)


# ---------------------------------------------------------------------------------------------
# Figures

def _plot_xy(x, y, xd, yd, rx, ry, pose_topic: str) -> Figure:
    fig = Figure(figsize=(6.4, 6.0), layout='constrained')
    ax = fig.add_subplot()
    ax.plot(rx, ry, 'k--', lw=1.2, label='reference $(x_d, y_d)$')
    ax.plot(x, y, 'C0-', lw=1.5, label=f'robot $(x, y)$ ({pose_topic})')
    ax.plot(x[:1], y[:1], 'C0o', label='robot start')
    ax.plot(xd[:1], yd[:1], 'ks', mfc='none', label='reference start')
    ax.set_aspect('equal', adjustable='datalim')
    ax.set_xlabel('x (m)')
    ax.set_ylabel('y (m)')
    ax.set_title('Path in the x-y plane (odom frame)')
    ax.grid(True, alpha=0.3)
    ax.legend(loc='best', fontsize='small')
    return fig


def _plot_errors(t, ex, ey, tolerance: float) -> Figure:
    fig = Figure(figsize=(7.5, 7.0), layout='constrained')
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


def _plot_xi(t, x, y, th, v, xd, yd, vxd, vyd, pose_topic: str) -> Figure:
    fig = Figure(figsize=(8.0, 8.0), layout='constrained')
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


def _plot_commands(t, v, w, note: str) -> Figure:
    fig = Figure(figsize=(7.5, 5.5), layout='constrained')
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
    """A readable summary: metrics table, messages per topic, gaps and plot files."""
    m = report.metrics
    tol = f'{m.tolerance * 100:g} cm'
    rows = [
        ('samples (pose matched with reference)', f'{report.matched} of {report.pose_samples}'),
        ('steps', str(m.steps)),
        ('duration', _fmt(m.duration, 's')),
        ('final position error', _fmt(m.final_error, 'm')),
        ('RMS position error', _fmt(m.rms_error, 'm')),
        (f'first within {tol}', _fmt(m.first_within, 's')),
        (f'enters and stays within {tol} at', _fmt(m.settling_time, 's')),
        ('RMS error after settling', _fmt(m.rms_error_settled, 'm')),
        ('max error after settling', _fmt(m.max_error_settled, 'm')),
        ('peak |v| (cmd_vel)', _fmt(m.peak_abs_v, 'm/s')),
        ('peak |w| (cmd_vel)', _fmt(m.peak_abs_w, 'rad/s')),
        ('pose step (median)', _fmt(report.median_step, 's')),
    ]
    width = max(len(r[0]) for r in rows)
    lines = [f'Bag {report.bag} (pose from {report.pose_topic})', '',
             f'{"metric":<{width}}  value', f'{"-" * width}  {"-" * 16}']
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
    else:
        lines += ['', f'gaps on {report.pose_topic}: none']
    if report.command_time_note:
        lines.append(f'note: {report.command_time_note}')
    if report.plots:
        lines += ['', f'plots in {report.out_dir}: ' + ', '.join(sorted(report.plots))]
    return '\n'.join(lines)
