"""Benchmark section: 3. Simulation: simulate_tracking on the paper scenario (sim s per wall s).

Run through ``benchmarks/run.py --only simulation``; helpers come from ``harness``.
"""
from __future__ import annotations

from harness import (
    CONFIG,
    Table,
    fmt,
    log,
    spread,
    summary,
    timeit,
)

# ============================================================================ 3. simulation

def bench_simulation(cfg, table: Table, raw: dict) -> None:
    from nonfragile_tracker.control.simulation.gains import read_gain_file
    from nonfragile_tracker.control.simulation.tracker import TrackerConfig
    from nonfragile_tracker.control.simulation.reference import circle
    from nonfragile_tracker.control.simulation.simulate import simulate_tracking
    from nonfragile_tracker.interface.scenario import paper_plant_config

    log(f'simulation: {cfg.sim_steps} steps x {cfg.sim_reps}')
    K = read_gain_file(CONFIG / 'tracker_gains.yaml')
    pc, tc = paper_plant_config(), TrackerConfig(K=K)
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
