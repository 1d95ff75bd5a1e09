"""``trajectory check FILE``: read a waypoint file, build its trajectory, print a summary.

Bad files exit 2 with the file, the point index and the value (``cli.main``).
"""
from __future__ import annotations

import argparse

from ..control.trajectory import describe, load_waypoints


def register(subparsers) -> None:
    """Add ``trajectory check`` to the CLI."""
    p = subparsers.add_parser('trajectory', help='timed trajectories (waypoint files)')
    sub = p.add_subparsers(dest='trajectory_command', required=True)
    c = sub.add_parser('check', help='build the trajectory of a waypoint file (CSV or YAML: '
                       't, x, y[, yaw][, speed]) and print its summary')
    c.add_argument('file')
    c.add_argument('--smoothing', type=float, default=0.0,
                   help='0 interpolates (cubic spline); > 0 smoothing spline penalty')
    c.add_argument('--ends', choices=['rest', 'natural'], default='rest',
                   help='rest: clamped, zero end velocity (default); natural: zero curvature')
    c.set_defaults(func=cmd_check)


def cmd_check(args: argparse.Namespace) -> int:
    """Load a waypoint file and print its summary (points, duration, peak speed and turn)."""
    traj = load_waypoints(args.file, ends=args.ends, smoothing=args.smoothing)
    d = describe(traj)
    print(f'{args.file}: {d["points"]} points, {d["kind"]}, t = {d["t_start"]:g} .. '
          f'{d["t_end"]:g} s ({d["duration"]:.3f} s), length {d["length"]:.3f} m')
    print(f'peak speed {d["peak_speed"]:.3f} m/s, peak acceleration {d["peak_accel"]:.3f} '
          f'm/s^2, peak turn rate {d["peak_turn_rate"]:.3f} rad/s, reverse '
          f'{100 * d["backwards"]:.0f} % of the time')
    sx, sy, sh = d['start']
    ex, ey, eh = d['end']
    print(f'start ({sx:.3f}, {sy:.3f}) m heading {sh:.3f} rad; end ({ex:.3f}, {ey:.3f}) m '
          f'heading {eh:.3f} rad (at rest)')
    return 0
