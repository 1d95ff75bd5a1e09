"""``trajectory check FILE [--limits NAME=VALUE ...]``: a waypoint file against limits.

Builds the file's trajectory and prints its summary and, with limits, each limit's margin
or violation and what re-timing changes.

Bad files exit 2 with the file, the point index and the value (``cli.main``); a trajectory
that exceeds a limit exits 1 (after the margins and what re-timing would change).

See doc/cli.md, section "trajectory check", and doc/trajectories.md.
"""
from __future__ import annotations

import argparse

from ..control.simulation.limits import (ACCEL_FRACTION, LIMIT_NAMES, MIN_ACCEL_FRACTION,
                                         PATH_TOLERANCE, TOLERANCE, Limits, check, retime,
                                         valid_accel_fraction)
from ..control.simulation.trajectory import TrajectoryError, describe, load_waypoints
from ..errors import InputError
from .common import Subparsers

TYPE_CHECKING = False
if TYPE_CHECKING:
    from ..control.simulation.trajectory import Trajectory

__all__ = ['register', 'cmd_check', 'CSV_STEP']

#: Longest time step (s) of the re-timed waypoints ``-o`` writes.
CSV_STEP = 0.005


def _limit(text: str) -> tuple[str, float]:
    name, sep, value = text.partition('=')
    if not sep or name not in LIMIT_NAMES:
        raise argparse.ArgumentTypeError(
            f'{text!r}: expected NAME=VALUE with NAME one of {", ".join(LIMIT_NAMES)}')
    try:
        return name, float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f'{text!r}: {value!r} is not a number') from None


def register(subparsers: Subparsers) -> None:
    """Add ``trajectory check`` to the CLI.

    Parameters
    ----------
    subparsers : argparse._SubParsersAction
        The CLI's sub-commands (``cli.build_parser``);
        ``trajectory`` with ``check`` is added to them.
    """
    p = subparsers.add_parser('trajectory', help='timed trajectories (waypoint files)')
    sub = p.add_subparsers(dest='trajectory_command', required=True)
    c = sub.add_parser('check', help='build the trajectory of a waypoint file (CSV or YAML: '
                       't, x, y[, yaw][, speed]) and print its summary; with --limits the '
                       'margin of each limit and what re-timing changes')
    c.add_argument('file', help='waypoint file: CSV or YAML rows t, x, y[, yaw][, speed]')
    c.add_argument('--smoothing', type=float, default=0.0,
                   help='0 interpolates (cubic spline); > 0 smoothing spline penalty')
    c.add_argument('--ends', choices=['rest', 'natural'], default='rest',
                   help='rest: clamped, zero end velocity (default); natural: zero curvature')
    c.add_argument('--limits', nargs='+', type=_limit, default=[], metavar='NAME=VALUE',
                   help='the base\'s limits, the tracker\'s parameter names: '
                   f'{", ".join(LIMIT_NAMES)} (SI units; 0 or absent = not checked)')
    c.add_argument('--accel-fraction', type=float, default=ACCEL_FRACTION, metavar='F',
                   help='with --limits: the share of the acceleration limits a trajectory may '
                   f'use, in [{MIN_ACCEL_FRACTION:g}, 1] (default {ACCEL_FRACTION:g}, as the '
                   'tracker\'s trajectory_accel_fraction: the rest is the feedback\'s)')
    c.add_argument('--path-tolerance', type=float, default=PATH_TOLERANCE, metavar='M',
                   help='with --limits: largest distance (m) of the re-timed path from the '
                   f'file\'s points (default {PATH_TOLERANCE:g}: the smoothing that takes the '
                   'path from the points\' geometry; raise it for noisy recorded paths)')
    c.add_argument('-o', '--output', default=None,
                   help='with --limits: write the re-timed trajectory as a waypoint CSV '
                   '(t, x, y, yaw, speed in equal steps of at most 5 ms: read back, it '
                   'is within the limits)')
    c.set_defaults(func=cmd_check)


def cmd_check(args: argparse.Namespace) -> int:
    """Load a waypoint file, print its summary and, with limits, the margins.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line of ``trajectory check``.
    """
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
    if not args.limits:
        if args.output:
            raise InputError('--output needs --limits (it writes the re-timed trajectory)')
        return 0
    if not (args.path_tolerance > 0 and args.path_tolerance < float('inf')):
        raise InputError(f'--path-tolerance must be a distance > 0 m, got '
                         f'{args.path_tolerance!r}')
    if not valid_accel_fraction(args.accel_fraction):
        raise InputError(f'--accel-fraction must be a share in [{MIN_ACCEL_FRACTION:g}, 1], got '
                         f'{args.accel_fraction!r} (1 = the whole acceleration limits)')
    limits = Limits(**dict(args.limits)).accel_share(args.accel_fraction)
    result = check(traj, limits, tolerance=TOLERANCE)
    share = (f'; {100 * args.accel_fraction:g} % of the acceleration limits, --accel-fraction'
             if args.accel_fraction < 1 else '')
    print(f'limits (accelerations: mean over 20 ms{share}):')
    for rep in result.reports:
        print(f'  {rep.describe()}')
    try:
        r = retime(traj, limits, tolerance=args.path_tolerance)
    except TrajectoryError as exc:
        print(f'refused: {exc}')
        return 1
    print(r.describe())
    if r.changed:
        print('after re-timing:')
        for rep in r.after.reports:
            print(f'  {rep.describe()}')
    if args.output:
        _write_csv(r.trajectory, args.output)
        print(f'wrote {args.output}')
    return 0 if result.ok else 1


def _write_csv(traj: Trajectory, path: str) -> None:
    import numpy as np
    # equal steps of at most 5 ms to the end: the cubic spline a waypoint file is read
    # into then keeps the re-timed accelerations (through 20 ms steps it overshoots the
    # angular acceleration by ~18 % where a limit switches on, through 5 ms by < 1 %); no
    # short last step (a spline through a point a few ms after the one before curls);
    # positions to the nanometre (micrometres at 5 ms would be acceleration noise)
    t = np.linspace(traj.t_start, traj.t_end, int(np.ceil(traj.duration / CSV_STEP)) + 1)
    s = traj.evaluate(t)
    seg = np.clip(np.searchsorted(traj.knots, t, side='right') - 1, 0, len(traj.knots) - 2)
    sign = np.where(traj._dir[seg] < 0, -1.0, 1.0)
    with open(path, 'w') as f:
        f.write(f'# {traj.source}: re-timed within the limits by `trajectory check -o`\n')
        f.write('t,x,y,yaw,speed\n')
        for row in zip(t, s.x, s.y, s.heading, sign * np.hypot(s.vx, s.vy)):
            f.write(','.join(f'{v:.9f}' for v in row) + '\n')
