#!/usr/bin/env python3
"""Speed, cost and control-quality benchmarks of nonfragile_tracker (issue 7).

    .venv/bin/python benchmarks/run.py [--quick] [--json PATH] [--only SECTIONS]

Prints ONE table (median and spread over repetitions, ratios where a baseline
exists, targets with met/missed) and writes a JSON file with every raw number,
the date and the machine.  Not part of the test suite.  See benchmarks/README.md.

Every ROS measurement runs on localhost discovery and a domain id of its own
(215..232 by default, outside the 100..199 of the tests and the runner), and
every process started here is stopped (SIGINT, then kill) before the next one.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
CONFIG = ROOT / 'config'
HELPERS = HERE / 'ros_helpers.py'
PY = sys.executable
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

# Targets of issue 7 (figure -> (operator, value, unit)).
TARGETS = {
    'lockstep_processes': ('>=', 2000.0, 'steps/s'),
    'lockstep_composed': ('>=', 10000.0, 'steps/s'),
    'latency_p99_100hz': ('<=', 1.0, 'ms'),
    'simulation': ('>=', 1000.0, 'sim s/wall s'),
    'warm_resolve': ('<=', 5.0, 'ms'),
}

T_START = time.monotonic()


def log(msg: str) -> None:
    print(f'[bench {time.monotonic() - T_START:6.1f} s] {msg}', file=sys.stderr, flush=True)


def elapsed() -> float:
    return time.monotonic() - T_START


# --------------------------------------------------------------------------------- statistics

def summary(xs) -> dict:
    """Median, min, max, quartiles and the raw values of the finite entries of ``xs``."""
    import numpy as np
    vals = [float(x) for x in xs if x is not None and math.isfinite(float(x))]
    if not vals:
        return {'n': 0, 'median': math.nan, 'min': math.nan, 'max': math.nan,
                'q1': math.nan, 'q3': math.nan, 'values': []}
    a = np.asarray(vals)
    return {'n': len(vals), 'median': float(np.median(a)), 'min': float(a.min()),
            'max': float(a.max()), 'q1': float(np.percentile(a, 25)),
            'q3': float(np.percentile(a, 75)), 'values': vals}


def timeit(fn, reps: int) -> tuple[dict, list]:
    """Wall time of ``fn()`` over ``reps`` calls: (summary in s, results)."""
    ts, out = [], []
    for _ in range(reps):
        t0 = time.perf_counter()
        out.append(fn())
        ts.append(time.perf_counter() - t0)
    return summary(ts), out


def fmt(x, digits: int = 3) -> str:
    """Compact number: 3 significant digits, thousands separators, nan as '-'."""
    if x is None:
        return '-'
    if isinstance(x, str):
        return x
    if isinstance(x, bool):
        return 'yes' if x else 'no'
    if isinstance(x, int):
        return f'{x:,}'
    if math.isnan(x):
        return '-'
    if math.isinf(x):
        return 'inf' if x > 0 else '-inf'
    ax = abs(x)
    if ax >= 1000:
        return f'{x:,.0f}'
    if ax == 0:
        return '0'
    if ax < 1e-3:
        return f'{x:.{digits - 1}e}'
    decimals = max(0, digits - 1 - int(math.floor(math.log10(ax))))
    return f'{x:.{decimals}f}'


def length(x: float) -> str:
    """A distance in m as mm or um."""
    if x is None or not math.isfinite(x):
        return '-'
    return f'{fmt(x * 1e3)} mm' if abs(x) >= 1e-3 else f'{fmt(x * 1e6)} um'


def spread(s: dict, scale: float = 1.0) -> str:
    if not s or s.get('n', 0) == 0:
        return '-'
    if s['n'] == 1:
        return 'n=1'
    return f"{fmt(s['min'] * scale)}-{fmt(s['max'] * scale)} (n={s['n']})"


class Table:
    """The one table: rows of (id, figure, value, unit, spread/detail, ratio, target, status)."""

    def __init__(self) -> None:
        self.rows: list[dict] = []

    def add(self, rid: str, figure: str, value, unit: str = '', detail: str = '',
            ratio: str = '', target: str | None = None, raw=None) -> dict:
        status = ''
        tgt = ''
        if target is not None:
            op, limit, tunit = TARGETS[target]
            tgt = f'{op} {fmt(limit)} {tunit}'
            if value is None or (isinstance(value, float) and math.isnan(value)):
                status = 'n/a'
            else:
                ok = value >= limit if op == '>=' else value <= limit
                status = 'MET' if ok else 'MISSED'
        row = {'id': rid, 'figure': figure, 'value': value, 'unit': unit, 'detail': detail,
               'ratio': ratio, 'target': tgt, 'status': status, 'target_key': target}
        if raw is not None:
            row['raw'] = raw
        self.rows.append(row)
        return row

    def note(self, rid: str, figure: str, text: str) -> None:
        self.rows.append({'id': rid, 'figure': figure, 'value': None, 'unit': '',
                          'detail': text, 'ratio': '', 'target': '', 'status': 'skipped',
                          'target_key': None})

    def render(self) -> str:
        head = ['#', 'figure', 'median', 'unit', 'spread (min-max) / detail', 'ratio / baseline',
                'target', 'status']
        body = [[r['id'], r['figure'], fmt(r['value']) if r['value'] is not None else '-',
                 r['unit'], r['detail'], r['ratio'], r['target'], r['status']]
                for r in self.rows]
        widths = [max(len(h), *(len(b[i]) for b in body)) if body else len(h)
                  for i, h in enumerate(head)]
        widths = [min(w, lim) for w, lim in zip(widths, (8, 52, 10, 12, 64, 36, 22, 7))]

        def line(cells):
            import textwrap
            cols = [textwrap.wrap(c, w, break_on_hyphens=False) or [''] for c, w in
                    zip(cells, widths)]
            out = []
            for k in range(max(len(c) for c in cols)):
                row = []
                for i, (c, w) in enumerate(zip(cols, widths)):
                    t = c[k] if k < len(c) else ''
                    row.append(t.rjust(w) if i == 2 else t.ljust(w))
                out.append('| ' + ' | '.join(row) + ' |')
            return '\n'.join(out)
        sep = '|-' + '-|-'.join('-' * w for w in widths) + '-|'
        lines = [line(head), sep]
        prev = None
        for b, r in zip(body, self.rows):
            sec = r['id'].split('.')[0]
            if prev is not None and sec != prev:
                lines.append(sep)
            prev = sec
            lines.append(line(b))
        return '\n'.join(lines)


# --------------------------------------------------------------------------------- processes

class Procs:
    """Processes started here; ``stop()`` sends SIGINT, waits, then kills (by pid only)."""

    live: list['Procs'] = []

    def __init__(self) -> None:
        self.procs: list[subprocess.Popen] = []
        Procs.live.append(self)

    def start(self, cmd: list[str], env: dict, log_path: Path | None = None) -> subprocess.Popen:
        out = open(log_path, 'w') if log_path is not None else subprocess.DEVNULL
        p = subprocess.Popen(cmd, env=env, stdin=subprocess.DEVNULL, stdout=out,
                             stderr=subprocess.STDOUT, cwd=str(ROOT))
        if log_path is not None:
            out.close()
        self.procs.append(p)
        return p

    def stop(self, grace: float = 5.0) -> dict:
        for p in self.procs:
            if p.poll() is None:
                try:
                    p.send_signal(signal.SIGINT)
                except ProcessLookupError:
                    pass
        deadline = time.monotonic() + grace
        for p in self.procs:
            try:
                p.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
        codes = {p.pid: p.returncode for p in self.procs}
        self.procs = []
        if self in Procs.live:
            Procs.live.remove(self)
        return codes

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.stop()

    @classmethod
    def stop_all(cls) -> None:
        for group in list(cls.live):
            group.stop(grace=3.0)


def ros_env(domain: int) -> dict:
    env = dict(os.environ)
    env['ROS_DOMAIN_ID'] = str(domain)
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    env['PYTHONUNBUFFERED'] = '1'
    env['PYTHONPATH'] = str(ROOT) + (os.pathsep + env['PYTHONPATH'] if env.get('PYTHONPATH')
                                     else '')
    return env


def write_params(path: Path, params: dict, wildcard: bool = True) -> Path:
    """Parameter file; ``/**/node`` keys so that the file applies in any namespace."""
    import yaml

    def bare(key: str) -> str:               # 'plant', '/plant' and '/**/plant' -> 'plant'
        return key.split('/')[-1]
    data = {(f'/**/{bare(k)}' if wildcard else k): v for k, v in params.items()}
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def realtime_params(rate: float) -> dict:
    from nonfragile_tracker import runner
    dt = 1.0 / rate
    return runner.scenario_parameters(CONFIG / 'paper_scenario.yaml', CONFIG / 'tracker_gains.yaml', {
        'plant': {'ros__parameters': {'mode': 'realtime', 'dt': dt, 'duration': 0.0}},
        'reference': {'ros__parameters': {'mode': 'realtime', 'publish_rate': float(rate)}},
        'tracker': {'ros__parameters': {'mode': 'realtime', 'dt': dt}}})


def node_cmd(name: str, params_file: Path, *extra: str) -> list[str]:
    return [PY, '-m', f'nonfragile_tracker.nodes.{name}', '--ros-args', '--params-file',
            str(params_file), *extra]


def run_probe(env: dict, out: Path, *, namespaces: str = '', pids=(), warmup: float = 1.0,
              duration: float = 5.0, wait: float = 30.0, no_cmd: bool = False) -> dict:
    cmd = [PY, str(HELPERS), 'probe', '--namespaces', namespaces, '--pids',
           ','.join(str(p) for p in pids), '--warmup', str(warmup), '--duration', str(duration),
           '--wait', str(wait), '--out', str(out)]
    if no_cmd:
        cmd.append('--no-cmd')
    subprocess.run(cmd, env=env, check=True, timeout=wait + warmup + duration + 60,
                   stdin=subprocess.DEVNULL, cwd=str(ROOT))
    return json.loads(out.read_text())


# ================================================================================ 1. synthesis

def worker_cold() -> None:
    """Child of the cold measurement: import, load, solve once, report."""
    t0 = time.perf_counter()
    from nonfragile_tracker.control.lmi import synthesize
    from nonfragile_tracker.control.problem import load_problem
    t1 = time.perf_counter()
    p = load_problem(CONFIG / 'paper_problem.yaml')
    r = synthesize(p, gain_bound=p.options.get('gain_bound'))
    t2 = time.perf_counter()
    print(json.dumps({'import_s': t1 - t0, 'first_solve_s': t2 - t1, 'solver_s': r.solve_time,
                      'status': r.status}))


def stacked_problem(k: int):
    """k copies of the paper's robot, block-diagonal (n = 4 k)."""
    import scipy.linalg as sla
    from nonfragile_tracker.control.problem import load_problem
    p = load_problem(CONFIG / 'paper_problem.yaml')
    bd = lambda M: sla.block_diag(*([M] * k))  # noqa: E731
    return p.replace(A=bd(p.A), B=bd(p.B), A_tau=bd(p.A_tau), E=bd(p.E), F=bd(p.F),
                     perturbations={}, name=f'paper_x{k}')


def worker_growth(n: int, solver: str, reps: int) -> None:
    """Child of the growth measurement: after a warm-up solve of the paper's problem (cvxpy's
    first-use cost), build + solve the stacked problem once, then warm re-solves."""
    import numpy as np
    from nonfragile_tracker.control import lmi, sdp
    from nonfragile_tracker.control.problem import load_problem
    p0 = load_problem(CONFIG / 'paper_problem.yaml')
    lmi.synthesize(p0, gain_bound=p0.options.get('gain_bound'), solver=solver)
    sdp.clear_cache()
    p = stacked_problem(n // 4)
    gb = p.options.get('gain_bound')
    out = {'n': n, 'solver': solver, 'first_s': None, 'first_solver_s': None,
           'warm_s': [], 'warm_solver_s': []}
    t = time.perf_counter()
    r = lmi.synthesize(p, gain_bound=gb, solver=solver)
    out['first_s'] = time.perf_counter() - t
    out['first_solver_s'] = r.solve_time
    out['norm_K'] = float(np.linalg.norm(r.K, 2))
    out['margin'] = r.margin_achieved
    print(json.dumps(out), flush=True)
    for _ in range(reps - 1):
        t = time.perf_counter()
        r = lmi.synthesize(p, gain_bound=gb, solver=solver)
        out['warm_s'].append(time.perf_counter() - t)
        out['warm_solver_s'].append(r.solve_time)
        print(json.dumps(out), flush=True)


def worker_roots(reps: int) -> None:
    """Child: rightmost_roots timing (run with OPENBLAS_NUM_THREADS=1 for the comparison)."""
    import numpy as np
    import yaml
    from nonfragile_tracker.control import delay
    from nonfragile_tracker.control.problem import load_problem
    p = load_problem(CONFIG / 'paper_problem.yaml')
    K = np.array(yaml.safe_load((CONFIG / 'paper_gains.yaml').read_text())['K_nf'], float)
    A0 = delay.closed_loop_matrix(p.A, p.B, K)
    delay.rightmost_roots(A0, p.A_tau, p.tau)
    s, _ = timeit(lambda: delay.rightmost_roots(A0, p.A_tau, p.tau), reps)
    print(json.dumps(s))


def run_worker(args: list[str], timeout: float, env: dict | None = None) -> tuple[dict | None, float, bool]:
    """Run ``run.py --worker ...``; (last JSON line, wall s, timed out)."""
    t0 = time.perf_counter()
    proc = subprocess.Popen([PY, str(Path(__file__).resolve()), '--worker', *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=str(ROOT), stdin=subprocess.DEVNULL, env=env)
    timed_out = False
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        timed_out = True
        proc.send_signal(signal.SIGINT)
        try:
            out, err = proc.communicate(timeout=5)
        except subprocess.TimeoutExpired:
            proc.kill()
            out, err = proc.communicate()
    wall = time.perf_counter() - t0
    lines = [ln for ln in (out or '').splitlines() if ln.startswith('{')]
    if not lines and not timed_out:
        log(f'worker {args} failed: {(err or "")[-500:]}')
    return (json.loads(lines[-1]) if lines else None), wall, timed_out


def bench_synthesis(cfg, table: Table, raw: dict) -> None:
    import numpy as np
    from nonfragile_tracker.control import delay, lmi, sdp
    from nonfragile_tracker.control.problem import load_problem

    p = load_problem(CONFIG / 'paper_problem.yaml')
    gb = p.options.get('gain_bound')
    res: dict = {'gain_bound': gb}
    raw['synthesis'] = res

    log('synthesis: cold (new process incl. imports)')
    cold, inner = [], []
    for _ in range(cfg.cold_reps):
        info, wall, _ = run_worker(['cold'], timeout=180)
        cold.append(wall)
        inner.append(info)
    res['cold_s'] = summary(cold)
    res['cold_inner'] = inner
    imp = summary([i['import_s'] for i in inner if i])
    first = summary([i['first_solve_s'] for i in inner if i])

    log('synthesis: first call in this process, rebuild + solve, warm re-solve')
    t = time.perf_counter()
    r0 = lmi.synthesize(p, gain_bound=gb)
    res['first_call_in_process_s'] = time.perf_counter() - t

    def rebuild():
        sdp.clear_cache()           # drop the cached DPP problem: compile again
        return lmi.synthesize(p, gain_bound=gb)
    rebuild_s, _ = timeit(rebuild, cfg.rebuild_reps)
    lmi.synthesize(p, gain_bound=gb)
    warm_s, warm_res = timeit(lambda: lmi.synthesize(p, gain_bound=gb), cfg.warm_reps)
    solver_s = summary([r.solve_time for r in warm_res])
    iters = None
    try:
        prog = next(iter(v for k, v in sdp.cached_programs() if k[0] == 'theorem1' and not k[5]))
        iters = prog.problem.solver_stats.num_iters
    except Exception:                    # noqa: BLE001 - diagnostics only
        pass
    res.update(rebuild_s=rebuild_s, warm_s=warm_s, warm_solver_s=solver_s,
               clarabel_iterations=iters, K=r0.K.tolist())

    log('synthesis: SCS')
    sdp.clear_cache()
    scs_first = []
    for _ in range(cfg.rebuild_reps):
        sdp.clear_cache()
        t = time.perf_counter()
        rs = lmi.synthesize(p, gain_bound=gb, solver='SCS')
        scs_first.append((time.perf_counter() - t, rs.solve_time))
    scs_warm, scs_res = timeit(lambda: lmi.synthesize(p, gain_bound=gb, solver='SCS'),
                               cfg.warm_reps)
    sdp.clear_cache()
    res['scs'] = {'rebuild_s': summary([a for a, _ in scs_first]),
                  'rebuild_solver_s': summary([b for _, b in scs_first]),
                  'warm_s': scs_warm, 'warm_solver_s': summary([r.solve_time for r in scs_res]),
                  'norm_K': float(np.linalg.norm(scs_res[-1].K, 2)),
                  'margin': scs_res[-1].margin_achieved}

    log('synthesis: certify_gain, certified_perturbation_scale, fragility_margin')
    K = r0.K
    cert_s, cert_r = timeit(lambda: lmi.certify_gain(p, K), cfg.cert_reps)
    cps_s, cps_r = timeit(lambda: lmi.certified_perturbation_scale(p, K), cfg.margin_reps)
    fm_s, fm_r = timeit(lambda: delay.fragility_margin(p.A, p.B, K, p.A_tau, p.tau, p.E, p.F),
                        cfg.margin_reps)
    res.update(certify_s=cert_s, certified=bool(cert_r[-1].certified),
               certified_scale_s=cps_s, certified_scale=float(cps_r[-1]),
               fragility_margin_s=fm_s, fragility_margin=float(fm_r[-1].alpha),
               fragility_evaluations=int(fm_r[-1].evaluations))

    log('synthesis: growth with n')
    growth = {}
    for n in cfg.growth_n:
        for solver in ('CLARABEL', 'SCS'):
            reps = cfg.growth_reps if n <= 16 else 1
            limit = cfg.growth_timeout if n > 16 else 300
            if n > 16:
                limit = max(30.0, min(limit, cfg.budget - elapsed() - 330))
            info, wall, to = run_worker(['growth', str(n), solver, str(reps)], timeout=limit)
            growth[f'{n}/{solver}'] = {'result': info, 'process_wall_s': wall, 'timed_out': to,
                                       'timeout_s': limit}
            log(f'  n={n} {solver}: {"timeout" if to else "done"} ({wall:.1f} s)')
    res['growth'] = growth

    # ---- table
    table.add('1.1', 'Theorem 1 cold (new process: imports + first solve)',
              res['cold_s']['median'], 's', spread(res['cold_s']) +
              f"; imports {fmt(imp['median'])} s, first solve {fmt(first['median'])} s",
              raw=res['cold_s'])
    table.add('1.2', 'first synthesize in a process (cvxpy first use)',
              res['first_call_in_process_s'], 's', 'n=1')
    table.add('1.3', 'rebuild + solve (DPP cache cleared)', rebuild_s['median'] * 1e3, 'ms',
              spread(rebuild_s, 1e3), f"x{fmt(rebuild_s['median'] / warm_s['median'])} warm")
    table.add('1.4', 'warm re-solve (cached DPP problem, CLARABEL)', warm_s['median'] * 1e3,
              'ms', spread(warm_s, 1e3), 'issue ref: 3 ms', target='warm_resolve')
    table.add('1.5', '  of which solver time (result.solve_time)', solver_s['median'] * 1e3,
              'ms', spread(solver_s, 1e3) + (f'; {iters} IPM iterations' if iters else ''),
              f"{fmt(100 * solver_s['median'] / warm_s['median'])}% of warm")
    sc = res['scs']
    table.add('1.6', 'SCS rebuild + solve (no warm start)', sc['rebuild_s']['median'] * 1e3,
              'ms', spread(sc['rebuild_s'], 1e3) +
              f"; solver {fmt(sc['rebuild_solver_s']['median'] * 1e3)} ms",
              f"x{fmt(sc['rebuild_s']['median'] / rebuild_s['median'])} CLARABEL")
    table.add('1.7', 'SCS warm re-solve (cvxpy warm-starts SCS)', sc['warm_s']['median'] * 1e3,
              'ms', spread(sc['warm_s'], 1e3) +
              f"; solver {fmt(sc['warm_solver_s']['median'] * 1e3)} ms; ||K|| "
              f"{fmt(sc['norm_K'])} vs {fmt(float(np.linalg.norm(K, 2)))}",
              f"x{fmt(sc['warm_s']['median'] / warm_s['median'])} CLARABEL")
    table.add('1.8', 'certify_gain (Theorem 1 for fixed K)', cert_s['median'] * 1e3, 'ms',
              spread(cert_s, 1e3) + f"; certified {fmt(res['certified'])}")
    table.add('1.9', 'certified_perturbation_scale (bisection)', cps_s['median'], 's',
              spread(cps_s) + f"; scale {fmt(res['certified_scale'])}",
              f"{fmt(cps_s['median'] / cert_s['median'])} certify_gain calls")
    table.add('1.10', 'delay.fragility_margin (measured)', fm_s['median'], 's',
              spread(fm_s) + f"; alpha {fmt(res['fragility_margin'])}, "
              f"{res['fragility_evaluations']} abscissa evals")
    base = {}
    for n in cfg.growth_n:
        for solver in ('CLARABEL', 'SCS'):
            g = growth[f'{n}/{solver}']
            info = g['result']
            rid = f'1.g{n}{solver[0]}'
            if info is None or not info.get('first_s'):
                table.add(rid, f'synthesize n={n} {solver}', None, 's',
                          f"> {fmt(g['timeout_s'])} s (timeout: no solve finished)"
                          if g['timed_out'] else 'failed (see JSON)')
                continue
            val = info['first_s']
            det = f"solver {fmt(info['first_solver_s'])} s"
            if info['warm_s']:
                w = summary(info['warm_s'])
                det += f"; warm re-solve {fmt(w['median'])} s ({spread(w)})"
            else:
                det += '; n=1'
            base.setdefault(solver, val)
            table.add(rid, f'synthesize n={n} ({n // 4} robots), {solver}, build + solve',
                      val, 's', det, f"x{fmt(val / base[solver])} n=4")


# ============================================================================ 2. delay loop

def _cheb(N: int):
    import numpy as np
    x = np.cos(np.pi * np.arange(N + 1) / N)
    c = np.hstack([2.0, np.ones(N - 1), 2.0]) * (-1.0) ** np.arange(N + 1)
    X = np.tile(x, (N + 1, 1)).T
    dX = X - X.T
    D = np.outer(c, 1.0 / c) / (dX + np.eye(N + 1))
    return D - np.diag(D.sum(axis=1))


def reference_roots(A0, A1, tau: float, N: int = 160, keep: int = 12):
    """Independent reference: own Chebyshev discretization of the generator at high N,
    then Newton on det T(s) (f'/f = tr(T^-1 T')) to |ds| <= 1e-15 |s|."""
    import numpy as np
    n = A0.shape[0]
    M = np.kron(_cheb(N) * (2.0 / tau), np.eye(n))
    M[:n, :] = 0.0
    M[:n, :n] = A0
    M[:n, -n:] += A1
    ev = np.linalg.eigvals(M)
    ev = ev[np.abs(ev) < 0.5 * N / tau]          # the well-resolved part of the spectrum
    ev = ev[np.argsort(-ev.real)][:keep]
    I = np.eye(n)
    out = []
    for s in ev:
        s = complex(s)
        for _ in range(100):
            E = np.exp(-s * tau)
            T = s * I - A0 - A1 * E
            dT = I + tau * E * A1
            try:
                step = 1.0 / np.trace(np.linalg.solve(T, dT))
            except np.linalg.LinAlgError:      # landed exactly on the root
                break
            s -= step
            if abs(step) <= 1e-15 * max(1.0, abs(s)):
                break
        T = s * I - A0 - A1 * np.exp(-s * tau)
        res = np.linalg.svd(T, compute_uv=False)[-1]
        if not any(abs(s - u) < 1e-9 * max(1.0, abs(s)) for u, _ in out):
            out.append((s, float(res)))
    out.sort(key=lambda t: (-t[0].real, -t[0].imag))
    return out


def bench_delay(cfg, table: Table, raw: dict) -> None:
    import numpy as np
    import yaml
    from nonfragile_tracker.control import delay
    from nonfragile_tracker.control.problem import load_problem

    p = load_problem(CONFIG / 'paper_problem.yaml')
    gains = yaml.safe_load((CONFIG / 'paper_gains.yaml').read_text())
    K = np.array(gains['K_nf'], float)
    loops = {'D=0': delay.closed_loop_matrix(p.A, p.B, K)}
    for name, D in p.perturbations.items():
        loops[name] = delay.closed_loop_matrix(p.A, p.B, K, p.E, p.F, D)
    res: dict = {'loops': {}}
    raw['delay'] = res
    log('delay loop: rightmost_roots / spectral_abscissa timing and accuracy')
    A0 = loops['D=0']
    delay.rightmost_roots(A0, p.A_tau, p.tau)         # first call (lru caches)
    rr_s, rr = timeit(lambda: delay.rightmost_roots(A0, p.A_tau, p.tau), cfg.roots_reps)
    sa_s, _ = timeit(lambda: delay.spectral_abscissa(A0, p.A_tau, p.tau), cfg.roots_reps)
    ref_s, _ = timeit(lambda: reference_roots(A0, p.A_tau, p.tau), max(1, cfg.roots_reps // 5))
    one, _, _ = run_worker(['roots', str(cfg.roots_reps)], timeout=120,
                           env=dict(os.environ, OPENBLAS_NUM_THREADS='1'))
    res['rightmost_roots_openblas1_s'] = one
    res.update(rightmost_roots_s=rr_s, spectral_abscissa_s=sa_s, reference_s=ref_s,
               N=int(rr[-1].N), converged=bool(rr[-1].converged))
    worst_abs, worst_root = 0.0, 0.0
    for name, M in loops.items():
        got = delay.rightmost_roots(M, p.A_tau, p.tau)
        ref = reference_roots(M, p.A_tau, p.tau)
        ref_abs = max(s.real for s, _ in ref)
        d_abs = abs(got.abscissa - ref_abs)
        d_roots = max(min(abs(complex(z) - s) for s, _ in ref) for z in got.roots)
        missing = [s for s, _ in ref if s.real >= got.roots[-1].real - 1e-9
                   and min(abs(complex(z) - s) for z in got.roots) > 1e-6]
        res['loops'][name] = {
            'abscissa': float(got.abscissa), 'reference_abscissa': float(ref_abs),
            'abscissa_diff': float(d_abs), 'max_root_diff': float(d_roots),
            'roots': [[z.real, z.imag] for z in map(complex, got.roots)],
            'reference_roots': [[s.real, s.imag, r] for s, r in ref[:8]],
            'missing_in_window': [[s.real, s.imag] for s in missing],
            'N': int(got.N), 'converged': bool(got.converged)}
        worst_abs = max(worst_abs, d_abs)
        worst_root = max(worst_root, d_roots)
    res['worst_abscissa_diff'] = worst_abs
    res['worst_root_diff'] = worst_root
    nmiss = sum(len(v['missing_in_window']) for v in res['loops'].values())
    table.add('2.1', 'rightmost_roots (6 roots), paper loop with K_nf', rr_s['median'] * 1e3,
              'ms', spread(rr_s, 1e3) + f"; N={res['N']}, converged {fmt(res['converged'])}",
              f"x{fmt(ref_s['median'] / rr_s['median'])} faster than ref (N=160 + Newton)")
    if one:
        table.add('2.1b', '  same, OPENBLAS_NUM_THREADS=1 (new process)', one['median'] * 1e3,
                  'ms', spread(one, 1e3),
                  f"x{fmt(rr_s['median'] / one['median'])} faster than default threads")
    table.add('2.2', 'spectral_abscissa, same loop', sa_s['median'] * 1e3, 'ms',
              spread(sa_s, 1e3) + f"; abscissa {fmt(res['loops']['D=0']['abscissa'], 6)}")
    table.add('2.3', 'abscissa error vs reference (worst of D=0, Delta_1/2)',
              worst_abs, '1/s', f"max root distance {fmt(worst_root)}; {nmiss} reference "
              'roots missing in the returned window')


# ============================================================================ 3. simulation

def bench_simulation(cfg, table: Table, raw: dict) -> None:
    from nonfragile_tracker.control.gains import read_gain_file
    from nonfragile_tracker.control.loop import PlantConfig, TrackerConfig
    from nonfragile_tracker.control.reference import circle
    from nonfragile_tracker.control.simulate import simulate_tracking

    log(f'simulation: {cfg.sim_steps} steps x {cfg.sim_reps}')
    K = read_gain_file(CONFIG / 'tracker_gains.yaml')
    pc, tc = PlantConfig(), TrackerConfig(K=K)
    simulate_tracking(pc, tc, circle(), 1000)            # warm-up
    s, runs = timeit(lambda: simulate_tracking(pc, tc, circle(), cfg.sim_steps), cfg.sim_reps)
    sim_s = cfg.sim_steps * pc.dt
    rate = summary([sim_s / w for w in s['values']])
    raw['simulation'] = {'steps': cfg.sim_steps, 'dt': pc.dt, 'wall_s': s, 'sim_per_wall': rate,
                         'steps_per_s': summary([cfg.sim_steps / w for w in s['values']])}
    table.add('3.1', f'simulate_tracking, paper scenario ({cfg.sim_steps:,} steps)',
              rate['median'], 'sim s/wall s', spread(rate) +
              f"; {fmt(cfg.sim_steps / s['median'])} steps/s",
              f"x{fmt(rate['median'])} real time; issue ref 1,500 (plain RK4)",
              target='simulation')


# ============================================================================ 4. ROS loop

_STAMP = re.compile(r'\[(\d+\.\d+)\]')
_PROGRESS = re.compile(r'progress: t = ([\d.]+) s')
_COMPLETE = re.compile(r'lockstep run complete: (\d+) steps')


def _rate_from_lines(lines: list[str], dt: float) -> float | None:
    """Steps/s between the first progress line and the 'complete' line (plant log stamps)."""
    pts = []
    for ln in lines:
        m = _STAMP.search(ln)
        if not m:
            continue
        t = float(m.group(1))
        if (g := _PROGRESS.search(ln)):
            pts.append((t, int(round(float(g.group(1)) / dt))))
        elif (g := _COMPLETE.search(ln)):
            pts.append((t, int(g.group(1))))
        elif 'peers matched' in ln:
            pts.append((t, 0))
    if len(pts) < 2:
        return None
    (t0, k0), (t1, k1) = pts[0], pts[-1]
    return (k1 - k0) / (t1 - t0) if t1 > t0 else None


def bench_lockstep(cfg, table: Table, raw: dict, domain: int) -> None:
    from nonfragile_tracker import runner
    res: dict = {'processes': [], 'composed': []}
    raw['lockstep'] = res
    env = ros_env(domain)
    log(f'lockstep, 3 processes: {cfg.ls_duration} s simulated x {cfg.ls_reps}')
    for i in range(cfg.ls_reps):
        params = runner.scenario_parameters(CONFIG / 'paper_scenario.yaml',
                                            CONFIG / 'tracker_gains.yaml',
                                            {'plant': {'ros__parameters': {
                                                'duration': float(cfg.ls_duration)}}})
        lines: list[str] = []
        with tempfile.TemporaryDirectory(prefix='nfbench_ls_') as d:
            r = runner.run_processes(params, Path(d), record=False, env=env,
                                     timeout=120.0, progress=lines.append)
        dt = params['plant']['ros__parameters']['dt']
        rate = _rate_from_lines(lines, dt)
        res['processes'].append({'steps': r.steps, 'wall_s': r.wall_time, 'codes': r.exit_codes,
                                 'in_run_steps_per_s': rate,
                                 'with_startup_steps_per_s': r.steps / r.wall_time,
                                 'log': lines[-3:]})
        log(f'  rep {i}: {fmt(rate)} steps/s in run, {fmt(r.steps / r.wall_time)} with start-up,'
            f' codes {r.exit_codes}')
    log(f'lockstep, composed: {cfg.lc_duration} s simulated x {cfg.ls_reps}')
    for i in range(cfg.ls_reps):
        t0 = time.perf_counter()
        proc = subprocess.run([PY, str(HELPERS), 'composed', '--duration', str(cfg.lc_duration),
                               '--scenario', str(CONFIG / 'paper_scenario.yaml'),
                               '--gains', str(CONFIG / 'tracker_gains.yaml')],
                              env=env, capture_output=True, text=True, timeout=300,
                              cwd=str(ROOT), stdin=subprocess.DEVNULL)
        wall = time.perf_counter() - t0
        lines = (proc.stdout + '\n' + proc.stderr).splitlines()
        info = next((json.loads(ln) for ln in lines if ln.startswith('{')), {})
        rate = _rate_from_lines(lines, 0.01)
        steps = info.get('steps', int(round(cfg.lc_duration / 0.01)))
        res['composed'].append({'steps': steps, 'process_wall_s': wall, 'info': info,
                                'in_run_steps_per_s': rate, 'rc': proc.returncode,
                                'with_startup_steps_per_s': steps / info['wall_s']
                                if info.get('wall_s') else None})
        log(f'  rep {i}: {fmt(rate)} steps/s in run (rc {proc.returncode})')
    sp = summary([r['in_run_steps_per_s'] for r in res['processes']])
    sw = summary([r['with_startup_steps_per_s'] for r in res['processes']])
    cp = summary([r['in_run_steps_per_s'] for r in res['composed']])
    cw = summary([r['with_startup_steps_per_s'] for r in res['composed']])
    res.update(processes_summary=sp, composed_summary=cp)
    table.add('4.1', f'lockstep, 3 processes ({int(cfg.ls_duration / 0.01):,} steps, '
              'run_processes)', sp['median'], 'steps/s',
              spread(sp) + f"; {fmt(sw['median'])} incl. start-up",
              f"x{fmt(sp['median'] / 2800)} bare EventsExecutor exchange (2,800)",
              target='lockstep_processes')
    table.add('4.2', f'lockstep, composed ({int(cfg.lc_duration / 0.01):,} steps, '
              'run_composed)', cp['median'], 'steps/s',
              spread(cp) + f"; {fmt(cw['median'])} incl. node start-up",
              f"x{fmt(cp['median'] / 13000)} bare exchange (13,000)",
              target='lockstep_composed')


def latency_stats(rec: dict, period: float) -> dict:
    """Tracker latency and plant deadlines from one namespace of a probe record."""
    import numpy as np
    o_src = np.asarray(rec['odom']['src'], dtype=np.int64)
    o_rcv = np.asarray(rec['odom']['rcv'], dtype=np.int64)
    o_st = np.asarray(rec['odom']['stamp'], dtype=np.int64)
    c_src = np.asarray(rec['cmd']['src'], dtype=np.int64)
    c_rcv = np.asarray(rec['cmd']['rcv'], dtype=np.int64)
    out: dict = {'odom': int(o_src.size), 'cmd': int(c_src.size)}
    if o_st.size > 1:
        iv = np.diff(np.sort(o_st)) * 1e-9
        late = iv > 1.5 * period
        out.update(interval_p50_ms=float(np.median(iv) * 1e3),
                   interval_max_ms=float(iv.max() * 1e3), late=int(late.sum()),
                   late_fraction=float(late.mean()), intervals=int(iv.size))
    if o_src.size and c_src.size:
        # each cmd_vel is paired with the last odom written before it (one command per pose):
        # latency = cmd write time - odom write time (DDS source timestamps, same host clock)
        i = np.searchsorted(o_src, c_src, side='right') - 1
        ok = i >= 0
        first = np.zeros(o_src.size, bool)
        pair = []
        for ci, oi in zip(np.flatnonzero(ok), i[ok]):
            if not first[oi]:
                first[oi] = True
                pair.append((ci, oi))
        if pair:
            ci, oi = map(np.asarray, zip(*pair))
            lat = (c_src[ci] - o_src[oi]) * 1e-6
            lat_rr = (c_rcv[ci] - o_rcv[oi]) * 1e-6
            out.update(pairs=len(pair), lat_p50_ms=float(np.percentile(lat, 50)),
                       lat_p99_ms=float(np.percentile(lat, 99)), lat_max_ms=float(lat.max()),
                       rr_p50_ms=float(np.percentile(lat_rr, 50)),
                       rr_p99_ms=float(np.percentile(lat_rr, 99)),
                       rr_max_ms=float(lat_rr.max()),
                       hop_p50_ms=float(np.median((o_rcv - o_src) * 1e-6)))
    return out


def _rt_once(kind: str, rate: float, env: dict, tmp: Path, cfg, tag: str) -> dict:
    """One real-time measurement: plant + reference + tracker (or plant + bare echo) + probe."""
    pf = write_params(tmp / f'rt_{tag}.yaml', realtime_params(rate))
    with Procs() as g:
        if kind == 'tracker':
            tr = g.start(node_cmd('tracker', pf), env, tmp / f'rt_{tag}_tracker.log')
            g.start(node_cmd('reference', pf), env, tmp / f'rt_{tag}_reference.log')
        else:
            tr = g.start([PY, str(HELPERS), 'echo'], env, tmp / f'rt_{tag}_echo.log')
        pl = g.start(node_cmd('plant', pf), env, tmp / f'rt_{tag}_plant.log')
        data = run_probe(env, tmp / f'rt_{tag}.json', pids=(tr.pid, pl.pid),
                         warmup=cfg.rt_warmup, duration=cfg.rt_window)
    st = latency_stats(data['data']['/'], 1.0 / rate)
    st.update(node_cpu=data['cpu_fraction'].get(str(tr.pid)),
              plant_cpu=data['cpu_fraction'].get(str(pl.pid)),
              probe_cpu=data['probe_cpu_fraction'], window_s=data['window_s'],
              machine_busy_cores=data.get('machine_busy_cores'))
    return st


def bench_realtime(cfg, table: Table, raw: dict, domain: int, tmp: Path) -> None:
    res: dict = {'method': (
        'probe process subscribes odom and cmd_vel (raw, SingleThreadedExecutor) and records '
        'the DDS source (write) and received timestamps of every message; each cmd_vel is '
        'paired with the last odom written before it; latency = cmd_vel write time - odom '
        'write time (plant -> tracker hop + tracker callback up to its publish); deadlines '
        'from the odom header stamps (plant timer), late = interval > 1.5 period'),
        'runs': {}}
    raw['realtime'] = res
    env = ros_env(domain)
    schedule = []
    for rate in cfg.rt_rates:
        reps = cfg.rt_reps if rate == 100 else 1
        for i in range(reps):
            schedule.append(('tracker', rate, i))
            if rate == 100:
                schedule.append(('echo', rate, i))       # interleaved: same conditions
    for kind, rate, i in schedule:
        log(f'real time {rate} Hz, {kind} rep {i}: plant + '
            f"{'reference + tracker' if kind == 'tracker' else 'bare echo node'} + probe "
            f'({cfg.rt_window} s window)')
        st = _rt_once(kind, rate, env, tmp, cfg, f'{kind}_{rate}_{i}')
        res['runs'].setdefault(f'{kind}_{rate}', []).append(st)
        log('  ' + ', '.join(f'{k} {fmt(v) if isinstance(v, float) else v}'
                             for k, v in st.items()))

    def agg(key: str, field: str) -> dict:
        return summary([r.get(field, math.nan) for r in res['runs'].get(key, [])])
    echo = {f: agg('echo_100', f) for f in ('lat_p50_ms', 'lat_p99_ms', 'lat_max_ms',
                                            'node_cpu')}
    res['echo_summary'] = echo
    for rate in cfg.rt_rates:
        key = f'tracker_{rate}'
        runs = res['runs'][key]
        p99, p50, mx = agg(key, 'lat_p99_ms'), agg(key, 'lat_p50_ms'), agg(key, 'lat_max_ms')
        cpu, rr = agg(key, 'node_cpu'), agg(key, 'rr_p99_ms')
        res[f'summary_{rate}'] = {'p99': p99, 'p50': p50, 'max': mx, 'cpu': cpu}
        ratio = ''
        if rate == 100 and echo['lat_p99_ms']['n']:
            ratio = (f"x{fmt(p99['median'] / echo['lat_p99_ms']['median'])} bare echo "
                     f"(p99 {fmt(echo['lat_p99_ms']['median'])} ms)")
        table.add(f'4.3.{rate}', f'tracker latency p99, real time {rate} Hz', p99['median'],
                  'ms', (spread(p99) + '; ' if p99['n'] > 1 else '') +
                  f"p50 {fmt(p50['median'])}, max {fmt(mx['max'])}; probe rcv->rcv p99 "
                  f"{fmt(rr['median'])}; {sum(r.get('pairs', 0) for r in runs)} pairs",
                  ratio, target='latency_p99_100hz' if rate == 100 else None)
        late = sum(r.get('late', 0) for r in runs)
        ivs = sum(r.get('intervals', 0) for r in runs)
        table.add(f'4.4.{rate}', f'  tracker CPU, missed plant deadlines, {rate} Hz',
                  100 * cpu['median'], '% of a core',
                  f"{late}/{ivs} steps late (>1.5 period), max interval "
                  f"{fmt(max(r.get('interval_max_ms', math.nan) for r in runs))} ms; plant CPU "
                  f"{fmt(100 * agg(key, 'plant_cpu')['median'])}%; machine busy "
                  f"{fmt(agg(key, 'machine_busy_cores')['median'])} of 2 cores")
    if echo['lat_p99_ms']['n']:
        table.add('4.5', 'baseline: bare echo node latency p99, 100 Hz',
                  echo['lat_p99_ms']['median'], 'ms',
                  (spread(echo['lat_p99_ms']) + '; ' if echo['lat_p99_ms']['n'] > 1 else '') +
                  f"p50 {fmt(echo['lat_p50_ms']['median'])}, max "
                  f"{fmt(echo['lat_max_ms']['max'])}; echo CPU "
                  f"{fmt(100 * echo['node_cpu']['median'])}%")


def bench_recorder(cfg, table: Table, raw: dict, domain: int, tmp: Path) -> None:
    check = subprocess.run([PY, '-c', 'import nonfragile_tracker.nodes.recorder, '
                            'nonfragile_tracker.bag.writer, rosbags.rosbag2'],
                           capture_output=True, text=True, cwd=str(ROOT))
    if check.returncode != 0:
        msg = 'recorder/bag modules not importable: ' + check.stderr.strip().splitlines()[-1]
        print(f'NOTE: skipping the recorder benchmark ({msg})', file=sys.stderr)
        table.note('4.6', 'recorder max sustained rate', msg)
        raw['recorder'] = {'skipped': msg}
        return
    from rosbags.rosbag2 import Reader
    env = ros_env(domain)
    res: dict = {'levels': []}
    raw['recorder'] = res
    best = None
    limited = False
    for rate in cfg.rec_rates:
        n = int(rate * cfg.rec_seconds)
        bag = tmp / f'bag_{rate}'
        log(f'recorder: {n} odom messages at {rate}/s')
        with Procs() as g:
            rec = g.start([PY, '-m', 'nonfragile_tracker.nodes.recorder', '--ros-args', '-p',
                           f'output:={bag}', '-p', "topics:=['odom']"], env,
                          tmp / f'rec_{rate}.log')
            pub = subprocess.run([PY, str(HELPERS), 'publish', '--topic', 'odom', '--rate',
                                  str(rate), '--count', str(n)], env=env, capture_output=True,
                                 text=True, timeout=120, cwd=str(ROOT), stdin=subprocess.DEVNULL)
            time.sleep(0.5)
            codes = g.stop(grace=20.0)
        info = next((json.loads(ln) for ln in pub.stdout.splitlines() if ln.startswith('{')), {})
        got = None
        try:
            rd = Reader(bag)
            rd.open()
            got = sum(c.msgcount for c in rd.connections if c.topic.endswith('odom'))
            rd.close()
        except Exception as exc:        # noqa: BLE001 - reported, not fatal
            info['read_error'] = str(exc)
        lvl = {'rate': rate, 'published': n, 'recorded': got, 'publisher': info,
               'recorder_exit': codes.get(rec.pid)}
        res['levels'].append(lvl)
        log(f'  recorded {got} of {n}; publisher {info}')
        achieved = info.get('achieved_rate') or 0.0
        if got is None or got < n:
            break
        best = (rate, achieved)
        if achieved < 0.9 * rate:
            limited = True
            break
        shutil.rmtree(bag, ignore_errors=True)
    res['max_sustained'] = best
    res['publisher_limited'] = limited
    last = res['levels'][-1] if res['levels'] else {}
    detail = ('; '.join(f"{lv['rate']}/s: {lv['recorded']}/{lv['published']}"
                        for lv in res['levels']))
    if limited:
        detail += '; publisher could not go faster'
    elif last and last.get('recorded') is not None and last['recorded'] < last['published']:
        detail += f"; drops from {last['rate']}/s"
    table.add('4.6', f'recorder: max rate without drops (odom, {cfg.rec_seconds:g} s/level)', float(best[1]) if best else None, 'msg/s', detail)


# ============================================================================ 5. quality

def _quality_job(job: dict) -> dict:
    """One simulation (runs in a worker process)."""
    from nonfragile_tracker.control.loop import PlantConfig, TrackerConfig
    from nonfragile_tracker.control.reference import circle, figure_eight
    from nonfragile_tracker.control.simulate import simulate_tracking
    pc = PlantConfig()
    kw = {}
    if job['comp']:
        kw = dict(delay_compensation=True, A_tau=pc.A_tau, tau=pc.tau)
    tc = TrackerConfig(K=job['K'], **kw)
    path = circle() if job['path'] == 'circle' else figure_eight(radius=0.5,
                                                                 rate=job['eight_rate'])
    run = simulate_tracking(pc, tc, path, job['steps'])
    m = run.metrics(0.01).as_dict()
    import numpy as np
    after = run.t >= (m['settling_time'] if math.isfinite(m['settling_time']) else 20.0)
    m['peak_abs_w_after'] = float(np.max(np.abs(run.cmd_w[after]))) if after.any() else math.nan
    return {**{k: v for k, v in job.items() if k != 'K'}, 'metrics': m}


def _analysis_job(job: dict) -> dict:
    import numpy as np
    from nonfragile_tracker.control.analysis import analyse_gain
    from nonfragile_tracker.control.problem import load_problem
    p = load_problem(CONFIG / 'paper_problem.yaml')
    t = time.perf_counter()
    a = analyse_gain(p, np.asarray(job['K']), name=job['name'])
    return {'name': job['name'], 'analysis': a.as_dict(), 'time_s': time.perf_counter() - t}


def bench_quality(cfg, table: Table, raw: dict) -> None:
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    import numpy as np
    import yaml
    from nonfragile_tracker.control import design
    from nonfragile_tracker.control.gains import read_gain_file
    from nonfragile_tracker.control.problem import load_problem

    p = load_problem(CONFIG / 'paper_problem.yaml')
    paper = yaml.safe_load((CONFIG / 'paper_gains.yaml').read_text())
    log('quality: max-decay-rate design at ||K|| <= 8.67')
    t = time.perf_counter()
    dec = design.at_gain_norm(design.max_decay_rate, p, 8.67)
    t_design = time.perf_counter() - t
    gains = {'K_nf (paper)': np.array(paper['K_nf'], float),
             'K_normal (paper)': np.array(paper['K_normal'], float),
             'shipped': read_gain_file(CONFIG / 'tracker_gains.yaml'),
             'max-decay': np.asarray(dec.K)}
    res: dict = {'design_s': t_design, 'decay_rate': float(dec.value),
                 'decay_solves': int(dec.solves), 'gains': {k: v.tolist() for k, v in gains.items()},
                 'steps': cfg.q_steps, 'eight_rate': cfg.eight_rate, 'runs': [], 'analysis': {}}
    raw['quality'] = res
    jobs = [{'gain': g, 'K': K.tolist(), 'comp': comp, 'path': path, 'steps': cfg.q_steps,
             'eight_rate': cfg.eight_rate}
            for path in ('circle', 'figure_eight') for g, K in gains.items()
            for comp in (False, True)]
    log(f'quality: {len(jobs)} simulations of {cfg.q_steps} steps + analyse_gain x {len(gains)}'
        ' (2 worker processes)')
    with ProcessPoolExecutor(max_workers=2, mp_context=mp.get_context('spawn')) as ex:
        fa = [ex.submit(_analysis_job, {'name': g, 'K': K.tolist()}) for g, K in gains.items()]
        runs = list(ex.map(_quality_job, jobs))
        ana = [f.result() for f in fa]
    res['runs'] = runs
    res['analysis'] = {a['name']: {**a['analysis'], 'time_s': a['time_s']} for a in ana}

    dur = cfg.q_steps * 0.01
    table.add('5.0', 'quality runs: simulated length (simulate_tracking)', dur, 's',
              f'circle r 0.5 m at 0.01 rad/s (paper), figure-eight r 0.5 m at {cfg.eight_rate} '
              'rad/s; start (0.7, 0.1, pi/2), 0.05 m/s; +comp = delay compensation')
    for a in ana:
        x = a['analysis']
        table.add(f"5.K.{list(gains).index(a['name']) + 1}", f"{a['name']}: ||K||_2",
                  x['norm'], '',
                  f"fragility margin measured {fmt(x['measured_margin'])}, certified "
                  f"{fmt(x['certified_margin'])}; Thm 1 NF cert {fmt(x['certified_nonfragile'])}"
                  f"; abscissa {fmt(x['abscissa_nominal'])}",
                  f"analyse_gain {fmt(a['time_s'])} s")
    table.add('5.D', 'max-decay design time (at_gain_norm(max_decay_rate, 8.67))', t_design, 's',
              f"decay rate {fmt(res['decay_rate'])} 1/s certified, {dec.solves} solves (inner)")
    ref = {}
    for i, r in enumerate(runs):
        m = r['metrics']
        name = (f"{'circle' if r['path'] == 'circle' else 'eight'} {r['gain']}"
                f"{' +comp' if r['comp'] else ''}")
        if r['gain'].startswith('K_nf'):
            ref[(r['path'], r['comp'])] = m['rms_error']
        base = ref.get((r['path'], r['comp']))
        settled = (f"RMS after {length(m['rms_error_settled'])}"
                   if math.isfinite(m['rms_error_settled']) else 'never stays within 1 cm')
        table.add(f'5.{i + 1}', f'{name}: enter and stay within 1 cm', m['settling_time'], 's',
                  f"final {length(m['final_error'])}, {settled}, peak |w| "
                  f"{fmt(m['peak_abs_w'])} (after {fmt(m['peak_abs_w_after'])}) rad/s",
                  f"whole-run RMS {length(m['rms_error'])}, x{fmt(m['rms_error'] / base)}"
                  " K_nf" if base else '')
    res['note'] = (f'{dur:g} s runs; circle r = 0.5 m at 0.01 rad/s; figure-eight r = 0.5 m at '
                   f'{cfg.eight_rate} rad/s')


# ============================================================================ 6. fleet

def _fleet_level(N: int, cfg, env: dict, pf: Path, remap: list, tmp: Path) -> dict:
    """N robot pairs + one shared reference + probe (odom only); deadline statistics."""
    with Procs() as g:
        g.start(node_cmd('reference', pf, '-r', '__ns:=/fleet'), env, tmp / 'fleet_ref.log')
        pids: dict[str, list[int]] = {'tracker': [], 'plant': []}
        for i in range(N):
            pids['tracker'].append(g.start(node_cmd('tracker', pf, '-r', f'__ns:=/robot{i}',
                                                    *remap), env).pid)
        for i in range(N):
            pids['plant'].append(g.start(node_cmd('plant', pf, '-r', f'__ns:=/robot{i}'),
                                         env).pid)
        data = run_probe(env, tmp / f'fleet_{N}.json',
                         namespaces=','.join(f'/robot{i}' for i in range(N)),
                         pids=pids['tracker'] + pids['plant'], warmup=cfg.fleet_warmup,
                         duration=cfg.fleet_window, wait=30 + 4 * N, no_cmd=True)
    per = {ns: latency_stats(rec, 0.01) for ns, rec in data['data'].items()}
    late = sum(s.get('late', 0) for s in per.values())
    ivs = sum(s.get('intervals', 0) for s in per.values())
    expected = N * data['window_s'] * 100.0
    received = sum(s['odom'] for s in per.values())
    frac = late / ivs if ivs else 1.0
    cpu = data['cpu_fraction']
    lvl = {'N': N, 'late': late, 'intervals': ivs, 'late_fraction': frac,
           'worst_robot_late_fraction': max((s.get('late_fraction', 1.0)
                                             for s in per.values()), default=1.0),
           'received': received, 'expected': expected,
           'missing_robots': [ns for ns, s in per.items() if s['odom'] == 0],
           'cpu_trackers': sum(cpu.get(str(p)) or 0 for p in pids['tracker']),
           'cpu_plants': sum(cpu.get(str(p)) or 0 for p in pids['plant']),
           'probe_cpu': data['probe_cpu_fraction'],
           'machine_busy_cores': data.get('machine_busy_cores'),
           'loadavg': data.get('loadavg'),
           'max_interval_ms': max((s.get('interval_max_ms', 0) for s in per.values()),
                                  default=None), 'per_robot': per}
    lvl['ok'] = frac <= 0.01 and not lvl['missing_robots'] and received >= 0.9 * expected
    return lvl


def bench_fleet(cfg, table: Table, raw: dict, domain: int, tmp: Path) -> None:
    env = ros_env(domain)
    pf = write_params(tmp / 'fleet.yaml', realtime_params(100.0))
    res: dict = {'levels': [], 'rate_hz': 100.0, 'criterion': '>1% of plant steps late by >50%'}
    raw['fleet'] = res
    remap = []
    for part in ('pose', 'twist', 'accel'):
        remap += ['-r', f'reference/{part}:=/fleet/reference/{part}']
    passed = 0
    for N in cfg.fleet_n:
        if elapsed() + 8 + 1.5 * N + cfg.fleet_warmup + cfg.fleet_window > cfg.budget:
            log(f'fleet: stopping before N={N} (time budget)')
            res['stopped'] = f'time budget before N={N}'
            break
        attempts = []
        for attempt in range(2):                 # a failed level is measured once more
            log(f'fleet: N={N} robot pairs at 100 Hz (one shared reference), attempt '
                f'{attempt + 1}')
            lvl = _fleet_level(N, cfg, env, pf, remap, tmp)
            attempts.append(lvl)
            log(f"  N={N}: late {lvl['late']}/{lvl['intervals']} "
                f"({100 * lvl['late_fraction']:.2f}%), received {lvl['received']}/"
                f"{lvl['expected']:.0f}, CPU trackers {lvl['cpu_trackers']:.2f} plants "
                f"{lvl['cpu_plants']:.2f} probe {lvl['probe_cpu']:.2f}, machine busy "
                f"{fmt(lvl['machine_busy_cores'])} cores -> {'ok' if lvl['ok'] else 'FAIL'}")
            if lvl['ok'] or elapsed() + 10 + 1.5 * N + cfg.fleet_window > cfg.budget:
                break
        best = min(attempts, key=lambda a: (not a['ok'], a['late_fraction']))
        best['attempts'] = len(attempts)
        best['other_attempts'] = [{k: v for k, v in a.items() if k != 'per_robot'}
                                  for a in attempts if a is not best]
        res['levels'].append(best)
        ok = best['ok']
        if not ok:
            break
        passed = N
    res['max_pairs_ok'] = passed
    detail = '; '.join(f"N={lv['N']}: {100 * lv['late_fraction']:.1f}% late"
                       + (f" (best of {lv['attempts']})" if lv['attempts'] > 1 else '')
                       for lv in res['levels'])
    last = res['levels'][-1] if res['levels'] else None
    tail = ''
    if last and not last['ok']:
        tail = f' (fails at N={last["N"]})'
    elif last and res.get('stopped'):
        tail = f" (no failure up to N={last['N']}; {res['stopped']})"
    elif last:
        tail = f' (no failure up to N={last["N"]}, the limit of this run)'
    table.add('6.1', 'fleet: robot pairs at 100 Hz within deadlines', passed, 'pairs',
              detail + tail + (f"; at N={last['N']}: trackers {fmt(last['cpu_trackers'])}, "
                               f"plants {fmt(last['cpu_plants'])}, machine "
                               f"{fmt(last['machine_busy_cores'])} of 2 cores busy"
                               if last else ''))


# ============================================================================ main

class Config:
    def __init__(self, quick: bool, budget: float):
        self.quick = quick
        self.budget = budget
        self.cold_reps = 1 if quick else 3
        self.rebuild_reps = 2 if quick else 5
        self.warm_reps = 10 if quick else 30
        self.cert_reps = 2 if quick else 5
        self.margin_reps = 1 if quick else 3
        self.growth_n = (4, 8) if quick else (4, 8, 16, 32)
        self.growth_reps = 2 if quick else 3
        self.growth_timeout = 180.0
        self.roots_reps = 3 if quick else 20
        self.sim_steps = 20000 if quick else 60000
        self.sim_reps = 2 if quick else 3
        self.ls_reps = 1 if quick else 3
        self.ls_duration = 15.0 if quick else 50.0
        self.lc_duration = 20.0 if quick else 100.0
        self.rt_rates = (100,) if quick else (50, 100, 500)
        self.rt_warmup = 0.5 if quick else 1.0
        self.rt_window = 1.5 if quick else 5.0
        self.rt_reps = 1 if quick else 3
        self.rec_rates = (2000, 8000) if quick else (1000, 2000, 4000, 6000, 8000, 12000,
                                                     16000)
        self.rec_seconds = 1.0 if quick else 2.0
        self.q_steps = 10000 if quick else 60000
        self.eight_rate = 0.05
        self.fleet_n = (1, 2, 4) if quick else (1, 2, 4, 8, 12, 16)
        self.fleet_warmup = 0.5 if quick else 2.0
        self.fleet_window = 1.5 if quick else 5.0


SECTIONS = ('synthesis', 'delay', 'simulation', 'lockstep', 'realtime', 'recorder', 'quality',
            'fleet')


def proc_stat() -> list[int]:
    """Aggregate CPU jiffies from /proc/stat: user nice system idle iowait irq softirq steal."""
    try:
        return [int(v) for v in Path('/proc/stat').read_text().splitlines()[0].split()[1:9]]
    except (OSError, ValueError, IndexError):
        return []


def cpu_usage(a: list[int], b: list[int]) -> dict:
    """Average busy cores and steal over the interval between two proc_stat() samples."""
    if not a or not b:
        return {}
    d = [y - x for x, y in zip(a, b)]
    total = sum(d) or 1
    n = os.cpu_count() or 1
    busy = total - d[3] - d[4]
    return {'busy_cores': busy / total * n, 'steal_cores': (d[7] if len(d) > 7 else 0) / total * n}


def machine() -> dict:
    import importlib.metadata as md
    import platform
    cpu = ''
    try:
        for ln in Path('/proc/cpuinfo').read_text().splitlines():
            if ln.startswith('model name'):
                cpu = ln.split(':', 1)[1].strip()
                break
    except OSError:
        pass
    mem = None
    try:
        for ln in Path('/proc/meminfo').read_text().splitlines():
            if ln.startswith('MemTotal'):
                mem = f"{int(ln.split()[1]) / 2 ** 20:.1f} GiB"
    except OSError:
        pass

    def ver(*names):
        for n in names:
            try:
                return md.version(n)
            except md.PackageNotFoundError:
                continue
        return None
    return {'cpu': cpu, 'cores': os.cpu_count(), 'memory': mem,
            'platform': platform.platform(), 'python': platform.python_version(),
            'numpy': ver('numpy'), 'scipy': ver('scipy'), 'cvxpy': ver('cvxpy'),
            'clarabel': ver('clarabel'), 'scs': ver('scs'),
            'rclpy': ver('ros-jazzy-rclpy', 'rclpy'), 'rosbags': ver('rosbags'),
            'rmw': os.environ.get('RMW_IMPLEMENTATION', 'rmw_fastrtps_cpp (default)'),
            'loadavg_start': os.getloadavg()}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description='nonfragile_tracker benchmarks (issue 7)')
    ap.add_argument('--quick', action='store_true', help='about 1 minute: fewer repetitions, '
                    'shorter runs, no n=32, fleet up to 4')
    ap.add_argument('--json', default=str(HERE / 'results' / 'latest.json'),
                    help='JSON output (default benchmarks/results/latest.json)')
    ap.add_argument('--only', default='', help=f'comma list of sections: {",".join(SECTIONS)}')
    ap.add_argument('--domain-id', type=int, default=None,
                    help='ROS_DOMAIN_ID for all ROS measurements (default 215 + pid %% 18)')
    ap.add_argument('--budget', type=float, default=None,
                    help='seconds the run may take (default 560, quick 100); the long tails '
                    '(n=32, fleet) are cut to fit')
    ap.add_argument('--worker', nargs='+', help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker:
        if args.worker[0] == 'cold':
            worker_cold()
        elif args.worker[0] == 'roots':
            worker_roots(int(args.worker[1]))
        elif args.worker[0] == 'growth':
            worker_growth(int(args.worker[1]), args.worker[2], int(args.worker[3]))
        return 0

    cfg = Config(args.quick, args.budget or (100.0 if args.quick else 560.0))
    only = [s for s in args.only.split(',') if s] or list(SECTIONS)
    bad = [s for s in only if s not in SECTIONS]
    if bad:
        ap.error(f'unknown section(s) {bad}; choose from {SECTIONS}')
    domain = args.domain_id if args.domain_id is not None else 215 + os.getpid() % 18
    table = Table()
    raw: dict = {}
    info = machine()
    started = datetime.now(timezone.utc).astimezone()
    log(f"{'quick' if args.quick else 'full'} run; sections {only}; ROS_DOMAIN_ID {domain}; "
        f"{info['cpu']} x{info['cores']}, load {info['loadavg_start']}")
    stat0 = proc_stat()
    tmp = Path(tempfile.mkdtemp(prefix='nfbench_'))
    failures = {}

    def handler(signum, frame):          # noqa: ARG001
        raise KeyboardInterrupt
    signal.signal(signal.SIGTERM, handler)
    try:
        steps = [('synthesis', lambda: bench_synthesis(cfg, table, raw)),
                 ('delay', lambda: bench_delay(cfg, table, raw)),
                 ('simulation', lambda: bench_simulation(cfg, table, raw)),
                 ('lockstep', lambda: bench_lockstep(cfg, table, raw, domain)),
                 ('realtime', lambda: bench_realtime(cfg, table, raw, domain, tmp)),
                 ('recorder', lambda: bench_recorder(cfg, table, raw, domain, tmp)),
                 ('quality', lambda: bench_quality(cfg, table, raw)),
                 ('fleet', lambda: bench_fleet(cfg, table, raw, domain, tmp))]
        for name, fn in steps:
            if name not in only:
                continue
            try:
                fn()
            except KeyboardInterrupt:
                raise
            except Exception as exc:     # noqa: BLE001 - one broken section must not hide the rest
                import traceback
                failures[name] = traceback.format_exc()
                log(f'section {name} FAILED: {exc!r}')
                table.note(name, f'{name} section failed', repr(exc)[:200])
    except KeyboardInterrupt:
        log('interrupted: stopping processes')
        return_code = 130
    else:
        return_code = 0
    finally:
        Procs.stop_all()
        shutil.rmtree(tmp, ignore_errors=True)

    wall = elapsed()
    info['loadavg_end'] = os.getloadavg()
    info['cpu_during_run'] = cpu_usage(stat0, proc_stat())
    text = table.render()
    print()
    print(f"nonfragile_tracker benchmarks - {started:%Y-%m-%d %H:%M %Z} - "
          f"{'quick' if args.quick else 'full'} run, {wall:.0f} s wall")
    print(f"{info['cpu']}, {info['cores']} cores, {info['memory']}; Python {info['python']}, "
          f"numpy {info['numpy']}, cvxpy {info['cvxpy']}, clarabel {info['clarabel']}, "
          f"scs {info['scs']}, rclpy {info['rclpy']}; load average "
          f"{' '.join(f'{x:.2f}' for x in info['loadavg_start'])} at start, "
          f"{' '.join(f'{x:.2f}' for x in info['loadavg_end'])} at end; machine busy "
          f"{fmt(info['cpu_during_run'].get('busy_cores'))} of {info['cores']} cores on "
          f"average (steal {fmt(info['cpu_during_run'].get('steal_cores'))})")
    print(text)
    tg = [r for r in table.rows if r['target_key']]
    print('targets: ' + ', '.join(f"{r['id']} {r['status']}" for r in tg))
    if failures:
        print(f'sections that failed: {", ".join(failures)} (tracebacks in the JSON)')
    out = Path(args.json)
    out.parent.mkdir(parents=True, exist_ok=True)

    def clean(o):
        if isinstance(o, float) and not math.isfinite(o):
            return None if math.isnan(o) else ('inf' if o > 0 else '-inf')
        if isinstance(o, dict):
            return {str(k): clean(v) for k, v in o.items()}
        if isinstance(o, (list, tuple)):
            return [clean(v) for v in o]
        if hasattr(o, 'item'):
            return clean(o.item())
        return o
    doc = {'date': started.isoformat(timespec='seconds'), 'quick': args.quick,
           'wall_s': wall, 'machine': info, 'ros_domain_id': domain, 'sections': only,
           'targets': {k: {'op': v[0], 'value': v[1], 'unit': v[2]} for k, v in TARGETS.items()},
           'table': table.rows, 'raw': raw, 'failures': failures, 'table_text': text}
    out.write_text(json.dumps(clean(doc), indent=1))
    print(f'JSON: {out}')
    return return_code


if __name__ == '__main__':
    sys.exit(main())
