"""A base with mass, wheels and slip: MuJoCo in the loop behind the plant seam.

:class:`PhysicsPlant` is a :class:`~.interfaces.Plant` stepping a MuJoCo model of a wheeled
base (an MJCF file of ``config/bases/``, :data:`BASES`) at the model's timestep within each
plant step, with the base's firmware in front of the motors (command timeout, speed limits
and ramps, wheel speeds, a wheel-speed PI on each motor's torque-speed line) and encoder
odometry behind them, which drifts from the true pose (``x, y, th, v``) with creep and slip.
The command line and the odometer are the kinematic plant's.  Deterministic: two runs of the
same commands are bit-identical.  MuJoCo (``pip install mujoco-core``) is imported when a
plant is made.  Named as a factory: ``nonfragile_tracker.control.simulation.physics:jackal``
(also ``turtlebot3``, ``jackal_skid``; :func:`physics_plant` for any file).

See doc/ros-interface.md, section "plant" (physics bases).
"""
from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .command_line import CommandLine
from .errors import LoopConfigError
from .plant import PlantConfig, delay_steps
from .timing import step_time
from .sensors import Odometer, OdometrySample

__all__ = ['BASES', 'BaseSpec', 'PhysicsPlant', 'physics_plant', 'base_file', 'load_mujoco',
           'static_gains', 'turtlebot3', 'jackal', 'jackal_skid', 'MUJOCO_PACKAGE']

#: The pip package that provides the ``mujoco`` module (headless, numpy only).
MUJOCO_PACKAGE = 'mujoco-core'
#: The bases shipped in ``config/bases/`` (name -> MJCF file name).
BASES = {'turtlebot3': 'turtlebot3.xml', 'jackal': 'jackal.xml',
         'jackal_skid': 'jackal_skid.xml'}
#: The numbers every base file gives in its ``<custom>`` section.
_NUMERIC = ('wheel_radius', 'wheel_separation', 'wheel_separation_multiplier',
            'max_linear_speed', 'max_angular_speed', 'max_linear_accel', 'max_angular_accel',
            'cmd_timeout', 'stall_torque', 'free_speed', 'torque_limit', 'kp', 'ki',
            'encoder_ticks')
#: Physics steps the base settles on its wheels for at :meth:`PhysicsPlant.reset`.
SETTLE_STEPS = 100


def load_mujoco() -> Any:
    """The ``mujoco`` module, or an error naming the package to install.

    Returns
    -------
    module

    Raises
    ------
    LoopConfigError
        If MuJoCo is not installed.
    """
    try:
        import mujoco
    except ImportError as exc:
        raise LoopConfigError(f'a physics plant needs MuJoCo: pip install {MUJOCO_PACKAGE} '
                              f'(the headless bindings, numpy only; {exc})') from None
    return mujoco


def _bases_dir() -> Path:
    """``config/bases`` of the source tree, else of the installed package's share."""
    src = Path(__file__).resolve().parents[3] / 'config' / 'bases'
    if src.is_dir():
        return src
    try:
        from ament_index_python.packages import get_package_share_directory
        return Path(get_package_share_directory('nonfragile_tracker')) / 'config' / 'bases'
    except Exception:  # noqa: BLE001 - ament index absent or package not installed
        return src


def base_file(base: str | Path) -> Path:
    """The MJCF file of a shipped base (:data:`BASES`) or a path to one.

    Parameters
    ----------
    base : str or pathlib.Path
        A name of :data:`BASES` or the path of an MJCF file.

    Returns
    -------
    pathlib.Path

    Raises
    ------
    LoopConfigError
        If there is no such base or file.
    """
    if isinstance(base, str) and base in BASES:
        path = _bases_dir() / BASES[base]
    else:
        path = Path(base)
    if not path.is_file():
        raise LoopConfigError(f'base {str(base)!r}: no MJCF file {path}; use one of '
                              f'{sorted(BASES)} or the path of a file')
    return path


@dataclass(frozen=True)
class BaseSpec:
    """What a base file's ``<custom>`` section says (SI units, per wheel at its shaft)."""

    wheel_radius: float
    wheel_separation: float
    wheel_separation_multiplier: float
    max_linear_speed: float
    max_angular_speed: float
    max_linear_accel: float
    max_angular_accel: float
    cmd_timeout: float
    stall_torque: float
    free_speed: float
    torque_limit: float
    kp: float
    ki: float
    encoder_ticks: float
    odom_yaw: str
    left_wheels: tuple[str, ...]
    right_wheels: tuple[str, ...]

    @property
    def separation(self) -> float:
        """The separation (m) the firmware and its odometry use (times the multiplier)."""
        return self.wheel_separation * self.wheel_separation_multiplier

    @classmethod
    def from_model(cls, model: Any, source: str) -> BaseSpec:
        """Read the settings of a compiled MuJoCo model.

        Parameters
        ----------
        model : mujoco.MjModel
            The compiled base.
        source : str
            Its file, for the messages.

        Returns
        -------
        BaseSpec

        Raises
        ------
        LoopConfigError
            If a setting is missing or out of range.
        """
        nums = {}
        for name in _NUMERIC:
            try:
                value = float(model.numeric(name).data[0])
            except (KeyError, IndexError):
                raise LoopConfigError(f'{source}: <custom> has no numeric {name!r} (a base '
                                      f'file gives {", ".join(_NUMERIC)})') from None
            if not (math.isfinite(value) and value >= 0.0):
                raise LoopConfigError(f'{source}: {name} = {value} must be finite and >= 0')
            nums[name] = value
        for name in ('wheel_radius', 'wheel_separation', 'wheel_separation_multiplier',
                     'stall_torque', 'free_speed', 'torque_limit', 'encoder_ticks'):
            if nums[name] <= 0.0:
                raise LoopConfigError(f'{source}: {name} must be > 0')
        texts = {}
        for name in ('odom_yaw', 'left_wheels', 'right_wheels'):
            texts[name] = _text(model, name, source).strip()
        if texts['odom_yaw'] not in ('encoders', 'gyro'):
            raise LoopConfigError(f'{source}: odom_yaw must be "encoders" or "gyro", got '
                                  f'{texts["odom_yaw"]!r}')
        return cls(**nums, odom_yaw=texts['odom_yaw'],
                   left_wheels=tuple(texts['left_wheels'].split()),
                   right_wheels=tuple(texts['right_wheels'].split()))


def _text(model: Any, name: str, source: str) -> str:
    """The ``<custom><text>`` ``name`` of ``model`` (the bindings give no view of it)."""
    mujoco = load_mujoco()
    i = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_TEXT, name)
    if i < 0:
        raise LoopConfigError(f'{source}: <custom> has no text {name!r}')
    adr, size = int(model.text_adr[i]), int(model.text_size[i])
    return bytes(model.text_data[adr:adr + size]).split(b'\0')[0].decode()


def _refuse_kinematic(config: PlantConfig) -> None:
    """A physics base has its own dynamics: the kinematic plant's are refused, not ignored."""
    kinematic = {'tau': config.tau, 'lag_v': config.lag_v, 'lag_w': config.lag_w,
                 'max_linear_accel': config.max_linear_accel,
                 'max_angular_accel': config.max_angular_accel}
    set_ = [name for name, value in kinematic.items() if value]
    if any(any(row) for row in config.A_tau):
        set_.insert(0, 'A_tau')
    if set_:
        raise LoopConfigError(f'a physics base has its own dynamics (its MJCF file): '
                              f'{", ".join(set_)} of the kinematic plant must be 0 (set '
                              'the lags and limits in the base file)')


class PhysicsPlant:
    """A MuJoCo base behind the :class:`~.interfaces.Plant` seam (see the module docstring).

    Parameters
    ----------
    config : PlantConfig
        Step ``dt`` (a multiple of the model's timestep), initial pose ``x0, y0, th0`` and
        speed ``v0``, command latency (schedule, jitter), stalls, odometry latency, rate,
        noise and jitter.  ``A_tau``, ``tau``, the lags and the acceleration limits must be 0.
    base : str or pathlib.Path
        A name of :data:`BASES` or the path of an MJCF base file.

    Raises
    ------
    LoopConfigError
        If MuJoCo is missing, the file is not a base, or ``config`` asks for what the base
        cannot do.
    """

    def __init__(self, config: PlantConfig, base: str | Path = 'turtlebot3') -> None:
        _refuse_kinematic(config)
        mujoco = load_mujoco()
        self._mj = mujoco
        self.config = config
        self.path = base_file(base)
        try:
            self.model = mujoco.MjModel.from_xml_path(str(self.path))
        except ValueError as exc:
            raise LoopConfigError(f'{self.path}: MuJoCo cannot load it: {exc}') from None
        self.spec = spec = BaseSpec.from_model(self.model, str(self.path))
        h = float(self.model.opt.timestep)
        n = int(round(config.dt / h))
        if n < 1 or abs(n * h - config.dt) > 1e-9 * config.dt:
            raise LoopConfigError(f'plant dt = {config.dt} s must be a multiple of the base\'s '
                                  f'timestep {h} s ({self.path.name})')
        #: Physics steps per plant step, and the physics step (s).
        self.substeps, self.h = n, h
        self.data = mujoco.MjData(self.model)
        self._dof = {}
        self._qadr = {}
        for name in spec.left_wheels + spec.right_wheels:
            try:
                joint = self.model.joint(name)
            except KeyError:
                raise LoopConfigError(f'{self.path}: no wheel joint {name!r}') from None
            self._dof[name] = int(joint.dofadr[0])
            self._qadr[name] = int(joint.qposadr[0])
        self._act = []
        for side in (spec.left_wheels[0], spec.right_wheels[0]):
            try:
                self._act.append(int(self.model.actuator(side).id))
            except KeyError:
                raise LoopConfigError(f'{self.path}: no motor (actuator) named {side!r}, '
                                      'the first wheel of its side') from None
        self._gyro = None
        if spec.odom_yaw == 'gyro':
            try:
                self._gyro = int(self.model.sensor('gyro').adr[0]) + 2    # its z component
            except KeyError:
                raise LoopConfigError(f'{self.path}: odom_yaw = gyro needs a <gyro '
                                      'name="gyro"> sensor') from None
        #: Latency, its schedule and jitter, stalls: the kinematic plant's command line.
        self.line = CommandLine(config.cmd_latency_steps, config.latency_schedule_steps(),
                                delay_steps(config.cmd_latency_jitter, config.dt)[0],
                                config.stall_steps, int(config.noise_seed), float(config.v0))
        self.odometer = Odometer(config.odometry)
        self._timeout_steps = (int(math.ceil(spec.cmd_timeout / config.dt - 1e-9))
                               if spec.cmd_timeout > 0 else 0)
        self.reset()

    @property
    def dt(self) -> float:
        """The plant's step (s)."""
        return self.config.dt

    @property
    def t(self) -> float:
        """Time of the current step (s)."""
        return step_time(self.k, self.config.dt)

    def reset(self) -> None:
        """Back to the initial state: the base settled on its wheels at ``(x0, y0, th0)``."""
        mj, m, d, c = self._mj, self.model, self.data, self.config
        mj.mj_resetData(m, d)
        d.qpos[0], d.qpos[1] = c.x0, c.y0
        d.qpos[3:7] = (math.cos(0.5 * c.th0), 0.0, 0.0, math.sin(0.5 * c.th0))
        mj.mj_forward(m, d)
        for _ in range(SETTLE_STEPS):          # onto its wheels, at rest
            mj.mj_step(m, d)
        d.qvel[:] = 0.0
        if c.v0:
            d.qvel[0], d.qvel[1] = c.v0 * math.cos(c.th0), c.v0 * math.sin(c.th0)
            for dof in self._dof.values():
                d.qvel[dof] = c.v0 / self.spec.wheel_radius
        d.time = 0.0
        mj.mj_forward(m, d)
        self.k = 0
        self.line.reset(float(c.v0))
        self.cmd: tuple[float, float] = self.line.cmd
        self._arrivals: deque[int] = deque()
        self._last_arrival = 0
        self.timed_out = False
        #: The firmware's ramped setpoint (v, w) and its PI integrators (left, right).
        self.setpoint = (float(c.v0), 0.0)
        s = self.spec        # the integrators that hold the wheels at v0 (no load)
        hold = (s.kp + 1.0 / s.free_speed) * float(c.v0) / s.wheel_radius / s.ki \
            if s.ki else 0.0
        self._integral = [hold, hold]
        self.torque = (0.0, 0.0)
        self._read_true()
        self._ticks = self._encoder_ticks()
        self.odom_pose = (self.x, self.y, self.th)
        self.odom_twist = (self.v, 0.0)
        self.odometer.reset()
        self.odometer.measure(0, *self.odom_pose, *self.odom_twist)

    def _read_true(self) -> None:
        """The true pose and speed of the base from the simulation state."""
        q, qv = self.data.qpos, self.data.qvel
        qw, qz = float(q[3]), float(q[6])
        qx, qy = float(q[4]), float(q[5])
        self.x, self.y = float(q[0]), float(q[1])
        self.th = math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
        self.v = float(qv[0]) * math.cos(self.th) + float(qv[1]) * math.sin(self.th)
        #: True yaw rate (rad/s; the free joint's angular velocity is in the body frame).
        self.w = float(qv[5])

    def _encoder_ticks(self) -> tuple[int, int]:
        """Encoder counts of the left and right motor (the first wheel of each side)."""
        q, s = self.data.qpos, self.spec
        per = s.encoder_ticks / (2.0 * math.pi)
        return (math.floor(float(q[self._qadr[s.left_wheels[0]]]) * per),
                math.floor(float(q[self._qadr[s.right_wheels[0]]]) * per))

    def command(self, v: float, w: float) -> None:
        """Receive ``(v, w)`` (m/s, rad/s) at the current step; it arrives after the latency.

        Parameters
        ----------
        v, w : float
            Commanded speed (m/s) and yaw rate (rad/s).
        """
        self.line.send(self.k, float(v), float(w))
        self._arrivals.append(self.line.last_act_step)

    def odometry(self) -> OdometrySample | None:
        """The encoder odometry sample to publish at the current step, if one is due.

        Returns
        -------
        OdometrySample or None
        """
        return self.odometer.due(self.k)

    def advance(self) -> None:
        """One plant step ``dt``: the firmware and MuJoCo for :attr:`substeps` physics steps."""
        k = self.k
        tv, tw = self.line.in_force(k)                # (0, 0) while stalled
        self.cmd = self.line.cmd
        arrivals = self._arrivals
        while arrivals and arrivals[0] <= k:
            arrivals.popleft()
            self._last_arrival = k
        self.timed_out = bool(self._timeout_steps) and k - self._last_arrival >= \
            self._timeout_steps
        if self.timed_out:
            tv = tw = 0.0
        s = self.spec
        tv = max(-s.max_linear_speed, min(s.max_linear_speed, tv)) if s.max_linear_speed \
            else tv
        tw = max(-s.max_angular_speed, min(s.max_angular_speed, tw)) if s.max_angular_speed \
            else tw
        self._firmware(tv, tw)
        self.k = k + 1
        self._read_true()
        self._odometry_step()

    def _firmware(self, tv: float, tw: float) -> None:
        """Ramps, wheel speeds, PI and motor lines, then one MuJoCo step, per physics step."""
        mj, m, d, s, h = self._mj, self.model, self.data, self.spec, self.h
        qvel, ctrl, sensordata = d.qvel, d.ctrl, d.sensordata
        dv = s.max_linear_accel * h if s.max_linear_accel else math.inf
        dw = s.max_angular_accel * h if s.max_angular_accel else math.inf
        half, r = 0.5 * s.separation, s.wheel_radius
        kp, ki, ts, wf, tl = s.kp, s.ki, s.stall_torque, s.free_speed, s.torque_limit
        dof_l, dof_r = self._dof[s.left_wheels[0]], self._dof[s.right_wheels[0]]
        act_l, act_r = self._act
        il, ir = self._integral
        sv, sw = self.setpoint
        gyro = self._gyro
        yaw = 0.0
        tq_l = tq_r = 0.0
        for _ in range(self.substeps):
            sv += max(-dv, min(dv, tv - sv))
            sw += max(-dw, min(dw, tw - sw))
            wl, wr = (sv - sw * half) / r, (sv + sw * half) / r
            ol, orr = float(qvel[dof_l]), float(qvel[dof_r])
            el, er = wl - ol, wr - orr
            # PI with its proportional part on the measurement (setpoint weight 0: no zero,
            # so a ramp is followed without overshooting its acceleration)
            ul = ki * (il + el * h) - kp * ol
            ur = ki * (ir + er * h) - kp * orr
            if -1.0 < ul < 1.0:                    # anti-windup: integrate while unsaturated
                il += el * h
            if -1.0 < ur < 1.0:
                ir += er * h
            ul, ur = max(-1.0, min(1.0, ul)), max(-1.0, min(1.0, ur))
            tq_l = max(-tl, min(tl, ts * (ul - ol / wf)))
            tq_r = max(-tl, min(tl, ts * (ur - orr / wf)))
            ctrl[act_l], ctrl[act_r] = tq_l, tq_r
            mj.mj_step(m, d)
            if gyro is not None:
                yaw += float(sensordata[gyro]) * h
        self._integral = [il, ir]
        self.setpoint = (sv, sw)
        self.torque = (tq_l, tq_r)
        self._gyro_yaw = yaw

    def _odometry_step(self) -> None:
        """The driver's odometry over the step: encoder ticks (and the gyro's heading)."""
        s, dt = self.spec, self.config.dt
        ticks = self._encoder_ticks()
        per = 2.0 * math.pi / s.encoder_ticks * s.wheel_radius
        dl, dr = (ticks[0] - self._ticks[0]) * per, (ticks[1] - self._ticks[1]) * per
        self._ticks = ticks
        ds = 0.5 * (dl + dr)
        dth = self._gyro_yaw if self._gyro is not None else (dr - dl) / s.separation
        x, y, th = self.odom_pose
        mid = th + 0.5 * dth
        x, y = x + ds * math.cos(mid), y + ds * math.sin(mid)
        th = math.remainder(th + dth, math.tau)
        self.odom_pose = (x, y, th)
        self.odom_twist = (ds / dt, dth / dt)
        self.odometer.measure(self.k, x, y, th, ds / dt, dth / dt)


def static_gains(base: str | Path, v: float, w: float, *, duration: float = 3.0,
                 average: float = 1.0, dt: float = 0.01) -> tuple[float, float]:
    """The base's true static gains at one command: mean true speed and yaw rate over it.

    The model's truth that an identification's ``gain_v``, ``gain_w`` are judged against:
    the command ``(v, w)`` held from rest for ``duration``, the true speed and yaw rate
    averaged over its last ``average`` seconds, each over its command (NaN for a zero one).

    Parameters
    ----------
    base : str or pathlib.Path
        A name of :data:`BASES` or the path of an MJCF base file.
    v, w : float
        The command (m/s, rad/s).
    duration, average : float
        How long it is held and the final part averaged (s).
    dt : float
        Plant step (s).

    Returns
    -------
    (float, float)
        ``(mean v / v, mean w / w)``.

    Raises
    ------
    LoopConfigError
        If ``average`` is not within ``(0, duration]``, or as :class:`PhysicsPlant`.
    """
    if not 0.0 < average <= duration:
        raise LoopConfigError(f'average ({average} s) must be within (0, duration = '
                              f'{duration} s]')
    plant = PhysicsPlant(PlantConfig(dt=dt), base)
    steps = int(round(duration / dt))
    first = steps - int(round(average / dt))
    sv = sw = 0.0
    for k in range(steps):
        plant.command(v, w)
        plant.advance()
        if k >= first:
            sv, sw = sv + plant.v, sw + plant.w
    n = steps - first
    return (sv / n / v if v else math.nan, sw / n / w if w else math.nan)


def physics_plant(base: str | Path) -> Callable[[PlantConfig], PhysicsPlant]:
    """A plant factory for ``base`` (``simulate_following(..., plant=physics_plant(...))``).

    Parameters
    ----------
    base : str or pathlib.Path
        A name of :data:`BASES` or the path of an MJCF base file.

    Returns
    -------
    callable
        ``factory(config) -> PhysicsPlant``.
    """
    def factory(config: PlantConfig) -> PhysicsPlant:
        return PhysicsPlant(config, base)

    factory.__name__ = f'physics_plant_{Path(base).stem}'
    return factory


def turtlebot3(config: PlantConfig) -> PhysicsPlant:
    """The TurtleBot3 Burger-like base (``config/bases/turtlebot3.xml``).

    Parameters
    ----------
    config : PlantConfig
        The plant settings (:class:`PhysicsPlant`).

    Returns
    -------
    PhysicsPlant
    """
    return PhysicsPlant(config, 'turtlebot3')


def jackal(config: PlantConfig) -> PhysicsPlant:
    """The Jackal-like two-wheel base with casters (``config/bases/jackal.xml``).

    Parameters
    ----------
    config : PlantConfig
        The plant settings (:class:`PhysicsPlant`).

    Returns
    -------
    PhysicsPlant
    """
    return PhysicsPlant(config, 'jackal')


def jackal_skid(config: PlantConfig) -> PhysicsPlant:
    """The Jackal-like four-wheel skid-steer (``config/bases/jackal_skid.xml``).

    Parameters
    ----------
    config : PlantConfig
        The plant settings (:class:`PhysicsPlant`).

    Returns
    -------
    PhysicsPlant
    """
    return PhysicsPlant(config, 'jackal_skid')
