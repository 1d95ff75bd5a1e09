"""Benchmark section: 7. Identification on what real bases give (issue 22, item 4).

Run through ``benchmarks/run.py --only identify`` (or standalone:
``.venv/bin/python benchmarks/sections/identify.py [--quick]``).  For each case of
``config/identify_cases.yaml`` (recorded in process by ``test/recordings.py``, 30 s,
seeds 1..3; quick: seed 1) the truth, today's ``identify`` (the code of the session
start, commit d11fc49, loaded from git) and the new one side by side: latency (for the
jitter case: the range), lags, and MET/MISSED for the issue's target - latency within one
plant step (10 ms) of the truth (jitter: the reported range contains [L, L + 30 ms]
within one step) and lags within 20 %, or a refusal naming the cause.  Also the CPU time
of one identification (a target only in the sense of the issue: "reasonable").
"""
from __future__ import annotations

import importlib.util
import math
import subprocess
import sys
import tempfile
import time
import types
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
if str(HERE.parent) not in sys.path:
    sys.path.insert(0, str(HERE.parent))
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
if str(ROOT / 'test') not in sys.path:
    sys.path.insert(0, str(ROOT / 'test'))     # recordings.py, the synthetic recordings

from harness import Table, log  # noqa: E402

BASELINE = 'd11fc49'
STEP = 0.01


def _old_identify() -> types.ModuleType | None:
    """control/identify.py (today control/identification/identify.py) as of the session start
    (git show of its path then), or None without git."""
    try:
        src = subprocess.run(['git', '-C', str(ROOT), 'show',
                              f'{BASELINE}:nonfragile_tracker/control/identify.py'],
                             capture_output=True, text=True, check=True, timeout=30).stdout
    except (OSError, subprocess.SubprocessError):
        return None
    src = src.replace('from ..errors import', 'from nonfragile_tracker.errors import')
    path = Path(tempfile.mkdtemp(prefix='nf_old_identify_')) / 'old_identify.py'
    path.write_text(src)
    spec = importlib.util.spec_from_file_location('old_identify', path)
    if spec is None or spec.loader is None:
        return None
    mod = importlib.util.module_from_spec(spec)
    sys.modules['old_identify'] = mod            # dataclasses look their module up
    spec.loader.exec_module(mod)
    return mod


def _run(identify, rec) -> dict:
    t0 = time.process_time()
    try:
        res = identify(rec.commands, rec.odometry)
    except Exception as exc:           # noqa: BLE001 - a refusal is a result here
        return {'error': f'{type(exc).__name__}: {exc}'[:160],
                'cpu_s': time.process_time() - t0}
    rng = getattr(res, 'latency_range_s', (res.latency_low_s, res.latency_high_s))
    return {'L': res.latency_s, 'lo': res.latency_low_s, 'hi': res.latency_high_s,
            'range': list(rng), 'tau_v': res.tau_v_s, 'tau_w': res.tau_w_s,
            'a_v': getattr(res, 'max_linear_accel', math.nan),
            'a_w': getattr(res, 'max_angular_accel', math.nan),
            'notes': len(res.notes), 'cpu_s': time.process_time() - t0}


def _met(r: dict, truth: dict, jitter: float) -> bool:
    if 'error' in r:
        return False        # no refusal is expected on these recordings
    lags = (abs(r['tau_v'] - truth['tau_v']) < 0.2 * truth['tau_v']
            and abs(r['tau_w'] - truth['tau_w']) < 0.2 * truth['tau_w'])
    if jitter:
        lo, hi = r['range']
        return lags and lo <= truth['L'] + STEP and hi >= truth['L'] + jitter - STEP
    return lags and abs(r['L'] - truth['L']) <= STEP


def _fmt(r: dict, jitter: float) -> str:
    if 'error' in r:
        return 'refused: ' + r['error']
    lat = (f"range [{r['range'][0]:.3f}, {r['range'][1]:.3f}]" if jitter
           else f"L {r['L']:.3f} [{r['lo']:.3f}, {r['hi']:.3f}]")
    lim = (f", a {r['a_v']:.2f}/{r['a_w']:.2f}" if math.isfinite(r['a_v']) else '')
    return f"{lat}, tau {r['tau_v']:.3f}/{r['tau_w']:.3f}{lim}"


def bench_identify(cfg, table: Table, raw: dict) -> None:
    """Rows 7.x: each case of config/identify_cases.yaml, today's identify and the new."""
    import numpy as np
    from nonfragile_tracker.control.identification.identify import identify_latency
    from recordings import load_cases, record_case
    cases = load_cases(ROOT / 'config' / 'identify_cases.yaml')
    old = _old_identify()
    if old is None:
        log('identify: git history not available; today\'s column is n/a')
    seeds = (1,) if cfg.quick else (1, 2, 3)
    out = raw.setdefault('identify', {})
    for k, (name, spec) in enumerate(cases.items(), 1):
        p = spec['plant']
        truth = {'L': p['cmd_latency'], 'tau_v': p['lag_v'], 'tau_w': p['lag_w']}
        jitter = float(p.get('cmd_latency_jitter', 0.0))
        rows = {'new': [], 'old': []}
        for seed in seeds:
            rec = record_case(spec, seed=seed, duration=30.0)
            rows['new'].append(_run(identify_latency, rec))
            if old is not None:
                rows['old'].append(_run(old.identify_latency, rec))
            log(f'identify {name} seed {seed}: new {_fmt(rows["new"][-1], jitter)}; '
                f'today {_fmt(rows["old"][-1], jitter) if rows["old"] else "n/a"}')
        out[name] = {'truth': truth, 'jitter': jitter, **rows}
        tr = (f"truth L {truth['L']:g}" + (f"..{truth['L'] + jitter:g}" if jitter else '')
              + f" s, tau {truth['tau_v']:g}/{truth['tau_w']:g} s")
        for who, label in (('old', f'today ({BASELINE})'), ('new', 'new')):
            rs = rows[who]
            if not rs:
                table.note(f'7.{k}{who[0]}', f'identify {name} {label}', 'git not available')
                continue
            met = [_met(r, truth, jitter) for r in rs]
            err = [abs(r['L'] - truth['L']) / STEP for r in rs if 'error' not in r]
            table.add(f'7.{k}{who[0]}', f'identify ({name}) {spec.get("title", "")}: {label}',
                      float(np.median(err)) if err else None, 'steps |L err|',
                      detail=f'{tr}; got {_fmt(rs[0], jitter)}; met {sum(met)}/{len(met)}',
                      raw=rs, target='identify_case', check=float(sum(met) == len(met)))
        cpu = [r['cpu_s'] for r in rows['new']]
        cpu_old = [r['cpu_s'] for r in rows['old']]
        table.add(f'7.{k}t', f'identify ({name}) CPU time, new', float(np.median(cpu)), 's',
                  detail=f'min-max {min(cpu):.2f}-{max(cpu):.2f}',
                  ratio=(f'today {np.median(cpu_old):.2f} s' if cpu_old else ''))


if __name__ == '__main__':
    import argparse
    import json
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--quick', action='store_true')
    ap.add_argument('--json')
    a = ap.parse_args()
    from harness import Config
    t = Table()
    r: dict = {}
    bench_identify(Config(a.quick, 600.0), t, r)
    print(t.render())
    if a.json:
        Path(a.json).write_text(json.dumps(r, indent=1, default=str))
