"""Design-space sweeps: certified latency designs over a grid, in parallel, and their front.

What each extra 50 ms of certified latency costs in decay rate and gain norm, with or
without the predictor, for a lag: :func:`sweep_points` makes the grid (latency interval x
lag x gain bound x objective x predictor), :func:`run_sweep` designs every point with
:func:`.latency_design.design_for_latency` on an executor of :mod:`nonfragile_tracker.parallel`,
and :func:`pareto_front` / :func:`plot_sweep` show the trade-off.  The records are the same
on every executor, in the order of the points.  No ROS import.

See doc/cli.md, section "sweep" (the delay interval of a point, the certified command
latency, the order of the work).
"""
from __future__ import annotations

import itertools
import math
import time
from concurrent.futures import Executor
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Sequence

import numpy as np

from ...errors import InputError
from ..validate import as_finite_float
from .errors import InfeasibleError, LmiError
from ...parallel import map_tasks
from .latency_design import OBJECTIVES, delay_interval, design_for_latency
from .problem import Problem

__all__ = ['SweepPoint', 'sweep_points', 'design_point', 'run_sweep', 'pareto_front',
           'sweep_table', 'plot_sweep', 'records_for_json', 'DEFAULT_COMMAND_PERIOD']

#: The tracker's command period (s) unless the caller gives one.
DEFAULT_COMMAND_PERIOD = 0.02


@dataclass(frozen=True)
class SweepPoint:
    """One design of a sweep: what the robot has and what the design may use."""

    latency: tuple[float, float]      # command latency interval [L_lo, L_hi] (s)
    lag: float                        # first-order actuator time constant (s), 0: none
    gain_bound: float | None          # ||K||_2 bound (None: the problem's)
    objective: str                    # 'decay' or 'max-delay'
    predictor: bool                   # the tracker predicts L_lo (residual certified)


def sweep_points(latencies: Iterable[Sequence[float]], lags: Iterable[float] = (0.0,),
                 gain_bounds: Iterable[float | None] = (None,),
                 objectives: Iterable[str] = ('decay',),
                 predictors: Iterable[bool] = (False, True)) -> list[SweepPoint]:
    """The grid: every combination, latency outermost (the order of the records).

    Parameters
    ----------
    latencies : iterable of (float, float)
        Command latency intervals ``[L_lo, L_hi]`` (s), ``0 <= L_lo <= L_hi``.
    lags : iterable of float
        Actuator time constants (s), 0 for none.
    gain_bounds : iterable of float or None
        ``||K||_2`` bounds (None: the problem's ``options.gain_bound``).
    objectives : iterable of str
        ``'decay'`` and/or ``'max-delay'``.
    predictors : iterable of bool
        Without (False) and/or with (True) the predictor.  For an interval starting at 0
        the predictor has nothing to remove: the two are one design, made once (without).

    Raises
    ------
    InputError
        A bad number, interval or objective, or an empty axis.
    """
    lat = []
    for pair in latencies:
        if len(pair) != 2:
            raise InputError(f'a latency interval is two numbers LO HI, got {pair!r}')
        lo, hi = (as_finite_float(x, 'latency', low=0.0) for x in pair)
        if lo > hi:
            raise InputError(f'latency interval needs LO <= HI, got [{lo:g}, {hi:g}]')
        lat.append((lo, hi))
    lag_v = [as_finite_float(x, 'lag', low=0.0) for x in lags]
    bounds = [None if b is None else as_finite_float(b, 'gain bound', low=0.0, low_inclusive=False)
              for b in gain_bounds]
    objs = list(objectives)
    bad = [o for o in objs if o not in OBJECTIVES]
    if bad:
        raise InputError(f'objective must be one of {OBJECTIVES}, got {bad[0]!r}')
    preds = [bool(p) for p in predictors]
    axes = {'latency': lat, 'lag': lag_v, 'gain bound': bounds, 'objective': objs,
            'predictor': preds}
    empty = [k for k, v in axes.items() if not v]
    if empty:
        raise InputError(f'the sweep grid has no {empty[0]} value')
    return [SweepPoint(latency=la, lag=lg, gain_bound=b, objective=o, predictor=pr)
            for la, lg, b, o, pr in itertools.product(lat, lag_v, bounds, objs, preds)
            if not (pr and la[0] == 0 and False in preds)]


def _task(task: tuple[Problem, SweepPoint, float, float]) -> dict[str, Any]:
    return design_point(*task)


def design_point(problem: Problem, point: SweepPoint,
                 command_period: float = DEFAULT_COMMAND_PERIOD, tol: float = 2e-3
                 ) -> dict[str, Any]:
    """Design one point; a flat, JSON-ready record (never raises for an infeasible point).

    Parameters
    ----------
    problem : Problem
        The plant.
    point : SweepPoint
        What to design.
    command_period : float
        The tracker's command period ``T`` (s).
    tol : float
        Tolerance of the certified ``h_max`` (s).

    Returns
    -------
    dict
        The point, the delay interval certified, ``status`` (``'ok'``, ``'infeasible'`` or
        ``'failed'``, with ``message``), and for ``'ok'``: ``K``, ``gain_norm``,
        ``decay_rate``, ``certified_h_max`` (the loop the design is for),
        ``certified_command_latency`` (module docstring), ``true_delay_margin``,
        ``worst_abscissa``, ``verified`` (numpy verification of the synthesis) and the
        design's own ``seconds``.
    """
    h0, h1 = delay_interval(point.latency[0], point.latency[1], predictor=point.predictor,
                            command_period=command_period)
    rec: dict[str, Any] = {
        'latency': list(point.latency), 'lag': point.lag, 'gain_bound': point.gain_bound,
        'objective': point.objective, 'predictor': point.predictor,
        'command_period': float(command_period), 'delay_interval': [h0, h1]}
    t0 = time.perf_counter()
    try:
        d = design_for_latency(problem, h0, h1, gain_bound=point.gain_bound,
                               objective=point.objective, lag=point.lag, tol=tol)
    except InfeasibleError as exc:
        rec.update(status='infeasible', message=str(exc),
                   seconds=time.perf_counter() - t0)
        return rec
    except LmiError as exc:
        rec.update(status='failed', message=str(exc), seconds=time.perf_counter() - t0)
        return rec
    H = d.lag_certified_h_max if d.lag_certified_h_max is not None else d.certified_h_max
    base = point.latency[0] if point.predictor else 0.0
    rec.update(
        status='ok', message='', K=np.asarray(d.K).tolist(), gain_norm=d.gain_norm,
        gain_bound_used=d.gain_bound, decay_rate=d.decay_rate, certified_h_max=float(H),
        certified_command_latency=float(max(base + H - command_period, 0.0)),
        true_delay_margin=d.true_delay_margin, worst_abscissa=d.worst_abscissa,
        verified=bool(d.synthesis.verification.ok),
        verification_max_eig=d.synthesis.verification.max_eig_Psi,
        seconds=time.perf_counter() - t0)
    return rec


def run_sweep(problem: Problem, points: Sequence[SweepPoint], *,
              command_period: float = DEFAULT_COMMAND_PERIOD, tol: float = 2e-3,
              executor: str | Executor = 'local', workers: int | None = None,
              scheduler: str | None = None) -> list[dict[str, Any]]:
    """Design every point on ``executor``; records in the order of ``points``.

    Parameters
    ----------
    problem : Problem
        The plant (sent to the workers).
    points : sequence of SweepPoint
        From :func:`sweep_points`.
    command_period : float
        The tracker's command period (s).
    tol : float
        Tolerance of each certified ``h_max`` (s).
    executor, workers, scheduler
        As in :func:`.parallel.map_tasks` (``'local'`` processes by default, ``'dask'``,
        or a ``concurrent.futures.Executor``).
    """
    T = as_finite_float(command_period, 'command period', low=0.0, low_inclusive=False)
    tasks = [(problem, p, T, float(tol)) for p in points]
    if isinstance(executor, str) and executor == 'local':
        # forked workers inherit what this process imported: cvxpy once here (about 0.7 s
        # of CPU), not once per worker
        import cvxpy  # noqa: F401
    return map_tasks(_task, tasks, executor=executor, workers=workers, scheduler=scheduler,
                     cost=_cost)


def _cost(task: tuple[Problem, SweepPoint, float, float]) -> float:
    """Relative run time of a design, for the order of a parallel sweep (longest first).

    Measured on the double integrator of the benchmarks (one core): a design with an
    actuator lag takes 0.25-0.48 s (its lagged loop is certified with a larger program
    and its exact figures are those of a larger loop), one without 0.20-0.23 s; a
    ``'max-delay'`` design bisects the delay itself; within a class a longer interval
    (with the lag) takes a little longer.
    """
    _, p, T, _ = task
    return (2.0 if p.objective == 'max-delay' else 1.0) * (
        (1.0 if p.lag > 0 else 0.0) + 0.1 * (p.latency[1] + T + p.lag))


def pareto_front(records: Sequence[dict[str, Any]]) -> list[int]:
    """Indices of the designs no other design for the same robot beats in every figure.

    Figures: certified command latency (more is better), decay rate (more) and
    ``||K||_2`` (less).  Designs are compared within the same actuator lag only (a
    design for another lag is not certified for this robot).  Only ``'ok'`` records
    count; ties are kept.

    Parameters
    ----------
    records : sequence of dict
        Sweep records (:func:`run_sweep`'s).

    Returns
    -------
    list of int
        Indices into ``records``.
    """
    ok = [i for i, r in enumerate(records) if r.get('status') == 'ok']
    lags = {records[i]['lag'] for i in ok}
    if len(lags) > 1:
        return sorted(i for lag in lags for i in pareto_front(
            [r if r.get('lag') == lag else {'status': 'other'} for r in records]))

    def vec(r: dict[str, Any]) -> tuple[float, float, float]:
        return (r['certified_command_latency'], r['decay_rate'], -r['gain_norm'])

    front = []
    for i in ok:
        a = vec(records[i])
        if not any(all(b >= x for b, x in zip(vec(records[j]), a)) and vec(records[j]) != a
                   for j in ok if j != i):
            front.append(i)
    return front


def sweep_table(records: Sequence[dict[str, Any]]) -> str:
    """One line per design (fixed columns), the Pareto-front designs marked ``*``.

    Parameters
    ----------
    records : sequence of dict
        Sweep records; a failed design's line has its status and no figures.

    Returns
    -------
    str
        The table, a header line first.
    """
    front = set(pareto_front(records))
    head = (f'{"":1} {"latency [s]":>15} {"lag":>6} {"bound":>6} {"objective":>9} '
            f'{"pred":>4} {"interval [s]":>15} {"status":>10} {"||K||":>7} {"decay":>7} '
            f'{"cert. lat.":>10} {"margin":>7}')
    lines = [head]
    for i, r in enumerate(records):
        lat = f'[{r["latency"][0]:.3g}, {r["latency"][1]:.3g}]'
        iv = f'[{r["delay_interval"][0]:.3g}, {r["delay_interval"][1]:.3g}]'
        bound = r.get('gain_bound_used', r.get('gain_bound'))
        b = '-' if bound is None else f'{bound:.3g}'
        line = (f'{"*" if i in front else " "} {lat:>15} {r["lag"]:>6.3g} {b:>6} '
                f'{r["objective"]:>9} {"yes" if r["predictor"] else "no":>4} {iv:>15} '
                f'{r["status"]:>10}')
        if r['status'] == 'ok':
            line += (f' {r["gain_norm"]:>7.3f} {r["decay_rate"]:>7.3f} '
                     f'{r["certified_command_latency"]:>10.4f} {r["true_delay_margin"]:>7.4f}')
        lines.append(line)
    return '\n'.join(lines)


def plot_sweep(records: Sequence[dict[str, Any]], path: str | Path) -> None:
    """PNG: certified command latency against decay rate and against ``||K||_2``.

    Every ``'ok'`` design is a marker (circle: without the predictor, square: with it;
    colour: the lag), the Pareto front (:func:`pareto_front`, per lag) is ringed.

    Parameters
    ----------
    records : sequence of dict
        Sweep records.
    path : str or pathlib.Path
        The PNG file to write.
    """
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    front = set(pareto_front(records))
    ok = [r for r in records if r.get('status') == 'ok']
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.5))
    for ax, key, label in ((axes[0], 'decay_rate', 'certified decay rate (1/s)'),
                           (axes[1], 'gain_norm', '||K||_2')):
        for pred, marker in ((False, 'o'), (True, 's')):
            sel = [r for r in ok if r['predictor'] == pred]
            if sel:
                ax.scatter([r['certified_command_latency'] for r in sel],
                           [r[key] for r in sel], c=[r['lag'] for r in sel], cmap='viridis',
                           marker=marker, s=28,
                           label='with predictor' if pred else 'without predictor')
        fr = sorted((r for i, r in enumerate(records) if i in front),
                    key=lambda r: r['certified_command_latency'])
        if fr:
            ax.scatter([r['certified_command_latency'] for r in fr], [r[key] for r in fr],
                       facecolors='none', edgecolors='red', s=90, label='Pareto front')
        ax.set_xlabel('certified command latency (s)')
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    lags = sorted({r['lag'] for r in ok})
    if len(lags) > 1 and ok:
        sm = plt.cm.ScalarMappable(cmap='viridis',
                                   norm=plt.Normalize(vmin=lags[0], vmax=lags[-1]))
        fig.colorbar(sm, ax=axes[1], label='actuator lag (s)')
    axes[0].set_title('decay rate against certified latency (front: per lag)')
    axes[1].set_title('gain norm against certified latency')
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def records_for_json(records: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """The records with the front marked (``pareto``), non-finite numbers as None.

    Parameters
    ----------
    records : sequence of dict
        Sweep records (not modified).

    Returns
    -------
    list of dict
        JSON-ready copies.
    """
    front = set(pareto_front(records))

    def clean(v: Any) -> Any:
        if isinstance(v, float) and not math.isfinite(v):
            return None
        if isinstance(v, list):
            return [clean(x) for x in v]
        return v

    return [{**{k: clean(v) for k, v in r.items()}, 'pareto': i in front}
            for i, r in enumerate(records)]
