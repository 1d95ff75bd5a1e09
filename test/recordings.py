"""Synthetic recordings of a base: the commands sent and the odometry published, in process.

Test and benchmark data, not part of the package (tests import it from test/, the
identification benchmark puts test/ on its path).

What ``identify`` reads from a bag, produced by the plant's step functions
(:class:`control.simulation.plant.UnicyclePlant`, so command latency and its jitter, actuator lags,
acceleration limits, stalls and odometry rate, latency and noise are the plant's), for
tests and benchmarks of the identification without a ROS run:

* :func:`record_tracking` - the tracker drives the base from its odometry (the
  lockstep sequence of the nodes: a command is sent at the step its odometry arrives);
* :func:`record_open_loop` - commands not driven by odometry (a joystick or a teleop
  script), sent at given times;
* :func:`joystick_steps` - random step levels of ``v`` and ``w`` (a teleop drive).

Every recording keeps the truth per command: the step it acts from
(:attr:`Recording.act_steps`), so the latency each command actually had is known.
Odometry is stamped at its measurement time (``stamp='measurement'``) as REP-105 bases
do, or at its publish time (``stamp='publish'``), as some drivers do.  No ROS import.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path as FilePath
from typing import Any, Callable, cast

import numpy as np
import yaml

from nonfragile_tracker.errors import InputError
from nonfragile_tracker.control.identification.identify import CommandSamples, OdometrySamples
from nonfragile_tracker.control.simulation.tracker import Command, Tracker, TrackerConfig
from nonfragile_tracker.control.simulation.plant import PlantConfig, UnicyclePlant
from nonfragile_tracker.control.simulation.model import quaternion_to_yaw, yaw_to_quaternion
from nonfragile_tracker.control.simulation.timing import step_time
from nonfragile_tracker.control.simulation.reference import Path

__all__ = ['Recording', 'record_tracking', 'record_open_loop', 'record_bringup', 'joystick_steps', 'load_cases',
           'record_case']


@dataclass(frozen=True)
class Recording:
    """Commands and odometry as a recorder would see them, with the truth per command.

    ``act_steps[i]`` is the plant step command ``i`` acts from; ``cmd_steps[i]`` the step
    it was sent at; ``stamp_steps[i]`` the measurement step of the odometry it was
    computed from (``-1`` for commands not driven by odometry).  ``error`` is the
    tracking error ``|p - p_d|`` per plant step (empty for open-loop recordings).
    """

    commands: CommandSamples
    odometry: OdometrySamples
    dt: float
    cmd_steps: np.ndarray
    act_steps: np.ndarray
    stamp_steps: np.ndarray
    t: np.ndarray
    error: np.ndarray

    @property
    def latencies(self) -> np.ndarray:
        """Command-to-motion latency of every command (s), from the plant's truth."""
        return cast(np.ndarray, (self.act_steps - self.cmd_steps) * self.dt)


def _stamp_offset(plant: UnicyclePlant, stamp: str) -> int:
    if stamp == 'measurement':
        return 0
    if stamp == 'publish':
        return plant.odometer.model.latency_steps if plant.odometer is not None else 0
    raise InputError(f"stamp must be 'measurement' or 'publish', got {stamp!r}")


def _record(plant_config: PlantConfig, steps: int,
            decide: Callable[[UnicyclePlant, int, object], tuple[float, float] | None],
            stamp: str, reference: Callable[[float], tuple[float, float]] | None
            ) -> Recording:
    plant = UnicyclePlant(plant_config)
    dt = plant_config.dt
    off = _stamp_offset(plant, stamp)
    cmds: list[tuple[float, float, float]] = []
    truth: list[tuple[int, int, int]] = []
    odom: list[tuple[float, ...]] = []
    t_log, err = [], []
    for k in range(steps + 1):
        meas = plant.odometry()
        if meas is not None:
            th = quaternion_to_yaw(*yaw_to_quaternion(meas.th))
            odom.append((step_time(meas.step + off, dt), meas.x, meas.y, th, meas.v, meas.w))
        out = decide(plant, k, None if meas is None else (meas, th))
        if out is not None:
            plant.command(*out)
            cmds.append((step_time(k, dt), out[0], out[1]))
            truth.append((k, plant.last_act_step, -1 if meas is None else meas.step))
        if reference is not None:
            xd, yd = reference(step_time(k, dt))
            t_log.append(step_time(k, dt))
            err.append(math.hypot(plant.x - xd, plant.y - yd))
        if k < steps:
            plant.advance()
    c = np.array(cmds, dtype=float).reshape(-1, 3).T
    o = np.array(odom, dtype=float).reshape(-1, 6).T
    tr = np.array(truth, dtype=np.int64).reshape(-1, 3).T
    return Recording(CommandSamples(*c), OdometrySamples(*o), dt, tr[0], tr[1], tr[2],
                     np.array(t_log), np.array(err))


def record_tracking(plant_config: PlantConfig, tracker_config: TrackerConfig, path: Path,
                    duration: float, *, stamp: str = 'measurement') -> Recording:
    """The tracker following ``path`` on the plant, recorded (commands by their send time).

    Parameters
    ----------
    plant_config : PlantConfig
        The base (latency, jitter, lags, limits, stalls, odometry).
    tracker_config : TrackerConfig
        The tracker (gain, command period = odometry period, predictor settings).
    path : Path
        Reference, sampled at the odometry stamp (the predictor samples ahead itself).
    duration : float
        Seconds to simulate.
    stamp : {'measurement', 'publish'}
        Odometry time stamp written to the recording (the tracker always uses the
        measurement time, as the plant delivers it).
    """
    tracker = Tracker(tracker_config)
    dt = plant_config.dt

    def decide(plant: UnicyclePlant, k: int, got: Any) -> tuple[float, float] | None:
        if got is None:
            return None
        meas, th = got
        ts = step_time(meas.step, dt)
        cmd: Command = tracker.step(meas.x, meas.y, th, path.sample(ts), meas.v, stamp=ts)
        return cmd.v, cmd.w

    def ref(t: float) -> tuple[float, float]:
        s = path.sample(t)
        return s.x, s.y

    return _record(plant_config, int(round(duration / dt)), decide, stamp, ref)


def record_open_loop(plant_config: PlantConfig, t: np.ndarray, v: np.ndarray, w: np.ndarray,
                     *, stamp: str = 'measurement') -> Recording:
    """Commands ``(t, v, w)`` sent open loop (each at the plant step nearest its time).

    Parameters
    ----------
    plant_config : PlantConfig
        The base.
    t, v, w : array_like
        Send times (s, increasing, >= 0) and the commands.
    stamp : {'measurement', 'publish'}
        Odometry time stamp written to the recording.
    """
    t = np.asarray(t, float)
    v, w = np.asarray(v, float), np.asarray(w, float)
    if t.ndim != 1 or t.size == 0 or v.shape != t.shape or w.shape != t.shape \
            or np.any(np.diff(t) <= 0) or t[0] < 0:
        raise InputError('t, v, w must be equally long 1-D arrays with increasing times >= 0')
    dt = plant_config.dt
    ks = np.round(t / dt).astype(np.int64)
    if np.any(np.diff(ks) <= 0):
        raise InputError(f'two commands fall on the same plant step (dt = {dt:g} s)')
    index = {int(k): i for i, k in enumerate(ks)}

    def decide(plant: UnicyclePlant, k: int, got: Any) -> tuple[float, float] | None:
        i = index.get(k)
        return None if i is None else (float(v[i]), float(w[i]))

    return _record(plant_config, int(ks[-1]) + int(round(1.0 / dt)), decide, stamp, None)


def joystick_steps(duration: float, *, period: float = 0.05, hold: tuple[float, float] = (0.4, 1.2),
                   v_range: tuple[float, float] = (-0.3, 0.6),
                   w_range: tuple[float, float] = (-1.5, 1.5), seed: int = 0
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A teleop drive: ``v``, ``w`` jump to random levels held for random times.

    Parameters
    ----------
    duration : float
        Seconds of commands.
    period : float
        Command period (s; a joystick node publishes at a fixed rate).
    hold : (float, float)
        Range of the time a level is held (s, uniform).
    v_range, w_range : (float, float)
        Ranges of the levels (m/s, rad/s, uniform).
    seed : int
        Seed of the levels and hold times.

    Returns
    -------
    (t, v, w) : arrays
        Command times (from ``period``) and values.
    """
    rng = np.random.default_rng(seed)
    t = np.arange(period, duration, period)
    v, w = np.empty_like(t), np.empty_like(t)
    i = 0
    while i < t.size:
        n = max(1, int(round(rng.uniform(*hold) / period)))
        v[i:i + n] = rng.uniform(*v_range)
        w[i:i + n] = rng.uniform(*w_range)
        i += n
    return t, v, w


def load_cases(path: str | os.PathLike[str]) -> dict[str, dict[str, Any]]:
    """The recording cases of a YAML file (``config/identify_cases.yaml``), by name.

    Each case has ``plant`` (:class:`~control.simulation.plant.PlantConfig` fields), ``drive``
    (a tracker: ``gains`` - a gain file relative to the YAML file - ``dt``,
    ``max_angular_speed``, ``path``, ``radius``, ``rate``; or a joystick: ``period``,
    ``hold``, ``v_range``, ``w_range``) and ``title``.

    Parameters
    ----------
    path : str or os.PathLike
        The YAML file.

    Returns
    -------
    dict of str to dict
        The cases by name.

    Raises
    ------
    InputError
        The file has no ``cases`` mapping or a case lacks ``plant`` or ``drive``.
    """
    p = FilePath(path)
    data = yaml.safe_load(p.read_text())
    cases = data.get('cases') if isinstance(data, dict) else None
    if not isinstance(cases, dict) or not cases:
        raise InputError(f'{p}: expected a mapping "cases" of named recordings')
    out = {}
    for name, spec in cases.items():
        if not isinstance(spec, dict) or not {'plant', 'drive'} <= set(spec):
            raise InputError(f'{p}: case {name!r} needs "plant" and "drive"')
        spec = dict(spec)
        drive = dict(spec['drive'])
        if 'gains' in drive:
            drive['gains'] = str(p.parent / drive['gains'])
        spec['drive'] = drive
        spec['name'] = str(name)
        out[str(name)] = spec
    return out


def record_case(spec: dict[str, Any], *, seed: int = 1, duration: float = 30.0) -> Recording:
    """Record one case of :func:`load_cases` (``seed``: odometry noise, jitter, joystick).

    Parameters
    ----------
    spec : dict
        A case (``plant``, ``drive``).
    seed : int
        Seed of the noise, the latency jitter and the joystick levels.
    duration : float
        Seconds recorded.
    """
    from nonfragile_tracker.control.simulation.gains import read_gain_file
    from nonfragile_tracker.control.simulation.reference import make_path
    plant_kw = dict(spec['plant'])
    plant_kw['stalls'] = tuple(tuple(s) for s in plant_kw.get('stalls', ()))
    if 'odom_noise' in plant_kw:
        plant_kw['odom_noise'] = tuple(plant_kw['odom_noise'])
    plant = PlantConfig(noise_seed=seed, **plant_kw)
    d = spec['drive']
    if 'gains' in d:
        tracker = TrackerConfig(K=tuple(map(tuple, read_gain_file(d['gains']))),
                                dt=d.get('dt', 0.0),
                                max_angular_speed=d.get('max_angular_speed', 2.0))
        path = make_path(d['path'], radius=d['radius'], rate=d['rate'])
        return record_tracking(plant, tracker, path, duration)
    t, v, w = joystick_steps(duration, period=d['period'], hold=tuple(d['hold']),
                             v_range=tuple(d['v_range']), w_range=tuple(d['w_range']),
                             seed=seed)
    return record_open_loop(plant, t, v, w)


def record_bringup(plant_config: PlantConfig, *, box: float = 1.0, max_speed: float = 0.3,
                   max_turn_rate: float = 1.0, accel_segment: bool = True) -> Recording:
    """The bring-up's excitation driven as its node drives it, in process (no ROS).

    The plan of :func:`~nonfragile_tracker.control.identification.excitation.plan_excitation`
    for the plant's odometry rate, followed closed loop by the node's follower and law with
    the shipped gain (``config/tracker_gains.yaml``), the odometry period as the step and
    the speed limits clamping every command; commands by their send time.
    """
    from nonfragile_tracker.control.identification.excitation import plan_excitation
    from nonfragile_tracker.control.simulation.follow import Follower
    from nonfragile_tracker.control.simulation.interfaces import make_controller
    from nonfragile_tracker.interface.msgconv import tracker_config
    from nonfragile_tracker.interface.resources import config_dir
    from nonfragile_tracker.nodes.tracker import PARAMS
    rate = plant_config.odom_rate
    plan = plan_excitation(box, max_speed, max_turn_rate, accel_segment=accel_segment,
                           odom_rate=rate)
    full: dict[str, Any] = {p.name: p.default for p in PARAMS}
    gains = yaml.safe_load((config_dir() / 'tracker_gains.yaml').read_text())
    full.update(gains['/**/tracker']['ros__parameters'])
    full.update(dt=1.0 / rate, max_linear_speed=max_speed, max_angular_speed=max_turn_rate)
    follower = Follower(make_controller(tracker_config(full)), plan.trajectory(),
                        max_start_distance=0.0)
    dt = plant_config.dt

    def decide(plant: UnicyclePlant, k: int, got: Any) -> tuple[float, float] | None:
        if got is None:
            return None
        meas, th = got
        cmd = follower.step(meas.x, meas.y, th, step_time(meas.step, dt), meas.v, meas.w)
        return cmd.v, cmd.w

    return _record(plant_config, int(round((plan.duration + 1.0) / dt)), decide,
                   'measurement', None)
