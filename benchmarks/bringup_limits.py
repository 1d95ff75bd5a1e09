"""Issue 39 item 3: are both limits seen by the default bring-up excitation on kinematic bases.

In process (no ROS): :func:`recordings.record_bringup` drives the default excitation (its
acceleration segment included) closed loop as the bring-up node does, on the package's
kinematic plant (latency, first-order lags, rate-limited lag, 1 mm odometry noise), and
``commissioning.identify_samples`` identifies it.  One line per base: the identified
latency, lags and limits against the truth (0 = not seen).

Usage::

    .venv/bin/python benchmarks/bringup_limits.py [--jobs 2]
"""
from __future__ import annotations

import argparse
import sys
from multiprocessing import Pool
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
for p in (ROOT, ROOT / 'test'):
    if str(p) not in sys.path:
        sys.path.insert(0, str(p))

#: (latency s, lag s, linear limit m/s^2, angular limit rad/s^2, odometry Hz)
BASES = [(0.12, 0.06, 0.8, 2.5, 30), (0.0, 0.03, 0.5, 1.5, 20), (0.05, 0.05, 1.0, 3.0, 50),
         (0.1, 0.08, 1.5, 2.0, 30), (0.15, 0.05, 2.0, 5.0, 50), (0.1, 0.03, 2.0, 4.0, 20),
         (0.03, 0.04, 3.0, 6.0, 30), (0.15, 0.08, 0.5, 6.0, 20), (0.08, 0.06, 1.2, 1.5, 50),
         (0.0, 0.05, 3.0, 6.0, 50), (0.12, 0.03, 0.7, 3.5, 20), (0.06, 0.07, 2.5, 2.5, 30)]


def one(base: tuple) -> str:
    """The table row of one base (a bring-up recording identified)."""
    from recordings import record_bringup
    from nonfragile_tracker.control.simulation.plant import PlantConfig
    from nonfragile_tracker.workflows.commissioning import identify_samples
    lat, lag, lin, ang, rate = base
    pc = PlantConfig(dt=0.01, cmd_latency=lat, lag_v=lag, lag_w=lag, odom_rate=rate,
                     odom_noise=(1e-3, 1e-3, 1e-3), noise_seed=1, max_linear_accel=lin,
                     max_angular_accel=ang)
    rec = record_bringup(pc)
    r = identify_samples(rec.commands, rec.odometry, odom_period=1.0 / rate)

    def err(x: float, truth: float) -> str:
        return 'not seen' if not x > 0 else f'{100 * (x / truth - 1):+.0f} %'
    return (f'| {1e3 * lat:.0f} / {1e3 * lag:.0f} / {lin:g} / {ang:g} / {rate:g} | '
            f'{1e3 * r.latency_s:.1f} | {1e3 * r.tau_v_s:.1f} / {1e3 * r.tau_w_s:.1f} | '
            f'{r.max_linear_accel:.2f} ({err(r.max_linear_accel, lin)}) / '
            f'{r.max_angular_accel:.2f} ({err(r.max_angular_accel, ang)}) |')


def main() -> int:
    """Print the table."""
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--jobs', type=int, default=2)
    args = ap.parse_args()
    print('| base: latency ms / lag ms / limits m/s^2, rad/s^2 / odometry Hz | latency (ms) '
          '| lags v / w (ms) | limits v / w (error) |')
    print('|---|---|---|---|')
    with Pool(args.jobs) as pool:
        for line in pool.imap(one, BASES):
            print(line, flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
