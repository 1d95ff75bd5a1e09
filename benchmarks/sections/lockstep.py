"""Benchmark section: 4. ROS loop in lockstep: steps/s with one process per node and composed.

Run through ``benchmarks/run.py --only lockstep``; helpers come from ``harness``.
"""
from __future__ import annotations

import json
import re
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
