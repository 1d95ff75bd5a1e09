"""Step functions (plant, tracker) and the simulations built from them."""
import math

import numpy as np
import pytest

from nonfragile_tracker.control.simulation.errors import LoopConfigError
from nonfragile_tracker.control.simulation.plant import PlantConfig, UnicyclePlant, delay_steps
from nonfragile_tracker.control.simulation.tracker import Tracker, TrackerConfig, validate_gain
from nonfragile_tracker.control.simulation.model import quaternion_to_yaw, yaw_to_quaternion
from nonfragile_tracker.control.simulation.timing import step_time
from nonfragile_tracker.control.simulation.model import double_integrator_model
from nonfragile_tracker.control.simulation.reference import (RefSample, circle, figure_eight,
                                                             make_path, PathError)
from nonfragile_tracker.control.simulation.simulate import simulate_delay_loop, simulate_tracking
from nonfragile_tracker.interface.scenario import paper_plant_config

K_NF = [[-4.4453, -4.8047, -1.4766, -1.5234], [-1.4766, -1.5234, -4.4453, -4.8047]]
NO_DELAY = dict(A_tau=np.zeros((4, 4)), tau=0.0)


def test_plant_integrates_arcs_exactly():
    p = UnicyclePlant(PlantConfig(x0=0.0, y0=0.0, th0=0.0, v0=0.0, dt=0.1, **NO_DELAY))
    for _ in range(10):
        p.step(1.0, 0.5)                      # radius 2 m, 1 s
    assert p.x == pytest.approx(2 * math.sin(0.5), abs=1e-14)
    assert p.y == pytest.approx(2 * (1 - math.cos(0.5)), abs=1e-14)
    assert p.th == pytest.approx(0.5, abs=1e-14) and p.k == 10 and p.t == pytest.approx(1.0)


def test_plant_delay_term_matches_delay_equation():
    """At rest the plant's x obeys x' = 0.01 x(t - 0.2): compare with RK4 of the same DDE."""
    p = UnicyclePlant(paper_plant_config(x0=1.0, y0=2.0, th0=0.3, v0=0.0, dt=0.001))
    for _ in range(20000):
        p.step(0.0, 0.0)
    ref = simulate_delay_loop(np.zeros((4, 4)), np.array(p.config.A_tau), 0.2,
                              [1.0, 0.0, 2.0, 0.0], 20.0, dt=0.001)
    assert p.x == pytest.approx(ref.xi[-1, 0], rel=1e-4)
    assert p.y == pytest.approx(ref.xi[-1, 2], rel=1e-4)
    assert p.x > 1.2          # the delayed term really drives the position (e^{~0.2} growth)


def test_delay_steps_rounding():
    assert delay_steps(0.2, 0.01) == (20, pytest.approx(0.2))
    n, eff = delay_steps(0.2049, 0.01)
    assert n == 20 and eff == pytest.approx(0.2)
    with pytest.raises(LoopConfigError, match='tau must be a finite number >= 0'):
        delay_steps(-1.0, 0.01)


def test_quaternion_helpers():
    for th in np.linspace(-3.1, 3.1, 13):
        assert quaternion_to_yaw(*yaw_to_quaternion(th)) == pytest.approx(th, abs=1e-15)
    x, y, z, w = yaw_to_quaternion(0.7)
    assert quaternion_to_yaw(2 * x, 2 * y, 2 * z, 2 * w) == pytest.approx(0.7)


def test_linearized_error_dynamics_without_delay():
    """With A_tau = 0 the nonlinear loop's error follows e' = (A + B K) e (first order in dt)."""
    K = np.array(K_NF)
    mdl = double_integrator_model()
    path = circle(rate=0.2)
    errs = []
    for dt in (1e-3, 5e-4):
        pc = PlantConfig(x0=0.52, y0=0.01, th0=math.pi / 2, v0=0.1, dt=dt, **NO_DELAY)
        run = simulate_tracking(pc, TrackerConfig(K=K, dt=dt, max_angular_speed=100), path,
                                int(round(10 / dt)))
        e = np.stack([run.x - run.xd, run.speed * np.cos(run.th) - run.vxd, run.y - run.yd,
                      run.speed * np.sin(run.th) - run.vyd], 1)
        lin = simulate_delay_loop(mdl.A + mdl.B @ K, np.zeros((4, 4)), 0.0, e[0], 10.0, dt=dt)
        errs.append(np.abs(e[:, [0, 2]] - lin.xi[:, [0, 2]]).max())
        assert np.abs(e[0, [0, 2]]).max() > 0.01      # a real transient is being compared
    assert errs[0] < 1e-5 and errs[1] == pytest.approx(errs[0] / 2, rel=0.1)


def test_tracker_limits_and_floor():
    cfg = TrackerConfig(K=K_NF, max_linear_speed=0.3, max_angular_speed=0.5, min_speed=0.01)
    tr = Tracker(cfg)
    rng = np.random.default_rng(0)
    for _ in range(2000):
        ref = RefSample(0.0, *rng.normal(scale=5, size=6), 0.0)
        cmd = tr.step(*rng.normal(scale=5, size=2), rng.uniform(-4, 4), ref,
                      measured_speed=rng.normal())
        assert abs(cmd.v) <= 0.3 and abs(cmd.w) <= 0.5
        assert math.isfinite(cmd.v) and math.isfinite(cmd.w)
    tr = Tracker(cfg)
    cmd = tr.step(1.0, 0.0, 0.0, RefSample(0, 0, 0, 0, 0, 0, 0, 0), measured_speed=0.0)
    assert cmd.floored


def test_validate_gain_messages():
    with pytest.raises(LoopConfigError, match='has 7 entries; a 2x4 gain needs 8'):
        validate_gain(list(range(7)))
    with pytest.raises(LoopConfigError, match=r'K\[0\]\[1\] is nan'):
        validate_gain([[0, float('nan'), 0, 0], [0] * 4])
    with pytest.raises(LoopConfigError, match='does not stabilize the nominal loop'):
        validate_gain([[1.0, 1.0, 0, 0], [0, 0, 1.0, 1.0]])
    assert validate_gain(K_NF).shape == (2, 4)


def test_paper_scenario_steady_band_and_compensation():
    """Paper K_nf, 100 Hz, one period: a ~1 cm bias without compensation, < 0.1 mm with it."""
    pc = paper_plant_config()
    steps = 62832                                   # 2 pi / 0.01 rad/s at dt = 0.01 s
    plain = simulate_tracking(pc, TrackerConfig(K=K_NF), circle(), steps)
    comp = simulate_tracking(pc, TrackerConfig(K=K_NF, delay_compensation=True,
                                               A_tau=pc.A_tau, tau=pc.tau), circle(), steps)
    err = plain.error[plain.t > 20]
    assert 0.004 < err.min() and err.max() < 0.013           # persistent bias of 4..13 mm
    m = comp.metrics()
    assert m.settling_time < 4.0 and comp.error[comp.t > 20].max() < 1e-4
    assert m.peak_abs_w <= 2.0 + 1e-12


def test_paths():
    c = circle()
    s = c.sample(0.0)
    assert (s.x, s.y, s.vx, s.vy) == pytest.approx((0.5, 0, 0, 0.005))
    assert s.heading == pytest.approx(math.pi / 2)         # tangent, not the paper's t
    f = figure_eight(radius=1.0, rate=0.5)
    h = 1e-6
    a, b = f.sample(1.0), f.sample(1.0 + h)
    assert (b.x - a.x) / h == pytest.approx(a.vx, rel=1e-5)
    assert (b.vy - a.vy) / h == pytest.approx(a.ay, rel=1e-5)
    with pytest.raises(PathError, match="unknown path 'square'"):
        make_path('square')
    with pytest.raises(PathError, match='radius must be > 0'):
        circle(radius=0.0)
    with pytest.raises(PathError, match='path parameter rate: expected a number, got True'):
        circle(rate=True)
    with pytest.raises(PathError, match='center_x: expected a finite number'):
        circle(center_x=float('nan'))


def test_step_time_is_integer_nanoseconds():
    assert step_time(3, 0.01) == 30_000_000 * 1e-9
