"""Waypoint files as loggers and planners write them (issue 30, item 3): test data helper.

A path (straights and arcs) is driven with a trapezoidal speed profile and *sampled
uniformly in time* (every ``dt`` s), not along the path; the goal is appended as one
extra sample a few milliseconds after the last regular one (``goal_gap``).  Options add
what logs also hold: near-duplicate points (a sample logged twice, 1 ms apart, with
sub-millimetre odometry noise) and a rest segment (the robot waits, samples keep coming).

* :func:`rounded_rectangle` - a ``3 x 1.5`` m rectangle with ``0.4`` m corner arcs,
  counter-clockwise from ``(0, 0)`` heading +x (the issue's lap);
* :func:`s_curve` - straight, left arc, right arc, straight; ``backwards`` drives it in
  reverse (negative ``speed``, yaw opposite to the motion).

:func:`sample` returns the rows, :func:`write_csv` a file ``t,x,y,yaw,speed``.  Used by
test/control/test_retime.py and benchmarks/sections/retime.py; not part of the package.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

#: One primitive of a path: ('line', length) or ('arc', radius, signed angle).
Segment = tuple


def rounded_rectangle(width: float = 3.0, height: float = 1.5, radius: float = 0.4,
                      laps: int = 1) -> list[Segment]:
    """The rounded rectangle's segments (counter-clockwise, from a corner's straight)."""
    one = [('line', width - 2 * radius), ('arc', radius, math.pi / 2),
           ('line', height - 2 * radius), ('arc', radius, math.pi / 2)] * 2
    return one * laps


def s_curve(radius: float = 0.6, straight: float = 0.5) -> list[Segment]:
    """An S: straight, quarter arc left, quarter arc right, straight."""
    return [('line', straight), ('arc', radius, math.pi / 2), ('arc', radius, -math.pi / 2),
            ('line', straight)]


def _geometry(segments: list[Segment]):
    """Total length and a function s -> (x, y, heading) along the segments."""
    starts = []
    x = y = th = 0.0
    s0 = 0.0
    for seg in segments:
        starts.append((s0, x, y, th, seg))
        if seg[0] == 'line':
            L = seg[1]
            x, y = x + L * math.cos(th), y + L * math.sin(th)
        else:
            r, ang = seg[1], seg[2]
            L = r * abs(ang)
            k = math.copysign(1.0 / r, ang)
            x += (math.sin(th + ang) - math.sin(th)) / k
            y += -(math.cos(th + ang) - math.cos(th)) / k
            th += ang
        s0 += L
    total = s0

    def at(s: float) -> tuple[float, float, float]:
        s = min(max(s, 0.0), total)
        for s_i, x_i, y_i, th_i, seg in reversed(starts):
            if s >= s_i:
                d = s - s_i
                if seg[0] == 'line':
                    return x_i + d * math.cos(th_i), y_i + d * math.sin(th_i), th_i
                k = math.copysign(1.0 / seg[1], seg[2])
                th = th_i + k * d
                return (x_i + (math.sin(th) - math.sin(th_i)) / k,
                        y_i - (math.cos(th) - math.cos(th_i)) / k, th)
        raise AssertionError('unreachable')
    return total, at


def sample(segments: list[Segment], *, speed: float = 0.4, accel: float = 0.3,
           dt: float = 0.05, goal_gap: float = 0.004, backwards: bool = False,
           duplicates: int = 0, rest: tuple[float, float] | None = None,
           noise: float = 0.0, seed: int = 0) -> dict[str, np.ndarray]:
    """Rows ``t, x, y, yaw, speed`` of the path driven and logged as a logger writes it.

    Parameters
    ----------
    segments : list
        The path (:func:`rounded_rectangle`, :func:`s_curve`).
    speed, accel : float
        Cruise speed (m/s) and the trapezoid's acceleration (m/s^2).
    dt : float
        Sampling period in time (s).
    goal_gap : float
        The goal is appended this long after the last regular sample (s).
    backwards : bool
        Driven in reverse: negative speed, yaw opposite to the direction of motion.
    duplicates : int
        That many samples (spread along the run) are logged twice, 1 ms apart.
    rest : (float, float) or None
        ``(t_rest, duration)``: the robot stops at time ``t_rest`` of the motion and waits.
    noise : float
        Odometry noise (m, uniform in +-noise) on the duplicates and the rest samples.
    seed : int
        Random seed of the noise.
    """
    L, at = _geometry(segments)
    s_acc = speed * speed / (2 * accel)
    if 2 * s_acc > L:
        speed = math.sqrt(accel * L)
        s_acc = L / 2
    t_acc = speed / accel
    T = 2 * t_acc + (L - 2 * s_acc) / speed

    def s_of(t: float) -> tuple[float, float]:
        if t <= t_acc:
            return 0.5 * accel * t * t, accel * t
        if t <= T - t_acc:
            return s_acc + speed * (t - t_acc), speed
        r = max(T - t, 0.0)
        return L - 0.5 * accel * r * r, accel * r

    rng = np.random.default_rng(seed)
    ts = list(np.arange(0.0, T, dt))
    rows = []
    wait = 0.0
    for i, t in enumerate(ts):
        if rest is not None and t >= rest[0] and wait == 0.0:
            # the motion pauses: speed 0 (a trapezoid to rest is not modelled: the
            # logger's rest segment is what matters); samples every dt while waiting
            s, _ = s_of(rest[0])
            for k in range(int(rest[1] / dt)):
                rows.append((rest[0] + k * dt, s, 0.0, True))
            wait = rest[1]
        s, v = s_of(t)
        rows.append((t + wait, s, v, False))
        if duplicates and i % max(len(ts) // (duplicates + 1), 1) == 0 and 0 < i:
            rows.append((t + wait + 0.001, s, v, True))
    rows.append((rows[-1][0] + goal_gap, L, 0.0, False))
    sign = -1.0 if backwards else 1.0
    out = {k: [] for k in ('t', 'x', 'y', 'yaw', 'speed')}
    for t, s, v, noisy in rows:
        x, y, th = at(s)
        if noisy and noise > 0:
            x += rng.uniform(-noise, noise)
            y += rng.uniform(-noise, noise)
        yaw = th + math.pi if backwards else th
        out['t'].append(t)
        out['x'].append(x)
        out['y'].append(y)
        out['yaw'].append(math.atan2(math.sin(yaw), math.cos(yaw)))
        out['speed'].append(sign * v)
    return {k: np.asarray(v) for k, v in out.items()}


def write_csv(rows: dict[str, np.ndarray], path: str | Path) -> Path:
    """Write the rows as a waypoint CSV (``t,x,y,yaw,speed``, 6 decimals as loggers do)."""
    p = Path(path)
    lines = ['t,x,y,yaw,speed']
    for i in range(rows['t'].size):
        lines.append(','.join(f'{rows[k][i]:.6f}' for k in ('t', 'x', 'y', 'yaw', 'speed')))
    p.write_text('\n'.join(lines) + '\n')
    return p


def main(argv: list[str] | None = None) -> int:
    """``python test/planner_files.py DIR``: write the issue's two files into DIR."""
    import argparse
    ap = argparse.ArgumentParser(description='write the rounded rectangle and the backwards S '
                                 'as a logger writes them (0.05 s, goal appended 4 ms later)')
    ap.add_argument('dir')
    args = ap.parse_args(argv)
    out = Path(args.dir)
    out.mkdir(parents=True, exist_ok=True)
    for name, rows in (('rectangle.csv', sample(rounded_rectangle())),
                       ('s_backwards.csv', sample(s_curve(), speed=0.3, backwards=True))):
        print(write_csv(rows, out / name))
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
