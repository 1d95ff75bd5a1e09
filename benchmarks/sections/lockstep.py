"""Benchmark section: 4. ROS loop in lockstep: steps/s with one process per node and composed.

Run through ``benchmarks/run.py --only lockstep``; helpers come from ``harness``.
"""
from __future__ import annotations

import json
import os
import re
import resource
import subprocess
import tempfile
import time
from pathlib import Path

from harness import (
    CONFIG,
    HELPERS,
    PY,
    ROOT,
    Table,
    fmt,
    log,
    ros_env,
    spread,
    summary,
)

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


def _children_cpu() -> float:
    """utime + stime (s) of the reaped child processes so far (the nodes, the helper)."""
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _processes_run(cfg, env, duration: float, record: bool, record_all: bool = False) -> dict:
    """One lockstep run with one process per node: in-run steps/s, wall, CPU of the nodes."""
    from nonfragile_tracker.workflows import runner
    params = runner.scenario_parameters(CONFIG / 'paper_scenario.yaml',
                                        CONFIG / 'tracker_gains.yaml',
                                        {'plant': {'ros__parameters': {
                                            'duration': float(duration)}}})
    lines: list[str] = []
    cpu0 = _children_cpu()
    with tempfile.TemporaryDirectory(prefix='nfbench_ls_') as d:
        r = runner.run_processes(params, Path(d), record=record, env=env,
                                 timeout=120.0, progress=lines.append, record_all=record_all)
        counts = None
        if record and r.bag is not None and r.bag.exists():
            from nonfragile_tracker.bag.reader import read_bag
            counts = read_bag(r.bag, strict=False).counts
    cpu = _children_cpu() - cpu0
    dt = params['plant']['ros__parameters']['dt']
    return {'steps': r.steps, 'wall_s': r.wall_time, 'codes': r.exit_codes,
            'in_run_steps_per_s': _rate_from_lines(lines, dt),
            'with_startup_steps_per_s': r.steps / r.wall_time, 'cpu_s': cpu,
            'counts': counts, 'load': os.getloadavg()[0], 'log': lines[-3:]}


def _composed_run(cfg, env, duration: float) -> dict:
    cpu0 = _children_cpu()
    t0 = time.perf_counter()
    proc = subprocess.run([PY, str(HELPERS), 'composed', '--duration', str(duration),
                           '--scenario', str(CONFIG / 'paper_scenario.yaml'),
                           '--gains', str(CONFIG / 'tracker_gains.yaml')],
                          env=env, capture_output=True, text=True, timeout=300,
                          cwd=str(ROOT), stdin=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    cpu = _children_cpu() - cpu0
    lines = (proc.stdout + '\n' + proc.stderr).splitlines()
    info = next((json.loads(ln) for ln in lines if ln.startswith('{')), {})
    steps = info.get('steps', int(round(duration / 0.01)))
    return {'steps': steps, 'process_wall_s': wall, 'info': info,
            'in_run_steps_per_s': _rate_from_lines(lines, 0.01), 'rc': proc.returncode,
            'with_startup_steps_per_s': steps / info['wall_s'] if info.get('wall_s') else None,
            'cpu_s': cpu, 'load': os.getloadavg()[0]}


def _cpu_per_step(runs: list[dict], startup: dict) -> float | None:
    """Median CPU time per step (us) of the runs, start-up CPU (a 5-step run) taken off."""
    vals = [(r['cpu_s'] - startup['cpu_s']) / (r['steps'] - startup['steps']) * 1e6
            for r in runs if r['steps'] > startup['steps']]
    return summary(vals)['median'] if vals else None


def bench_lockstep(cfg, table: Table, raw: dict, domain: int) -> None:
    res: dict = {'processes': [], 'recorded': [], 'recorded_full': [], 'composed': []}
    raw['lockstep'] = res
    env = ros_env(domain)
    # CPU time per step: the processes' utime + stime over the run, less that of a 5-step
    # run (imports, discovery, the trajectory): less load-sensitive than steps/s
    startup = {'processes': _processes_run(cfg, env, 0.05, False),
               'recorded': _processes_run(cfg, env, 0.05, True),
               'recorded_full': _processes_run(cfg, env, 0.05, True, True),
               'composed': _composed_run(cfg, env, 0.05)}
    res['startup'] = startup
    for key, record, full in (('processes', False, False), ('recorded', True, False),
                              ('recorded_full', True, True)):
        what = (' + recorder (every topic)' if full else ' + recorder (lean)') if record else ''
        log(f'lockstep, 3 processes{what}: {cfg.ls_duration} s simulated x {cfg.ls_reps}')
        for i in range(cfg.ls_reps):
            r = _processes_run(cfg, env, cfg.ls_duration, record, full)
            res[key].append(r)
            log(f'  rep {i}: {fmt(r["in_run_steps_per_s"])} steps/s in run, '
                f'{fmt(r["with_startup_steps_per_s"])} with start-up, CPU {fmt(r["cpu_s"])} s, '
                f'load {r["load"]:.2f}, codes {r["codes"]}'
                + (f', bag counts {r["counts"]}' if record else ''))
    log(f'lockstep, composed: {cfg.lc_duration} s simulated x {cfg.ls_reps}')
    for i in range(cfg.ls_reps):
        r = _composed_run(cfg, env, cfg.lc_duration)
        res['composed'].append(r)
        log(f'  rep {i}: {fmt(r["in_run_steps_per_s"])} steps/s in run (rc {r["rc"]}), '
            f'load {r["load"]:.2f}')
    out = {}
    for key in ('processes', 'recorded', 'recorded_full', 'composed'):
        out[key] = (summary([r['in_run_steps_per_s'] for r in res[key]]),
                    summary([r['with_startup_steps_per_s'] for r in res[key]]),
                    _cpu_per_step(res[key], startup[key]),
                    summary([r['load'] for r in res[key]])['median'])
    res.update(processes_summary=out['processes'][0], recorded_summary=out['recorded'][0],
               recorded_full_summary=out['recorded_full'][0],
               composed_summary=out['composed'][0])

    def detail(key: str, startup_what: str) -> str:
        s, w, cpu, load = out[key]
        return (spread(s) + f"; {fmt(w['median'])} incl. {startup_what}; CPU {fmt(cpu)} us/step"
                f"; load {fmt(load)}")

    table.add('4.1', f'lockstep, 3 processes ({int(cfg.ls_duration / 0.01):,} steps, '
              'run_processes)', out['processes'][0]['median'], 'steps/s',
              detail('processes', 'start-up'),
              f"x{fmt(out['processes'][0]['median'] / 2800)} bare EventsExecutor exchange "
              '(2,800)')
    unrec = max(out['processes'][0]['median'], 1e-9)
    table.add('4.1r', f'lockstep, 3 processes + recorder ({int(cfg.ls_duration / 0.01):,} '
              'steps, run_processes, lean recording (default): odom, cmd_vel, run_done, '
              'trajectory messages)', out['recorded'][0]['median'],
              'steps/s', detail('recorded', 'start-up'),
              f"x{fmt(out['recorded'][0]['median'] / unrec)} unrecorded, x"
              f"{fmt(out['recorded'][0]['median'] / max(out['recorded_full'][0]['median'], 1e-9))}"
              ' full recording', target='lockstep_processes')
    table.add('4.1f', f'lockstep, 3 processes + recorder ({int(cfg.ls_duration / 0.01):,} '
              'steps, run_processes, --record-all: every topic incl. /clock, pose, reference '
              'samples)', out['recorded_full'][0]['median'],
              'steps/s', detail('recorded_full', 'start-up'),
              f"x{fmt(out['recorded_full'][0]['median'] / unrec)} unrecorded")
    table.add('4.2', f'lockstep, composed ({int(cfg.lc_duration / 0.01):,} steps, '
              'run_composed)', out['composed'][0]['median'], 'steps/s',
              detail('composed', 'node start-up'),
              f"x{fmt(out['composed'][0]['median'] / 13000)} bare exchange (13,000)",
              target='lockstep_composed')
