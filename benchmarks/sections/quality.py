"""Benchmark section: 5. Control quality: long simulated runs and the analysis of each gain.

Run through ``benchmarks/run.py --only quality``; helpers come from ``harness``.
"""
from __future__ import annotations

import math
import time

from harness import (
    CONFIG,
    Table,
    fmt,
    length,
    log,
)

# ============================================================================ 5. quality

def _quality_job(job: dict) -> dict:
    """One simulation (runs in a worker process)."""
    from nonfragile_tracker.control.simulation.tracker import TrackerConfig
    from nonfragile_tracker.control.simulation.reference import circle, figure_eight
    from nonfragile_tracker.control.simulation.simulate import simulate_tracking
    from nonfragile_tracker.interface.scenario import paper_plant_config
    pc = paper_plant_config()
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
    from nonfragile_tracker.control.synthesis.analysis import analyse_gain
    from nonfragile_tracker.control.synthesis.problem import load_problem
    p = load_problem(CONFIG / 'paper_problem.yaml')
    t = time.perf_counter()
    a = analyse_gain(p, np.asarray(job['K']), name=job['name'])
    return {'name': job['name'], 'analysis': a.as_dict(), 'time_s': time.perf_counter() - t}


def bench_quality(cfg, table: Table, raw: dict) -> None:
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    import numpy as np
    import yaml
    from nonfragile_tracker.control.synthesis import design
    from nonfragile_tracker.control.simulation.gains import read_gain_file
    from nonfragile_tracker.control.synthesis.problem import load_problem

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
