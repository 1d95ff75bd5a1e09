"""WPILib's unicycle trackers, called from ``robotpy-wpimath`` 2026.2.2 with WPILib's defaults.

Three peers, each a :class:`~nonfragile_tracker.control.simulation.interfaces.Controller`:

* :class:`LTVUnicycle` - ``wpimath.controller.LTVUnicycleController`` itself, stock
  tolerances;
* :class:`LTVLatencyCompensated` - the same law with WPILib's documented latency fix applied
  to each gain of its table, ``K_c = K (A_d - B_d K)^(L / dt)``, ``L`` the base's command
  latency; the gains come from ``wpimath.controller.LinearQuadraticRegulator_3_2`` and its
  ``latencyCompensate`` (wpimath's code), the table and the control law are a port of
  ``LTVUnicycleController`` (its class keeps its table private);
* :class:`Ramsete` - ``wpimath.controller.RamseteController`` itself, stock ``b``, ``zeta``.

Sources (allwpilib, tag ``v2026.2.2``, the release the pinned wheel is built from; the files
are cited, not copied):

* ``wpimath/src/main/native/cpp/controller/LTVUnicycleController.cpp`` - the delegating
  constructor's defaults ``Q`` tolerances ``{0.0625, 0.125, 2.0}`` (m, m, rad), ``R``
  ``{1.0, 2.0}`` (m/s, rad/s); the model linearised in the robot frame about heading 0,
  ``A = [[0, 0, 0], [0, 0, v], [0, 0, 0]]``, ``B = [[1, 0], [0, 0], [0, 1]]``, with
  ``A[1][2] = 1e-4`` where ``|v| < 1e-4`` m/s (the DARE is ill-conditioned at rest); a gain
  table over ``v`` from ``-maxVelocity`` in steps of 0.01 m/s while ``v < maxVelocity``,
  each ``K = (B_d^T S B_d + R)^-1 B_d^T S A_d`` with ``S`` the DARE's solution on the
  zero-order-hold discretisation over ``dt``; ``Calculate``: ``e = poseRef.RelativeTo(
  currentPose)`` as ``(x, y, theta)``, ``u = K(v_ref) e``, output ``(v_ref + u_0, w_ref + u_1)``.
* ``wpimath/src/main/native/include/frc/controller/LTVUnicycleController.h`` -
  ``maxVelocity = 9_mps`` by default; the table is a ``wpi::interpolating_map``.
* ``wpiutil/src/main/native/include/wpi/interpolating_map.h`` - ``operator[]``: the first
  key above the query (``upper_bound``); below the smallest key its value, above the
  largest the largest's, else linear interpolation between the two neighbours.
* ``wpimath/src/main/native/include/frc/StateSpaceUtil.h`` - ``MakeCostMatrix``: diagonal
  ``1 / tolerance^2`` (Bryson's rule).
* ``wpimath/src/main/native/include/frc/system/Discretization.h`` - ``DiscretizeAB``:
  ``expm([[A, B], [0, 0]] dt) = [[A_d, B_d], [0, I]]``.
* ``wpimath/src/main/native/include/frc/controller/LinearQuadraticRegulator.h`` -
  ``LatencyCompensate(plant, dt, inputDelay)``: ``K = K (A_d - B_d K)^(inputDelay / dt)``
  ("compute the control based on where the system will be after the time delay"; its
  derivation: Controls Engineering in FRC, appendix C.4).  The user-facing documentation
  of the fix: frc-docs ``source/docs/software/advanced-controls/state-space/
  state-space-intro.rst``, section "LQR and Measurement Latency Compensation"
  (``K_compensated = K (A - BK)^(delay / dt)``; "multiplying K by A - BK essentially
  advances the gains by one timestep").
* ``wpimath/src/main/native/include/frc/controller/RamseteController.h`` - the default
  constructor's ``b = 2.0`` rad^2/m^2 and ``zeta = 0.7`` 1/rad ("well-tested to produce
  desirable results"); ``Calculate``: ``e = poseRef.RelativeTo(currentPose)``,
  ``k = 2 zeta sqrt(w_ref^2 + b v_ref^2)``, ``v = v_ref cos(e_theta) + k e_x``,
  ``w = w_ref + k e_theta + b v_ref sinc(e_theta) e_y`` (``sinc(x) = sin x / x``,
  ``1 - x^2 / 6`` below 1e-9 rad).  WPILib 2026 marks it deprecated in favour of the LTV.
* ``dt``: the constructor's "discretization timestep", the period the controller runs at.
  WPILib robot code runs every 20 ms (``wpilibc/src/main/native/include/frc/TimedRobot.h``:
  ``kDefaultPeriod = 20_ms``; ``wpilibjExamples/.../simpledifferentialdrivesimulation/
  Robot.java`` constructs ``new LTVUnicycleController(0.020)``): on a 50 Hz base that is the
  odometry period the loop here runs at, and on a 20 Hz base the loop runs every 50 ms, so
  ``dt`` is the odometry period (0.02 s at 50 Hz, as the issue's table; 0.05 s at 20 Hz).

The reference each peer is given (WPILib's ``Trajectory::State``: pose, velocity,
curvature): the pose ``(x, y, heading)`` with the trajectory's heading (the direction of
travel, reversed when the trajectory drives backwards, ``RefSample.heading``), the signed
speed along it ``v_ref = (vx, vy) . (cos h, sin h)`` and ``w_ref = v_ref kappa`` from the
curvature of ``(vx, vy, ax, ay)``: ``w_ref = (vx ay - vy ax) / (vx^2 + vy^2)`` (0 at rest).
The output is the wpimath ``ChassisSpeeds`` as ``Command(v=vx, w=omega)``.
"""
from __future__ import annotations

import bisect
import copy
import math
from functools import lru_cache
from typing import Any

import numpy as np
from wpimath.controller import (LinearQuadraticRegulator_3_2, LTVUnicycleController,
                                RamseteController)
from wpimath.geometry import Pose2d, Rotation2d
from wpimath.system import LinearSystem_3_2_1

from nonfragile_tracker.control.simulation.tracker import Command
from nonfragile_tracker.control.simulation.plant import PlantConfig, odometry_period_steps
from nonfragile_tracker.control.simulation.reference import RefSample
from nonfragile_tracker.control.simulation.timing import PeriodEstimator

__all__ = ['PEERS', 'VARIANTS', 'LTV_Q', 'LTV_R', 'LTV_DT', 'LTV_MAX_VELOCITY', 'RAMSETE_B',
           'RAMSETE_ZETA', 'reference_twist', 'table_keys', 'ltv_gain', 'LTVUnicycle',
           'LTVLatencyCompensated', 'Ramsete', 'loop_period']

#: LTVUnicycleController.cpp: the default Q tolerances (x m, y m, heading rad).
LTV_Q = (0.0625, 0.125, 2.0)
#: LTVUnicycleController.cpp: the default R tolerances (v m/s, w rad/s).
LTV_R = (1.0, 2.0)
#: The default discretisation step: WPILib's 20 ms robot loop (see the module doc).
LTV_DT = 0.02
#: LTVUnicycleController.h: the gain table's default maxVelocity (m/s).
LTV_MAX_VELOCITY = 9.0
#: LTVUnicycleController.cpp: the table's velocity step (m/s).
LTV_TABLE_STEP = 0.01
#: LTVUnicycleController.cpp: the velocity below which A's v entry is held at 1e-4.
LTV_MIN_V = 1e-4
#: RamseteController.h: the default constructor's b (rad^2/m^2) and zeta (1/rad).
RAMSETE_B, RAMSETE_ZETA = 2.0, 0.7


def reference_twist(ref: RefSample) -> tuple[float, float, float, float, float]:
    """``(x, y, heading, v_ref, w_ref)`` of a reference sample, as a WPILib trajectory state.

    Parameters
    ----------
    ref : RefSample
        The reference sample.

    Returns
    -------
    tuple of 5 float
        Pose (m, m, rad), signed speed along the heading (m/s), yaw rate (rad/s).
    """
    h = ref.heading
    vx, vy = ref.vx, ref.vy
    s2 = vx * vx + vy * vy
    v_ref = vx * math.cos(h) + vy * math.sin(h)
    w_ref = (vx * ref.ay - vy * ref.ax) / s2 if s2 > 1e-12 else 0.0
    return ref.x, ref.y, h, v_ref, w_ref


def loop_period(plant_config: PlantConfig | None) -> float:
    """The period (s) the loop runs at on a base: its odometry period (default 0.02 s)."""
    if plant_config is None:
        return LTV_DT
    n, _ = odometry_period_steps(plant_config.odom_rate, plant_config.dt)
    return n * plant_config.dt


class _WpilibPeer:
    """The Controller protocol around a wpimath ``Calculate(current, ref, v_ref, w_ref)``."""

    name = 'wpilib'

    def __init__(self) -> None:
        self.timing = PeriodEstimator()

    @property
    def horizon(self) -> float:
        """0: the reference at the measurement's time (WPILib samples it there)."""
        return 0.0

    def reset(self, v: float | None = None) -> None:
        """Stateless laws: nothing to forget (``v`` unused)."""

    def __deepcopy__(self, memo: dict) -> '_WpilibPeer':
        """A copy sharing the wpimath object (which cannot be copied; the laws keep no state
        in it but the last pose error, which only ``AtReference`` reads): the bag replay and
        the input rules copy a controller to try a step."""
        new = copy.copy(self)
        for key, val in self.__dict__.items():
            if not key.startswith(('_ltv', '_ramsete')):
                setattr(new, key, copy.deepcopy(val, memo))
        return new

    def _calculate(self, current: Pose2d, ref: Pose2d, v_ref: float, w_ref: float
                   ) -> tuple[float, float]:
        raise NotImplementedError

    def step(self, x: float, y: float, th: float, ref: RefSample,
             measured_speed: float | None = None, stamp: float | None = None,
             stamp_ns: int | None = None, measured_rate: float | None = None) -> Command:
        """The wpimath law's ``(v, w)`` for the measured pose and the reference sample."""
        t = ref.t if stamp is None else float(stamp)
        t_ns = int(stamp_ns) if stamp_ns is not None else (
            int(round(t * 1e9)) if math.isfinite(t) else None)
        if t_ns is not None and self.timing.last_ns != t_ns:
            self.timing.observe_ns(t_ns)
        rx, ry, rh, v_ref, w_ref = reference_twist(ref)
        v, w = self._calculate(Pose2d(x, y, Rotation2d(th)), Pose2d(rx, ry, Rotation2d(rh)),
                               v_ref, w_ref)
        return Command(v=v, w=w)


@lru_cache(maxsize=None)
def _stock_ltv(dt: float) -> LTVUnicycleController:
    # stateless but for the last pose error (read by AtReference only): one per dt is shared
    return LTVUnicycleController(dt)


class LTVUnicycle(_WpilibPeer):
    """``wpimath.controller.LTVUnicycleController(dt)``: the stock tolerances and table."""

    name = 'WPILib LTV'

    def __init__(self, dt: float = LTV_DT):
        super().__init__()
        self.dt = float(dt)
        self._ltv = _stock_ltv(self.dt)

    def _calculate(self, current: Pose2d, ref: Pose2d, v_ref: float, w_ref: float
                   ) -> tuple[float, float]:
        s = self._ltv.calculate(current, ref, v_ref, w_ref)
        return s.vx, s.omega


@lru_cache(maxsize=None)
def table_keys(max_velocity: float = LTV_MAX_VELOCITY) -> tuple[float, ...]:
    """The velocities of LTVUnicycleController's gain table (accumulated as its loop does)."""
    keys = []
    v = -max_velocity
    while v < max_velocity:
        keys.append(v)
        v += LTV_TABLE_STEP
    return tuple(keys)


@lru_cache(maxsize=None)
def ltv_gain(v: float, dt: float, latency: float = 0.0, q: tuple[float, ...] = LTV_Q,
             r: tuple[float, ...] = LTV_R) -> np.ndarray:
    """LTVUnicycleController's gain at table velocity ``v``, latency-compensated for ``latency``.

    ``LinearQuadraticRegulator_3_2(A, B, Q, R, dt)`` on the robot-frame model of
    LTVUnicycleController.cpp, then (``latency > 0``) its ``latencyCompensate`` on the plant
    ``(A, B)`` (its ``C``, ``D`` do not enter): ``K (A_d - B_d K)^(latency / dt)``.

    Parameters
    ----------
    v : float
        A table velocity (m/s).
    dt : float
        Discretisation step (s).
    latency : float
        The input delay compensated (s); 0 = the stock gain.
    q, r : tuple of float
        Q and R tolerances (WPILib's defaults).

    Returns
    -------
    numpy.ndarray, shape (2, 3)
    """
    A = np.zeros((3, 3))
    A[1, 2] = LTV_MIN_V if abs(v) < LTV_MIN_V else v
    B = np.array([[1.0, 0.0], [0.0, 0.0], [0.0, 1.0]])
    lqr = LinearQuadraticRegulator_3_2(A, B, tuple(q), tuple(r), dt)
    if latency > 0.0:
        # only A and B enter the compensation (the wheel binds the 1- and 2-output plants)
        plant = LinearSystem_3_2_1(A, B, np.array([[1.0, 0.0, 0.0]]), np.zeros((1, 2)))
        lqr.latencyCompensate(plant, dt, latency)
    K = np.array(lqr.K(), dtype=float)
    K.setflags(write=False)
    return K


class LTVLatencyCompensated(_WpilibPeer):
    """LTVUnicycleController's law with each table gain latency-compensated (WPILib's fix).

    Parameters
    ----------
    latency : float
        The command latency compensated (s): the base's.
    dt : float
        Discretisation step (s).
    """

    name = 'WPILib LTV + latency comp.'

    def __init__(self, latency: float, dt: float = LTV_DT):
        super().__init__()
        self.latency = float(latency)
        self.dt = float(dt)
        self._keys = table_keys()

    def gain(self, v: float) -> np.ndarray:
        """The interpolated table gain at ``v`` (``wpi::interpolating_map::operator[]``)."""
        keys = self._keys
        i = bisect.bisect_right(keys, v)            # upper_bound
        if i == len(keys):
            return ltv_gain(keys[-1], self.dt, self.latency)
        if i == 0:
            return ltv_gain(keys[0], self.dt, self.latency)
        lo, hi = keys[i - 1], keys[i]
        d = (v - lo) / (hi - lo)
        return d * ltv_gain(hi, self.dt, self.latency) + (1.0 - d) * ltv_gain(
            lo, self.dt, self.latency)

    def _calculate(self, current: Pose2d, ref: Pose2d, v_ref: float, w_ref: float
                   ) -> tuple[float, float]:
        e = ref.relativeTo(current)
        K = self.gain(v_ref)
        ex, ey, et = e.X(), e.Y(), e.rotation().radians()
        return (v_ref + K[0, 0] * ex + K[0, 1] * ey + K[0, 2] * et,
                w_ref + K[1, 0] * ex + K[1, 1] * ey + K[1, 2] * et)


class Ramsete(_WpilibPeer):
    """``wpimath.controller.RamseteController()``: the stock ``b = 2``, ``zeta = 0.7``."""

    name = 'WPILib RAMSETE'

    def __init__(self) -> None:
        super().__init__()
        self._ramsete = RamseteController()

    def _calculate(self, current: Pose2d, ref: Pose2d, v_ref: float, w_ref: float
                   ) -> tuple[float, float]:
        s = self._ramsete.calculate(current, ref, v_ref, w_ref)
        return s.vx, s.omega


def ltv(tracker_config: Any, *, plant_config: PlantConfig | None = None) -> LTVUnicycle:
    """Factory: the stock LTV at the base's loop period."""
    return LTVUnicycle(loop_period(plant_config))


def ltv_latency(tracker_config: Any, *, plant_config: PlantConfig | None = None
                ) -> LTVLatencyCompensated:
    """Factory: the LTV compensated for the base's command latency (WPILib's fix)."""
    latency = plant_config.cmd_latency if plant_config is not None else 0.0
    return LTVLatencyCompensated(latency, loop_period(plant_config))


def ramsete(tracker_config: Any, *, plant_config: PlantConfig | None = None) -> Ramsete:
    """Factory: the stock RAMSETE (``plant_config`` unused: RAMSETE has no step or latency)."""
    return Ramsete()


#: The peers of this module, as the table driver picks them up (see the package doc).
PEERS = {'WPILib LTV': ltv, 'WPILib LTV + latency comp.': ltv_latency,
         'WPILib RAMSETE': ramsete}
#: The ones a user sets up per base (not as the library ships them): the latency fix.
VARIANTS = ('WPILib LTV + latency comp.',)
