"""Robustness study: sample perturbations, latencies, lags and initial poses; run the batch.

:func:`sample_study_cases` draws ``N`` cases (seeded) around a base scenario,
:func:`run_study` runs them with
:func:`~nonfragile_tracker.control.simulation.batch.simulate_batch` (split over workers
when ``N`` is large, :mod:`nonfragile_tracker.parallel`) and :func:`summarize` reports the
worst case, the distribution of settling time and steady error, and the fraction of cases
inside the certified region of the gain.  No ROS import.

See doc/study.md (the certified region, the figures, the batch simulation).
"""
from __future__ import annotations

import math
import os
from concurrent.futures import Executor
from dataclasses import asdict, dataclass
from typing import Any, Mapping, cast

import numpy as np

from ...errors import InputError
from ...parallel import EXECUTORS, default_workers, map_tasks
from .batch import (BatchCases, BatchRun, PathBatch, perturbation_schedule, sample_deltas,
                    simulate_batch)
from .errors import BatchError
from .plant import PlantConfig
from .tracker import TrackerConfig
from .simulate import steps_for_duration

__all__ = ['StudySpec', 'StudyCases', 'StudyResult', 'sample_study_cases', 'run_study',
           'summarize', 'certified_limits', 'plot_study', 'default_jobs', 'DELTA_KINDS',
           'PERCENTILES']

#: How ``Delta(t)`` varies within a case.
DELTA_KINDS = ('constant', 'switching', 'random')
#: Percentiles reported.
PERCENTILES = (50, 90, 99)
#: Below this many cases per worker the study runs in this process: the batch loop's
#: per-step cost is mostly numpy's per-call overhead up to about 1,000 cases, so smaller
#: shares gain less than a worker process costs.
MIN_CASES_PER_JOB = 1000


def default_jobs() -> int:
    """Cores this process may use (:func:`.parallel.default_workers`)."""
    return default_workers()


def _range(value: Any, name: str, low: float = 0.0) -> tuple[float, float]:
    try:
        lo, hi = (float(v) for v in value)
    except (TypeError, ValueError):
        raise InputError(f'{name}: expected two numbers LO HI, got {value!r}') from None
    if not (math.isfinite(lo) and math.isfinite(hi) and low <= lo <= hi):
        raise InputError(f'{name}: expected {low:g} <= LO <= HI (finite), got [{lo}, {hi}]')
    return lo, hi


@dataclass(frozen=True)
class StudySpec:
    """What to sample (SI units; ranges are ``(lo, hi)``, uniform).

    ``pose_spread`` is ``(r, a)``: initial position uniform in a disc of radius ``r``
    (m) around the scenario's, heading uniform within ``+-a`` (rad).  ``delta_norm``
    is the range of ``||Delta||_2`` of each sampled matrix; ``hold`` (s) the segment
    length of a switching or random ``Delta(t)``.
    """

    cases: int = 1000
    seed: int = 0
    duration: float = 60.0
    latency: tuple[float, float] = (0.0, 0.0)
    lag: tuple[float, float] = (0.0, 0.0)
    pose_spread: tuple[float, float] = (0.0, 0.0)
    delta: str = 'constant'
    delta_norm: tuple[float, float] = (0.0, 1.0)
    hold: float = 1.0
    tolerance: float = 0.01
    steady_from: float | None = None

    def __post_init__(self) -> None:
        n = self.cases
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
            raise InputError(f'cases must be an integer >= 1, got {n!r}')
        seed = self.seed
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise InputError(f'seed must be an integer >= 0, got {seed!r}')
        for name in ('duration', 'hold', 'tolerance'):
            val = getattr(self, name)
            if not (isinstance(val, (int, float)) and math.isfinite(val) and val > 0):
                raise InputError(f'{name} must be a finite number > 0, got {val!r}')
        for name in ('latency', 'lag', 'pose_spread', 'delta_norm'):
            object.__setattr__(self, name, _range(getattr(self, name), name))
        if self.delta not in DELTA_KINDS:
            raise InputError(f'delta {self.delta!r}: choose one of {", ".join(DELTA_KINDS)}')
        if self.steady_from is not None and not (
                math.isfinite(self.steady_from) and 0 <= self.steady_from < self.duration):
            raise InputError(f'steady_from must be in [0, duration), got {self.steady_from!r}')


@dataclass(frozen=True)
class StudyCases:
    """The sampled cases: the batch input and what each case's parameters were."""

    batch: BatchCases
    delta_norm: np.ndarray        # max over segments of ||Delta||_2, per case
    latency: np.ndarray           # command latency (s)
    lag_v: np.ndarray
    lag_w: np.ndarray
    x0: np.ndarray
    y0: np.ndarray
    th0: np.ndarray


def sample_study_cases(spec: StudySpec, plant: PlantConfig, E: Any, F: Any) -> StudyCases:
    """Draw ``spec.cases`` cases around ``plant`` (seeded by ``spec.seed``).

    Parameters
    ----------
    spec : StudySpec
        Ranges and kinds.
    plant : PlantConfig
        The base scenario (initial pose, delay, odometry).
    E, F : array_like
        The perturbation structure ``E Delta F`` of the problem (``Delta`` is
        ``E.shape[1] x F.shape[0]``).

    Returns
    -------
    StudyCases
    """
    E = np.asarray(E, float)
    F = np.asarray(F, float)
    if E.ndim != 2 or F.ndim != 2 or E.shape[0] != 2 or F.shape[1] != 4:
        raise InputError(f'the tracking loop needs E 2 x p and F q x 4, got E {E.shape}, '
                         f'F {F.shape}')
    n = int(spec.cases)
    rng = np.random.default_rng(spec.seed)
    steps = steps_for_duration(spec.duration, plant.dt)
    segments = {'constant': 1, 'switching': 2,
                'random': max(1, math.ceil(steps * plant.dt / spec.hold))}[spec.delta]
    D = sample_deltas(rng, n, segments, (E.shape[1], F.shape[0]), radius=spec.delta_norm)
    norms = np.linalg.norm(D, ord=2, axis=(-2, -1)).max(axis=1)
    P = perturbation_schedule(E, F, D)
    latency = rng.uniform(*spec.latency, size=n)
    lag_v = rng.uniform(*spec.lag, size=n)
    lag_w = rng.uniform(*spec.lag, size=n)
    r = spec.pose_spread[0] * np.sqrt(rng.uniform(size=n))
    phi = rng.uniform(0.0, 2.0 * math.pi, size=n)
    x0 = plant.x0 + r * np.cos(phi)
    y0 = plant.y0 + r * np.sin(phi)
    th0 = plant.th0 + rng.uniform(-1.0, 1.0, size=n) * spec.pose_spread[1]
    batch = BatchCases(n, perturbation=P, hold=spec.hold, cmd_latency=latency, lag_v=lag_v,
                       lag_w=lag_w, x0=x0, y0=y0, th0=th0)
    return StudyCases(batch, norms, latency, lag_v, lag_w, x0, y0, th0)


def certified_limits(design: Mapping[str, Any] | None) -> dict[str, float]:
    """Certified latency (s) without lag, and the lag and latency certified with it.

    Parameters
    ----------
    design : mapping or None
        The gain file's design record (:func:`.control.simulation.gains.read_gain_design`; ``None``:
        nothing recorded).

    Returns
    -------
    dict
        ``latency`` (``certified_h_max``, else ``certified_latency``; 0 if absent), ``lag``
        (``actuator_lag``), ``lag_latency`` (``lag_certified_h_max``) and ``recorded``
        (whether the record names a certified latency).
    """
    design = design or {}

    def num(key: str) -> float | None:
        val = design.get(key)
        return float(val) if isinstance(val, (int, float)) and not isinstance(val, bool) \
            and math.isfinite(val) else None

    h = num('certified_h_max')
    h = num('certified_latency') if h is None else h
    return {'latency': h if h is not None else 0.0,
            'lag': num('actuator_lag') or 0.0,
            'lag_latency': num('lag_certified_h_max') or 0.0,
            'recorded': h is not None}


def in_certified_region(cases: StudyCases, limits: Mapping[str, float],
                        odom_latency: float = 0.0) -> np.ndarray:
    """Per case: ``||Delta|| <= 1`` and latency (and lag) within the certified limits.

    Parameters
    ----------
    cases : StudyCases
        The sampled cases.
    limits : mapping of str to float
        :func:`certified_limits` of the gain.
    odom_latency : float
        Odometry latency (s) added to each case's command latency (the loop's latency).

    Returns
    -------
    numpy.ndarray of bool
        One entry per case.
    """
    eps = 1e-12
    loop_latency = cases.latency + odom_latency
    no_lag = (cases.lag_v == 0) & (cases.lag_w == 0)
    lag_ok = no_lag & (loop_latency <= limits['latency'] + eps)
    if limits['lag'] > 0:
        lag_ok |= ((np.maximum(cases.lag_v, cases.lag_w) <= limits['lag'] + eps)
                   & (loop_latency <= limits['lag_latency'] + eps))
    return cast(np.ndarray, (cases.delta_norm <= 1.0 + eps) & lag_ok)


def _run_chunk(plant: PlantConfig, tracker: TrackerConfig, path: Any, steps: int,
               batch: BatchCases, tolerance: float, steady_from: float | None) -> BatchRun:
    # statistics over many cases: the cheaper forms (``exact=False``) of simulate_batch
    return simulate_batch(plant, tracker, path, steps, batch, tolerance=tolerance,
                          steady_from=steady_from, exact=False)


def _chunk_task(task: tuple[Any, ...]) -> BatchRun:
    return _run_chunk(*task)


@dataclass(frozen=True)
class StudyResult:
    """Per-case outcome of a study (arrays over cases) and its inputs."""

    spec: StudySpec
    cases: StudyCases
    run: BatchRun
    inside: np.ndarray
    limits: dict[str, float]
    jobs: int


def _concat(runs: list[BatchRun]) -> BatchRun:
    if len(runs) == 1:
        return runs[0]

    def cat(field: str) -> np.ndarray:
        return np.concatenate([getattr(r, field) for r in runs])

    first = runs[0]
    return BatchRun(steps=first.steps, dt=first.dt, tolerance=first.tolerance,
                    steady_from=first.steady_from, settling_time=cat('settling_time'),
                    first_within=cat('first_within'), final_error=cat('final_error'),
                    rms_error=cat('rms_error'), steady_error=cat('steady_error'),
                    peak_abs_v=cat('peak_abs_v'), peak_abs_w=cat('peak_abs_w'),
                    finite=cat('finite'))


def run_study(spec: StudySpec, plant: PlantConfig, tracker: TrackerConfig, path: Any, E: Any,
              F: Any,
              design: Mapping[str, Any] | None = None, jobs: int | None = None, *,
              executor: str | Executor = 'local', scheduler: str | None = None
              ) -> StudyResult:
    """Sample the cases of ``spec`` and simulate them all.

    Parameters
    ----------
    spec : StudySpec
    plant, tracker : PlantConfig, TrackerConfig
        Base scenario and tracker (gain ``K``).
    path : PathBatch
        The reference (picklable: sent to the worker processes).
    E, F : array_like
        Perturbation structure.
    design : mapping, optional
        The gain file's design record (:func:`.control.simulation.gains.read_gain_design`).
    jobs : int, optional
        Workers, i.e. shares of the cases (default: the cores available); fewer are used
        when there are fewer than :data:`MIN_CASES_PER_JOB` cases per worker, none (this
        process) for one share on the local executor.
    executor : {'local', 'dask'} or concurrent.futures.Executor
        Where the shares run (:func:`.parallel.map_tasks`): local processes, a Dask
        cluster (``scheduler`` address, or a LocalCluster of ``jobs`` workers), or an
        executor the caller made.  The cases and their results do not depend on it.
    scheduler : str, optional
        Dask scheduler address (``executor='dask'``).
    """
    if not isinstance(path, PathBatch):
        raise BatchError('run_study needs the path as a PathBatch (sent to worker processes)')
    if isinstance(executor, str) and executor not in EXECUTORS:
        raise InputError(f'executor must be one of {EXECUTORS}, got {executor!r}')
    if scheduler is not None and executor != 'dask':
        raise InputError('--scheduler applies to --executor dask only')
    jobs = default_jobs() if jobs is None else jobs
    if isinstance(jobs, bool) or not isinstance(jobs, (int, np.integer)) or jobs < 1:
        raise InputError(f'jobs must be an integer >= 1, got {jobs!r}')
    cases = sample_study_cases(spec, plant, E, F)
    steps = steps_for_duration(spec.duration, plant.dt)
    n = spec.cases
    jobs = int(max(1, min(jobs, n // MIN_CASES_PER_JOB)))
    args = (plant, tracker, path, steps)
    if jobs == 1 and isinstance(executor, str) and executor == 'local':
        run = _run_chunk(*args, cases.batch, spec.tolerance, spec.steady_from)
    else:
        bounds = np.linspace(0, n, jobs + 1).round().astype(int)
        chunks = [cases.batch.take(slice(a, b)) for a, b in zip(bounds[:-1], bounds[1:])]
        tasks = [(*args, c, spec.tolerance, spec.steady_from) for c in chunks]
        run = _concat(map_tasks(_chunk_task, tasks, executor=executor, workers=jobs,
                                scheduler=scheduler))
    limits = certified_limits(design)
    inside = in_certified_region(cases, limits, plant.odom_latency)
    return StudyResult(spec, cases, run, inside, limits, jobs)


def _stats(values: np.ndarray) -> dict[str, float | None]:
    out: dict[str, float | None] = {f'p{p}': None for p in PERCENTILES}
    out.update(max=None, mean=None)
    if values.size:
        for p, v in zip(PERCENTILES, np.percentile(values, PERCENTILES)):
            out[f'p{p}'] = float(v)
        out['max'] = float(values.max())
        out['mean'] = float(values.mean())
    return out


def _group(run: BatchRun, mask: np.ndarray) -> dict[str, Any]:
    settle = run.settling_time[mask]
    steady = run.steady_error[mask]
    settled = np.isfinite(settle)
    finite = np.isfinite(steady)
    n = int(mask.sum())
    return {'cases': n,
            'settled_fraction': float(settled.mean()) if n else None,
            'settling_time': _stats(settle[settled]),
            'diverged': int((~run.finite[mask]).sum()),
            'steady_error': _stats(steady[finite])}


def _case(result: StudyResult, i: int) -> dict[str, Any]:
    c, r = result.cases, result.run

    def num(v: float) -> float | None:
        return float(v) if math.isfinite(v) else None

    return {'index': int(i), 'delta_norm': float(c.delta_norm[i]),
            'latency': float(c.latency[i]), 'lag_v': float(c.lag_v[i]),
            'lag_w': float(c.lag_w[i]), 'x0': float(c.x0[i]), 'y0': float(c.y0[i]),
            'th0': float(c.th0[i]), 'inside': bool(result.inside[i]),
            'settling_time': num(r.settling_time[i]), 'steady_error': num(r.steady_error[i]),
            'final_error': num(r.final_error[i]), 'peak_abs_w': num(r.peak_abs_w[i])}


def summarize(result: StudyResult) -> dict[str, Any]:
    """JSON-ready summary: spec, certified limits, per-group distributions, worst cases.

    Parameters
    ----------
    result : StudyResult
        A study's result (:func:`run_study`).

    Returns
    -------
    dict
    """
    run = result.run
    allc = np.ones(run.n, dtype=bool)
    steady = np.where(np.isfinite(run.steady_error), run.steady_error, np.inf)
    settle = np.where(np.isfinite(run.settling_time), run.settling_time, np.inf)
    spec = asdict(result.spec)
    return {'spec': spec, 'steps': run.steps, 'dt': run.dt, 'tolerance': run.tolerance,
            'steady_from': run.steady_from, 'jobs': result.jobs,
            'certified': dict(result.limits),
            'inside_fraction': float(result.inside.mean()),
            'all': _group(run, allc), 'inside': _group(run, result.inside),
            'outside': _group(run, ~result.inside),
            'worst_steady_error': _case(result, int(np.argmax(steady))),
            'worst_settling_time': _case(result, int(np.argmax(settle)))}


def case_records(result: StudyResult) -> list[dict[str, Any]]:
    """One JSON-ready record per case (parameters and metrics).

    Parameters
    ----------
    result : StudyResult
        A study's result (:func:`run_study`).

    Returns
    -------
    list of dict
    """
    return [_case(result, i) for i in range(result.run.n)]


def plot_study(result: StudyResult, path: str | os.PathLike[str]) -> None:
    """PNG of the distributions: settling time, steady error, error against latency.

    Parameters
    ----------
    result : StudyResult
        A study's result (:func:`run_study`).
    path : str or os.PathLike
        The PNG file written.
    """
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    run, inside = result.run, result.inside
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.5))
    groups = [(inside, 'inside certified region', 'tab:blue'),
              (~inside, 'outside', 'tab:orange')]
    ax = axes[0]
    settle = run.settling_time
    ok = np.isfinite(settle)
    if ok.any():
        bins = np.linspace(settle[ok].min(), settle[ok].max() + 1e-9, 40)
        for mask, label, color in groups:
            if (mask & ok).any():
                ax.hist(settle[mask & ok], bins=bins, alpha=0.6, label=label, color=color)
    ax.set_xlabel(f'settling time to {run.tolerance:g} m (s)')
    ax.set_ylabel('cases')
    ax.set_title(f'settled: {ok.mean():.1%} of {run.n}')
    ax.legend()
    ax = axes[1]
    steady = run.steady_error
    fin = np.isfinite(steady) & (steady > 0)
    if fin.any():
        lo, hi = np.log10(steady[fin].min()), np.log10(steady[fin].max()) + 1e-9
        bins = np.logspace(lo, max(hi, lo + 1e-3), 40)
        for mask, label, color in groups:
            if (mask & fin).any():
                ax.hist(steady[mask & fin], bins=bins, alpha=0.6, label=label, color=color)
        ax.set_xscale('log')
    ax.set_xlabel(f'steady error: max over t >= {run.steady_from:g} s (m)')
    ax.set_title('steady error')
    ax.legend()
    ax = axes[2]
    sc = ax.scatter(result.cases.latency[fin], steady[fin], c=result.cases.delta_norm[fin],
                    s=6, cmap='viridis')
    if result.limits['latency'] > 0:
        ax.axvline(result.limits['latency'], color='k', ls='--', lw=1,
                   label=f'certified latency {result.limits["latency"]:.3g} s')
        ax.legend()
    ax.set_yscale('log')
    ax.set_xlabel('command latency (s)')
    ax.set_ylabel('steady error (m)')
    fig.colorbar(sc, ax=ax, label='max ||Delta||_2')
    fig.suptitle(f'robustness study: {run.n} cases, {run.steps * run.dt:g} s each; '
                 f'{inside.mean():.1%} inside the certified region')
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
