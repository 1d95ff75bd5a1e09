#!/usr/bin/env python3
"""Speed, cost and control-quality benchmarks of nonfragile_tracker (issues 7 and 15).

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
import resource
import shutil
import time
import signal
import sys
import tempfile
from datetime import datetime, timezone
from pathlib import Path

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))

from harness import (TARGETS, Config, Procs, Table, cpu_usage, elapsed, fmt, log,  # noqa: E402
                     machine, proc_stat)
from sections.batch_study import bench_batch, worker_batch  # noqa: E402
from sections.delay import bench_delay, worker_roots  # noqa: E402
from sections.delay_tdcpy import bench_tdcpy, worker_tdcpy  # noqa: E402
from sections.design import bench_design, worker_sweep  # noqa: E402
from sections.fleet import bench_fleet  # noqa: E402
from sections.identify import bench_identify  # noqa: E402
from sections.lockstep import bench_lockstep  # noqa: E402
from sections.peers import bench_peers  # noqa: E402
from sections.quality import bench_quality  # noqa: E402
from sections.realtime import bench_realtime  # noqa: E402
from sections.recorder import bench_recorder  # noqa: E402
from sections.retime import bench_retime  # noqa: E402
from sections.scaling import bench_scaling  # noqa: E402
from sections.simulation import bench_simulation  # noqa: E402
from sections.stop import bench_stop  # noqa: E402
from sections.synthesis import bench_synthesis, worker_cold, worker_growth  # noqa: E402

SECTIONS = ('synthesis', 'scaling', 'delay', 'tdcpy', 'simulation', 'batch', 'lockstep',
            'realtime', 'recorder', 'quality', 'identify', 'fleet', 'design', 'retime',
            'stop', 'peers')


def cpu_seconds() -> float:
    """CPU time (user + system) of this process and of its waited-for children."""
    me = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description='nonfragile_tracker benchmarks (issues 7 and 15)')
    ap.add_argument('--quick', action='store_true', help='about 2 minutes: fewer repetitions, '
                    'shorter runs, no n=32, fleet up to 4')
    ap.add_argument('--json', default=str(HERE / 'results' / 'latest.json'),
                    help='JSON output (default benchmarks/results/latest.json)')
    ap.add_argument('--only', default='', help=f'comma list of sections: {",".join(SECTIONS)}')
    ap.add_argument('--domain-id', type=int, default=None,
                    help='ROS_DOMAIN_ID for all ROS measurements (default 215 + pid %% 18)')
    ap.add_argument('--budget', type=float, default=None,
                    help='seconds the run may take (default 560, quick 120); the long tails '
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
        elif args.worker[0] == 'batch':
            worker_batch(args.worker[1] == '1', int(args.worker[2]))
        elif args.worker[0] == 'tdcpy':
            worker_tdcpy(int(args.worker[1]))
        elif args.worker[0] == 'sweep':
            worker_sweep(args.worker[1], int(args.worker[2]))
        return 0

    cfg = Config(args.quick, args.budget or (120.0 if args.quick else 560.0))
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
    times: dict = {}

    def handler(signum, frame):          # noqa: ARG001
        raise KeyboardInterrupt
    signal.signal(signal.SIGTERM, handler)
    try:
        steps = [('synthesis', lambda: bench_synthesis(cfg, table, raw)),
                 ('scaling', lambda: bench_scaling(cfg, table, raw)),
                 ('delay', lambda: bench_delay(cfg, table, raw)),
                 ('tdcpy', lambda: bench_tdcpy(cfg, table, raw)),
                 ('simulation', lambda: bench_simulation(cfg, table, raw)),
                 ('batch', lambda: bench_batch(cfg, table, raw)),
                 ('lockstep', lambda: bench_lockstep(cfg, table, raw, domain)),
                 ('realtime', lambda: bench_realtime(cfg, table, raw, domain, tmp)),
                 ('recorder', lambda: bench_recorder(cfg, table, raw, domain, tmp)),
                 ('quality', lambda: bench_quality(cfg, table, raw)),
                 ('identify', lambda: bench_identify(cfg, table, raw)),
                 ('fleet', lambda: bench_fleet(cfg, table, raw, domain, tmp)),
                 ('design', lambda: bench_design(cfg, table, raw)),
                 ('retime', lambda: bench_retime(cfg, table, raw)),
                 ('stop', lambda: bench_stop(cfg, table, raw, domain, tmp)),
                 ('peers', lambda: bench_peers(cfg, table, raw))]
        for name, fn in steps:
            if name not in only:
                continue
            w0, c0 = time.monotonic(), cpu_seconds()
            try:
                fn()
            except KeyboardInterrupt:
                raise
            except Exception as exc:     # noqa: BLE001 - one broken section must not hide the rest
                import traceback
                failures[name] = traceback.format_exc()
                log(f'section {name} FAILED: {exc!r}')
                table.note(name, f'{name} section failed', repr(exc)[:200])
            finally:
                times[name] = {'wall_s': time.monotonic() - w0, 'cpu_s': cpu_seconds() - c0}
                log(f"section {name}: {times[name]['wall_s']:.0f} s wall, "
                    f"{times[name]['cpu_s']:.0f} s CPU")
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
    print('section times (wall / CPU of this process and its children, s): ' + ', '.join(
        f"{k} {v['wall_s']:.0f} / {v['cpu_s']:.0f}" for k, v in times.items()))
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
           'wall_s': wall, 'section_times': times, 'machine': info, 'ros_domain_id': domain,
           'sections': only,
           'targets': {k: {'op': v[0], 'value': v[1], 'unit': v[2]} for k, v in TARGETS.items()},
           'table': table.rows, 'raw': raw, 'failures': failures, 'table_text': text}
    out.write_text(json.dumps(clean(doc), indent=1))
    print(f'JSON: {out}')
    return return_code

if __name__ == '__main__':
    sys.exit(main())
