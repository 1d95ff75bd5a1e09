"""Benchmark section 1, synthesis: cold start, warm re-solves, certificates, margins, growth.

Run through ``benchmarks/run.py --only synthesis``; helpers come from ``harness``.
"""
from __future__ import annotations

import json
import time

from harness import (
    CONFIG,
    Table,
    elapsed,
    fmt,
    log,
    run_worker,
    spread,
    summary,
    timeit,
)

# ================================================================================ 1. synthesis

def worker_cold() -> None:
    """Child of the cold measurement: import, load, solve once, report."""
    t0 = time.perf_counter()
    from nonfragile_tracker.control.synthesis.lmi import synthesize
    from nonfragile_tracker.control.synthesis.problem import load_problem
    t1 = time.perf_counter()
    p = load_problem(CONFIG / 'paper_problem.yaml')
    r = synthesize(p, gain_bound=p.options.get('gain_bound'))
    t2 = time.perf_counter()
    print(json.dumps({'import_s': t1 - t0, 'first_solve_s': t2 - t1, 'solver_s': r.solve_time,
                      'status': r.status}))


def stacked_problem(k: int):
    """k copies of the paper's robot, block-diagonal (n = 4 k)."""
    import scipy.linalg as sla
    from nonfragile_tracker.control.synthesis.problem import load_problem
    p = load_problem(CONFIG / 'paper_problem.yaml')
    bd = lambda M: sla.block_diag(*([M] * k))  # noqa: E731
    return p.replace(A=bd(p.A), B=bd(p.B), A_tau=bd(p.A_tau), E=bd(p.E), F=bd(p.F),
                     perturbations={}, name=f'paper_x{k}')


def worker_growth(n: int, solver: str, reps: int) -> None:
    """Child of the growth measurement: after a warm-up solve of the paper's problem (cvxpy's
    first-use cost), build + solve the stacked problem once, then warm re-solves."""
    import numpy as np
    from nonfragile_tracker.control.synthesis import lmi, sdp
    from nonfragile_tracker.control.synthesis.problem import load_problem
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


def bench_synthesis(cfg, table: Table, raw: dict) -> None:
    import numpy as np
    from nonfragile_tracker.control.synthesis import delay, lmi, sdp
    from nonfragile_tracker.control.synthesis.problem import load_problem

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
