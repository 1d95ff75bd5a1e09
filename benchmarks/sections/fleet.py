"""Benchmark section: 6. Fleet: N namespaced robots on one machine, latency and CPU per robot.

Run through ``benchmarks/run.py --only fleet``; helpers come from ``harness``.
"""
from __future__ import annotations

from pathlib import Path

from harness import (
    Procs,
    Table,
    elapsed,
    fmt,
    log,
    node_cmd,
    realtime_params,
    ros_env,
    run_probe,
    write_params,
)
from sections.realtime import latency_stats

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
    if not res['levels']:
        table.note('6.1', 'fleet: robot pairs at 100 Hz within deadlines',
                   f"not measured: {res.get('stopped', '?')} (--budget S gives it more)")
        return
    table.add('6.1', 'fleet: robot pairs at 100 Hz within deadlines', passed, 'pairs',
              detail + tail + (f"; at N={last['N']}: trackers {fmt(last['cpu_trackers'])}, "
                               f"plants {fmt(last['cpu_plants'])}, machine "
                               f"{fmt(last['machine_busy_cores'])} of 2 cores busy"
                               if last else ''))
