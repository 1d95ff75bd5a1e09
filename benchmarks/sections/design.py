"""Benchmark section 12, design at scale (issue 24): latency-design speed, parallel sweeps.

Run through ``benchmarks/run.py --only design``; helpers come from ``harness``.

12.1  ``latency-design config/paper_problem.yaml --delay-interval 0 H --lag 0.05`` against a
      plain ``synthesize`` of the same problem, both as the user runs them (CLI
      subprocesses, imports included), alternated in one run; today's code (the branch's
      base commit, ``BENCH_BASELINE_REF``, extracted with ``git archive``) side by side.
12.2  a sweep of 200 designs (quick: 40) of the double integrator (``control.synthesis.sweep``):
      serial, two local worker processes, and a Dask LocalCluster of two single-threaded
      workers - wall time ratio to the serial run and the records compared design by design.
"""
from __future__ import annotations

import json
import os
import subprocess
import time
from pathlib import Path

from harness import CONFIG, PY, ROOT, Table, baseline_tree, fmt, log, run_worker, spread, summary

TARGETS_12 = {
    'latency_design_ratio': ('<=', 3.0, 'x synthesize'),
    'sweep_two_workers': ('<=', 0.55, 'x serial'),
}

#: The code before issue 24 (the base of the branch that made it).
BASELINE_REF = os.environ.get('BENCH_BASELINE_REF', 'd11fc49')

DI = dict(A=[[0.0, 1.0], [0.0, 0.0]], B=[[0.0], [1.0]], A_tau=[[0.0, 0.0], [0.0, 0.0]], tau=0.1,
          E=[[1.0]], F=[[0.2, 0.2]])




def _cli(args: list[str], pythonpath: Path | None = None, timeout: float = 600.0
         ) -> tuple[float, str]:
    env = dict(os.environ)
    if pythonpath is not None:
        # run from there: ``python -m`` puts the working directory first on sys.path
        env['PYTHONPATH'] = str(pythonpath)
    t0 = time.perf_counter()
    proc = subprocess.run([PY, '-m', 'nonfragile_tracker.cli', *args],
                          cwd=pythonpath or ROOT, env=env, capture_output=True, text=True,
                          timeout=timeout)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(f'{args[0]} failed: {proc.stderr[-300:]}')
    return wall, proc.stdout


def _figures(text: str) -> str:
    """The certified figures of a latency-design printout (decay, certified latency)."""
    keep = [ln for ln in text.splitlines()
            if 'decay rate' in ln or 'with the actuator lag' in ln or 'certified' in ln]
    return ' / '.join(k.strip() for k in keep)[:300]


#: What each command imports before its first solve (the start-up share of 12.1).
IMPORTS = {
    'synthesize': 'import nonfragile_tracker.cli, nonfragile_tracker.commands.synthesis, '
                  'nonfragile_tracker.control.synthesis.lmi, cvxpy',
    'latency-design': 'import nonfragile_tracker.cli, nonfragile_tracker.commands.latency_design, '
                      'nonfragile_tracker.control.synthesis.latency_design, '
                      'nonfragile_tracker.control.identification.monitor, '
                      'nonfragile_tracker.control.simulation.gains, cvxpy',
}


def _startup(code: str) -> float:
    """Wall time of a fresh interpreter that only imports (s)."""
    t0 = time.perf_counter()
    subprocess.run([PY, '-c', code], cwd=ROOT, check=True, capture_output=True, timeout=120)
    return time.perf_counter() - t0


def bench_startup(cfg, table: Table, raw: dict) -> None:
    """12.1.s: the start-up (imports) share of both commands, medians of alternated runs."""
    reps = 3 if cfg.quick else 5
    got: dict[str, list[float]] = {k: [] for k in IMPORTS}
    for _ in range(reps):
        for k, code in IMPORTS.items():
            got[k].append(_startup(code))
    s = {k: summary(v) for k, v in got.items()}
    raw['startup'] = s
    table.note('12.1.s', 'start-up (imports) of synthesize / latency-design',
               f'{fmt(s["synthesize"]["median"])} s / {fmt(s["latency-design"]["median"])} s '
               '(median; counted in both commands of 12.1.1 and 12.1.2)')


def bench_latency_design(cfg, table: Table, raw: dict) -> None:
    """12.1: latency-design / synthesize, today and now, medians of alternated runs."""
    reps = 1 if cfg.quick else 3
    base = baseline_tree(BASELINE_REF, 'nfbench_base_')
    paper = str(CONFIG / 'paper_problem.yaml')
    for k, h in enumerate((0.03, 0.15), start=1):
        ld = ['latency-design', paper, '--delay-interval', '0', str(h), '--lag', '0.05']
        syn, now, old, out_now, out_old = [], [], [], '', ''
        for _ in range(reps):
            syn.append(_cli(['synthesize', paper])[0])
            w, out_now = _cli(ld)
            now.append(w)
            if base is not None:
                w, out_old = _cli(ld, pythonpath=base)
                old.append(w)
        s, n, o = summary(syn), summary(now), summary(old)
        ratio_now = n['median'] / s['median']
        ratio_old = o['median'] / s['median'] if old else float('nan')
        raw[f'latency_design_{h}'] = {'synthesize': s, 'now': n, 'today': o,
                                      'figures_now': _figures(out_now),
                                      'figures_today': _figures(out_old)}
        log(f'12.1.{k}: [0, {h}] s: synthesize {fmt(s["median"])} s, latency-design '
            f'{fmt(n["median"])} s (today {fmt(o["median"])} s)')
        op, limit, unit = TARGETS_12['latency_design_ratio']
        table.add(f'12.1.{k}', f'latency-design [0, {h}] s, lag 50 ms / synthesize', ratio_now,
                  'x', detail=f'latency-design {fmt(n["median"])} s ({spread(n)}), synthesize '
                  f'{fmt(s["median"])} s; now: {_figures(out_now)}',
                  ratio=f'today {fmt(ratio_old)} x ({fmt(o["median"])} s; {_figures(out_old)})',
                  raw=raw[f'latency_design_{h}'])
        row = table.rows[-1]
        row['target'] = f'{op} {fmt(limit)} {unit}'
        row['status'] = 'MET' if ratio_now <= limit else 'MISSED'


def _sweep_points(count: int):
    from nonfragile_tracker.control.synthesis.sweep import sweep_points
    lats = [(0.0, 0.03), (0.0, 0.08), (0.05, 0.1), (0.1, 0.15), (0.0, 0.15)]
    lags = [0.0, 0.02, 0.05, 0.08, 0.1]
    bounds = [2.0, 2.5, 3.0, 4.0]
    pts = sweep_points(lats, lags=lags, gain_bounds=bounds, predictors=[False, True])
    return pts[:count]


def worker_sweep(mode: str, count: int) -> None:
    """Child of 12.2: one sweep, in a fresh process; prints wall time and the records."""
    import numpy as np
    from nonfragile_tracker.control.synthesis.problem import Problem
    from nonfragile_tracker.control.synthesis.sweep import run_sweep
    p = Problem(**{k: (np.array(v, float) if k != 'tau' else v) for k, v in DI.items()},
                name='di', perturbations={'minus': -np.eye(1), 'plus': np.eye(1)})
    pts = _sweep_points(count)
    t0 = time.perf_counter()
    if mode == 'dask':
        import distributed
        with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                      dashboard_address=None) as cluster, \
                distributed.Client(cluster) as client:
            t0 = time.perf_counter()          # the cluster's start-up is not the sweep's
            recs = run_sweep(p, pts, executor=client.get_executor())
    else:
        recs = run_sweep(p, pts, workers=1 if mode == 'serial' else 2)
    wall = time.perf_counter() - t0
    cpu = sum(r['seconds'] for r in recs)     # each design's own wall time, summed
    recs = [{k: v for k, v in r.items() if k != 'seconds'} for r in recs]
    print(json.dumps({'wall_s': wall, 'design_s': cpu, 'records': recs,
                      'loadavg': os.getloadavg()}))


def bench_sweep(cfg, table: Table, raw: dict) -> None:
    """12.2: a sweep serial, on two local workers and on a two-worker LocalCluster."""
    count = 40 if cfg.quick else 200
    out = {}
    for mode in ('serial', 'local2', 'dask'):
        # single-threaded BLAS, as the CLI runs (a multithreaded BLAS may round differently
        # from run to run, and the workers are the parallelism here)
        env = dict(os.environ, OPENBLAS_NUM_THREADS='1')
        res, wall, timed_out = run_worker(['sweep', mode, str(count)], timeout=3600.0,
                                          env=env)
        out[mode] = res
        log(f'12.2 sweep of {count} designs, {mode}: '
            f'{fmt(res["wall_s"]) if res else "failed"} s')
    raw['sweep'] = {m: (r['wall_s'] if r else None) for m, r in out.items()}
    ser = out['serial']
    if ser is None:
        table.note('12.2', 'sweep', 'the serial sweep failed (see the log)')
        return
    ok = sum(r['status'] == 'ok' for r in ser['records'])
    for rid, mode, label in (('12.2.1', 'local2', 'two local workers'),
                             ('12.2.2', 'dask', 'Dask LocalCluster, 2 workers')):
        r = out[mode]
        if r is None:
            table.note(rid, f'sweep of {count} designs, {label}', 'failed (see the log)')
            continue
        ratio = r['wall_s'] / ser['wall_s']
        same = r['records'] == ser['records']
        table.add(rid, f'sweep of {count} designs ({ok} certified), {label} / serial', ratio,
                  'x', detail=f'{fmt(r["wall_s"])} s vs serial {fmt(ser["wall_s"])} s '
                  f'(load {fmt(r["loadavg"][0])} / {fmt(ser["loadavg"][0])}); records equal '
                  f'design by design: {fmt(same)}')
        if mode == 'local2':
            op, limit, unit = TARGETS_12['sweep_two_workers']
            row = table.rows[-1]
            row['target'] = f'{op} {fmt(limit)} {unit}, equal'
            row['status'] = 'MET' if ratio <= limit and same else 'MISSED'
        else:
            row = table.rows[-1]
            row['target'] = 'equal to serial'
            row['status'] = 'MET' if same else 'MISSED'


def bench_design(cfg, table: Table, raw: dict) -> None:
    """Section 12 (issue 24)."""
    bench_latency_design(cfg, table, raw)
    bench_startup(cfg, table, raw)
    bench_sweep(cfg, table, raw)
