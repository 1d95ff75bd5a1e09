"""Benchmark section 13, nodes that start at once and stop at once (issue 30, item 4).

Run through ``benchmarks/run.py --only stop``, or standalone:
``.venv/bin/python benchmarks/sections/stop.py [--quick] [--json F]``.  Today's code (the
branch's base commit, ``BENCH_STOP_BASELINE_REF``, extracted with ``git archive`` and run
from its own directory) side by side with the working tree's.

13.1.k  start-up of the reference node for a horizon of 60, 600, 3600 s (k = 1, 2, 3): the console
        entry's process (``python -m nonfragile_tracker.nodes.entry reference``, as
        ``ros2 launch`` starts it) with the figure eight of ``config/latency_scenario.yaml``
        (r = 1 m, 0.2 rad/s: 801, 8,001 and 48,001 knots), from the process start to its
        ``started;`` line (and the CPU time it had used then); today and now alternated,
        median of 3 (quick: 1).
        Target (3600 s, now): < 1 s.
13.2    Ctrl-C under ``ros2 launch``: the four nodes of ``tracking.launch.py record:=true``
        (lockstep, that scenario, a 600 s run, the reference's default horizon of an hour)
        as launch starts them, the terminal's SIGINT to the group at a random moment of the
        first 8 s after the launch, launch's own SIGINT to each node right after, and
        launch's escalation (SIGTERM 5 s after, SIGKILL 5 s later); the figure is the number
        of tries in which every node ended within 1 s (20 tries, quick 5; the same moments
        for today and now).  Target: all of them.
"""
from __future__ import annotations

import argparse
import json
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

if __name__ == '__main__':
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from harness import CONFIG, PY, ROOT, Table, baseline_tree, fmt, log, ros_env, spread, summary  # noqa: E402

#: Today's code: the base of the branch that made issue 30's item 4.
BASELINE_REF = os.environ.get('BENCH_STOP_BASELINE_REF', '0cce4da')
#: Horizons (s) of 13.1: the issue's 60 s, 600 s and one-hour scenarios.
HORIZONS = (60.0, 600.0, 3600.0)
#: ``ros2 launch``'s escalation: SIGTERM this long after SIGINT, SIGKILL as long after.
LAUNCH_TIMEOUT = 5.0
STOP_TARGET = 1.0
STARTUP_TARGET = 1.0
NODES = ('recorder', 'tracker', 'reference', 'plant')




def _env(domain: int, code: Path) -> dict:
    env = ros_env(domain)
    env['PYTHONPATH'] = str(code) + os.pathsep + env['PYTHONPATH']
    return env


def _entry(name: str, *args: str) -> list[str]:
    return [PY, '-m', 'nonfragile_tracker.nodes.entry', name, '--ros-args', *args]


def _stop(p: subprocess.Popen) -> None:
    if p.poll() is None:
        p.send_signal(signal.SIGINT)
        try:
            p.wait(10)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()


def _cpu(pid: int) -> float:
    """CPU time (user + system, s) of a process so far."""
    fields = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def reference_startup(code: Path, horizon: float, domain: int, log_path: Path
                      ) -> tuple[float, float]:
    """Seconds from the start of a reference process to its ``started;`` line, and the
    CPU time it had used then (less sensitive to the machine's load)."""
    params = ['-p', 'path:=figure_eight', '-p', 'radius:=1.0', '-p', 'rate:=0.2',
              '-p', f'horizon:={horizon}']
    with open(log_path, 'w') as out:
        t0 = time.monotonic()
        p = subprocess.Popen(_entry('reference', *params), cwd=code, env=_env(domain, code),
                             stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
    try:
        while 'started;' not in log_path.read_text():
            if p.poll() is not None or time.monotonic() - t0 > 120:
                raise RuntimeError(f'reference did not start: {log_path.read_text()[-500:]}')
            time.sleep(0.002)
        return time.monotonic() - t0, _cpu(p.pid)
    finally:
        _stop(p)


def _catches_sigterm(pid: int) -> bool:
    try:
        text = Path(f'/proc/{pid}/status').read_text()
    except OSError:
        return True                                # gone: nothing to wait for
    for line in text.splitlines():
        if line.startswith('SigCgt:'):
            return bool(int(line.split()[1], 16) >> (signal.SIGTERM - 1) & 1)
    return False


def launch_stop(code: Path, run_dir: Path, domain: int, moment: float, seed: int) -> dict:
    """One Ctrl-C under an emulated ``ros2 launch`` (see 13.2); exit times per node (s)."""
    from nonfragile_tracker.workflows.runner import (lockstep_handshake, scenario_parameters,
                                           write_parameter_file)
    rng = random.Random(seed)
    hand = lockstep_handshake(record=True)
    ov = {n: {'ros__parameters': {'mode': 'lockstep', **hand[n]}}
          for n in ('plant', 'tracker', 'reference')}
    ov['plant']['ros__parameters']['duration'] = 600.0
    params = write_parameter_file(scenario_parameters(
        CONFIG / 'latency_scenario.yaml', CONFIG / 'tracker_gains.yaml', ov),
        run_dir / 'params.yaml')
    extra = {'recorder': ['-p', f'output:={run_dir / "bag"}', '-p', 'use_sim_time:=true',
                          '-p', 'lockstep_gate:=true']}
    env = _env(domain, code)
    procs: dict[str, subprocess.Popen] = {}
    pgid = 0
    t_launch = time.monotonic()
    for name in NODES:
        with open(run_dir / f'{name}.log', 'w') as out:
            p = subprocess.Popen(_entry(name, '--params-file', str(params),
                                        *extra.get(name, [])),
                                 cwd=code, env=env, stdout=out, stderr=subprocess.STDOUT,
                                 stdin=subprocess.DEVNULL, process_group=pgid)
        procs[name] = p
        pgid = pgid or p.pid
    exits: dict[str, float] = {}
    escalated: list[str] = []
    try:
        while time.monotonic() < t_launch + moment or \
                not all(_catches_sigterm(p.pid) for p in procs.values()):
            time.sleep(0.001)
        t0 = time.monotonic()
        os.killpg(pgid, signal.SIGINT)                 # the terminal
        time.sleep(rng.uniform(0.0, 0.05))
        for p in procs.values():                       # launch forwards it
            if p.poll() is None:
                p.send_signal(signal.SIGINT)
        while len(exits) < len(procs) and time.monotonic() - t0 < 2 * LAUNCH_TIMEOUT:
            now = time.monotonic() - t0
            for name, p in procs.items():
                if name not in exits and p.poll() is not None:
                    exits[name] = now
                elif name not in exits and name not in escalated and now > LAUNCH_TIMEOUT:
                    escalated.append(name)
                    p.send_signal(signal.SIGTERM)
            time.sleep(0.002)
    finally:
        for p in procs.values():
            if p.poll() is None:
                p.kill()
                p.wait()
    return {'moment': t0 - t_launch, 'exit': exits, 'escalated': escalated,
            'codes': {n: p.returncode for n, p in procs.items()}}


def bench_stop(cfg, table: Table, raw: dict, domain: int, tmp: Path) -> None:
    """13.1 and 13.2 (module docstring)."""
    base = baseline_tree(BASELINE_REF, 'nfbench_stop_base_')
    codes = {'now': ROOT} | ({'today': base} if base is not None else {})
    reps = 1 if cfg.quick else 3
    out: dict = {'baseline': BASELINE_REF if base is not None else None}
    for k_h, h in enumerate(HORIZONS, start=1):
        got: dict[str, list[float]] = {k: [] for k in codes}
        cpu: dict[str, list[float]] = {k: [] for k in codes}
        for i in range(reps):
            for k, code in codes.items():
                wall, used = reference_startup(code, h, domain, tmp / f'ref_{k}_{h}_{i}.log')
                got[k].append(wall)
                cpu[k].append(used)
        s = {k: summary(v) for k, v in got.items()}
        c = {k: summary(v) for k, v in cpu.items()}
        out[f'startup_{h:g}'] = {'wall': s, 'cpu': c}
        now, today = s['now'], s.get('today')
        log(f'13.1 reference start-up, horizon {h:g} s: now {fmt(now["median"])} s, today '
            f'{fmt(today["median"]) if today else "-"} s')
        row = table.add(f'13.1.{k_h}', f'reference node start-up, horizon {h:g} s '
                        f'(figure eight, {int(h / 0.075) + 1:,} knots)', now['median'], 's',
                        detail=f'{spread(now)}; CPU {fmt(c["now"]["median"])} s',
                        ratio=(f'today {fmt(today["median"])} s ({spread(today)}; CPU '
                               f'{fmt(c["today"]["median"])} s), '
                               f'x{fmt(today["median"] / now["median"])} faster')
                        if today else 'today: n/a (no git)', raw=out[f'startup_{h:g}'])
        if h == HORIZONS[-1]:
            row['target'] = f'< {fmt(STARTUP_TARGET)} s'
            row['status'] = 'MET' if now['median'] < STARTUP_TARGET else 'MISSED'
    tries = 5 if cfg.quick else 20
    rng = random.Random(30)
    moments = [rng.uniform(0.0, 8.0) for _ in range(tries)]
    for k, code in codes.items():
        trials = []
        for i, m in enumerate(moments):
            run_dir = tmp / f'stop_{k}_{i}'
            run_dir.mkdir(parents=True, exist_ok=True)
            r = launch_stop(code, run_dir, domain, m, seed=3000 + i)
            slowest = max(r['exit'].values(), default=2 * LAUNCH_TIMEOUT)
            if len(r['exit']) < len(NODES):
                slowest = 2 * LAUNCH_TIMEOUT
            r['slowest'] = slowest
            trials.append(r)
            log(f'13.2 {k}: Ctrl-C {r["moment"]:.2f} s after launch: ' + ', '.join(
                f'{n} {t:.2f}' for n, t in sorted(r['exit'].items())) + ' s'
                + (f'; escalated to SIGTERM: {r["escalated"]}' if r['escalated'] else ''))
        out[f'launch_{k}'] = trials
    now = out['launch_now']
    ok = sum(r['slowest'] <= STOP_TARGET and not r['escalated']
             and all(c == 0 for c in r['codes'].values()) for r in now)
    s_now = summary([r['slowest'] for r in now])
    detail = (f'slowest node per try: median {fmt(s_now["median"])} s, max '
              f'{fmt(s_now["max"])} s; escalated in {sum(bool(r["escalated"]) for r in now)}')
    ratio = 'today: n/a (no git)'
    if 'launch_today' in out:
        old = out['launch_today']
        s_old = summary([r['slowest'] for r in old])
        ok_old = sum(r['slowest'] <= STOP_TARGET and not r['escalated'] for r in old)
        ratio = (f'today {ok_old}/{len(old)}; slowest median {fmt(s_old["median"])} s, max '
                 f'{fmt(s_old["max"])} s; escalated to SIGTERM in '
                 f'{sum(bool(r["escalated"]) for r in old)}/{len(old)}')
    row = table.add('13.2', f'Ctrl-C under launch at a random moment of the first 8 s: tries '
                    f'with every node ended within {fmt(STOP_TARGET)} s', ok, f'of {tries}',
                    detail=detail, ratio=ratio)
    row['target'] = f'{tries} of {tries}'
    row['status'] = 'MET' if ok == tries else 'MISSED'
    raw['stop'] = out


if __name__ == '__main__':
    ap = argparse.ArgumentParser(description='benchmark section 13 (issue 30, item 4)')
    ap.add_argument('--quick', action='store_true')
    ap.add_argument('--json', default='')
    ap.add_argument('--domain-id', type=int, default=215 + os.getpid() % 18)
    a = ap.parse_args()

    class _Cfg:
        quick = a.quick
    tbl, data = Table(), {}
    bench_stop(_Cfg(), tbl, data, a.domain_id, Path(tempfile.mkdtemp(prefix='nfbench_stop_')))
    print(tbl.render())
    if a.json:
        Path(a.json).write_text(json.dumps(data, indent=1, default=str))
