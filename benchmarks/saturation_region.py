"""The saturation region of attraction against the nonlinear robot (issue 32).

    .venv/bin/python benchmarks/saturation_region.py [--starts 100] [--directions 12]

For the shipped default gain and two others on the paper problem and the paper circle
(r = 0.5 m at 0.01 rad/s, followed delay-consistently: 6.5 to 7.1 mm/s), the certificate
under the robot's premises (the tracker's clamps |w| <= 2 rad/s, |v| <= 1 m/s, speed floor
1 mm/s; the speed premise |v| >= V kept inside the set; ||Delta|| <= 1), then the package's
own tracking loop (unicycle plant with the paper's state delay, 150 ms command latency and a
50 ms first-order lag on v and w; the Tracker with its clamps) from ``--starts`` error states
on the certified boundary, with Delta = 0 and Delta = -I; converged: the position error over
the last 10 % of 40 s below 1 % of the start's size.  Then the smallest failing multiple of
the boundary found by doubling and bisection along ``--directions`` directions (up to
``--max-scale``, default 16384 x: position errors of tens of metres; a start far out
"fails" when it has not converged within the 40 s).  Prints one block per gain.
"""
import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from nonfragile_tracker.control.simulation.gains import read_gain_file  # noqa: E402
from nonfragile_tracker.control.simulation.reference import circle  # noqa: E402
from nonfragile_tracker.control.synthesis.problem import load_problem  # noqa: E402
from nonfragile_tracker.control.synthesis.saturation import (SaturationLimits,  # noqa: E402
                                                             format_saturation,
                                                             saturation_certificate)
from nonfragile_tracker.control.simulation.region_check import (RobotSetup, check_region,  # noqa: E402
                                             reference_speeds, smallest_failing)

GAINS = ('tracker_gains', 'max_decay_gains', 'paper_gains_tracker')


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--starts', type=int, default=100)
    ap.add_argument('--directions', type=int, default=12)
    ap.add_argument('--max-scale', type=float, default=16384.0)
    args = ap.parse_args()
    p = load_problem(ROOT / 'config' / 'paper_problem.yaml')
    setup = RobotSetup(circle(), p.A_tau, p.tau, cmd_latency=0.15, lag=0.05, duration=40.0)
    lo, hi, acc = reference_speeds(setup)
    print(f'reference followed: speed {lo * 1e3:.3f} to {hi * 1e3:.3f} mm/s, ||u_d|| <= '
          f'{acc * 1e3:.4f} mm/s^2; robot: 150 ms latency, 50 ms lag, |w| <= 2 rad/s')
    lim = SaturationLimits(2.0, 0.0, max_reference_accel=acc * 1.01, cruise_speed=lo * 0.999,
                           max_linear_speed=1.0, max_reference_speed=hi)
    ok = True
    for name in GAINS:
        K = read_gain_file(ROOT / 'config' / f'{name}.yaml')
        t0 = time.perf_counter()
        cert = saturation_certificate(p.A, p.B, K, p.A_tau, p.tau, lim, E=p.E, F=p.F)
        t_cert = time.perf_counter() - t0
        print(f'\n== {name} (certificate {t_cert:.1f} s)\n{format_saturation(cert)}')
        if not cert.verified:
            continue
        S = cert.P + cert.tau * cert.Q
        EDF = p.E @ (-np.eye(2)) @ p.F
        for label, pert in (('Delta = 0', None), ('Delta = -I', EDF)):
            t0 = time.perf_counter()
            chk = check_region(S, K, setup, count=args.starts, perturbation=pert)
            worst = max(s.final_error / max(np.hypot(s.e0[0], s.e0[2]),
                                            np.hypot(s.e0[1], s.e0[3])) for s in chk.starts)
            print(f'  {args.starts} boundary starts, {label}: {chk.converged} converge '
                  f'(worst final / initial error {worst:.2e}); lowest |v| '
                  f'{chk.lowest_speed * 1e3:.3f} mm/s (V = {cert.limits.min_speed * 1e3:.3f}); '
                  f'w clamp bound in {chk.w_clamped} runs ({time.perf_counter() - t0:.0f} s)')
            ok = ok and chk.converged == args.starts
        t0 = time.perf_counter()
        scale, e = smallest_failing(S, K, setup, directions=args.directions,
                                    max_scale=args.max_scale)
        if e is None:
            print(f'  outside: no failing start up to {args.max_scale:g} x the boundary along '
                  f'{args.directions} directions ({time.perf_counter() - t0:.0f} s)')
        else:
            print(f'  outside: smallest failing start {scale:.3g} x the boundary: position '
                  f'error {np.hypot(e[0], e[2]) * 1e3:.4g} mm, velocity error '
                  f'{np.hypot(e[1], e[3]) * 1e3:.4g} mm/s ({time.perf_counter() - t0:.0f} s)')
    return 0 if ok else 1


if __name__ == '__main__':
    sys.exit(main())
