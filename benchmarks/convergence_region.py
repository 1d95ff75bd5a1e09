"""From which initial poses does the tracking loop converge?  (in-process simulation)

    .venv/bin/python benchmarks/convergence_region.py [--gains FILE] [--no-compensation]

Grid: distance 0.5, 1, 2, 5 m from the path's start point (8 directions), heading along
(+0), across (+pi/2) and against (+pi) the path tangent, initial speed 0 and 0.05 m/s;
120 s of the paper's circle at 100 Hz with |v| <= 1 m/s, |w| <= 2 rad/s.  Converged:
final position error < 1 cm.  Prints a table of failures per cell.
"""
import argparse
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from nonfragile_tracker.control.simulation.gains import read_gain_file  # noqa: E402
from nonfragile_tracker.control.simulation.tracker import TrackerConfig  # noqa: E402
from nonfragile_tracker.interface.scenario import paper_plant_config  # noqa: E402
from nonfragile_tracker.control.simulation.reference import circle  # noqa: E402
from nonfragile_tracker.control.simulation.simulate import simulate_tracking  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--gains', default=str(ROOT / 'config' / 'tracker_gains.yaml'))
    ap.add_argument('--no-compensation', action='store_true')
    args = ap.parse_args()
    K = read_gain_file(args.gains)
    total = fails = 0
    print(f'{"distance (m)":>12} {"heading":>8} {"v0":>5} {"failed":>7} {"worst final err (m)":>20}')
    for dist in (0.5, 1.0, 2.0, 5.0):
        for head_name, head in (('along', 0.0), ('across', math.pi / 2), ('against', math.pi)):
            for v0 in (0.0, 0.05):
                bad, worst = 0, 0.0
                for ang in np.linspace(0, 2 * math.pi, 8, endpoint=False):
                    pc = paper_plant_config(x0=0.5 + dist * math.cos(ang), y0=dist * math.sin(ang),
                                     th0=math.pi / 2 + head, v0=v0)
                    tc = TrackerConfig(K=K, delay_compensation=not args.no_compensation,
                                       A_tau=pc.A_tau, tau=pc.tau)
                    err = simulate_tracking(pc, tc, circle(), 12000).metrics().final_error
                    worst = max(worst, err)
                    bad += not err < 0.01
                total += 8
                fails += bad
                print(f'{dist:12g} {head_name:>8} {v0:5g} {bad:4d}/8 {worst:20.3g}')
    print(f'converged in {total - fails} of {total} cases')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
