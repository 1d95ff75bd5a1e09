"""The WPILib peers (benchmarks/peers/wpilib.py) against their sources, and the one adapter.

Each port is checked against cases computed by hand from the formulas of its source file
(allwpilib v2026.2.2, cited in the module): RAMSETE's ``k = 2 zeta sqrt(w^2 + b v^2)`` law
on given errors, LTVUnicycleController's gain from the DARE (the decoupled x channel in
closed form, the whole gain against scipy's DARE), WPILib's latency compensation
``K (A_d - B_d K)^(L / dt)``, and the port of the LTV law against wpimath's own class.  The
adapter: ours and a peer given the very same inputs on the same run, and the same clamps.
"""
from __future__ import annotations

import importlib.util
import math
import sys

import numpy as np
import pytest
import scipy.linalg as sla

from conftest import ROOT

# robotpy-wpimath is in requirements.txt (benchmark/test-only): missing, these tests fail at
# collection instead of skipping (a skipped port would pass unseen)
import wpimath  # noqa: E402, F401
if str(ROOT / 'benchmarks') not in sys.path:
    sys.path.insert(0, str(ROOT / 'benchmarks'))

from peers import adapter, wpilib as W  # noqa: E402

from nonfragile_tracker.control.simulation.gains import read_gain_file  # noqa: E402
from nonfragile_tracker.control.simulation.tracker import Command, TrackerConfig  # noqa: E402
from nonfragile_tracker.control.simulation.reference import RefSample, figure_eight  # noqa: E402
from nonfragile_tracker.control.simulation.trajectory import Trajectory  # noqa: E402


def ref_sample(x, y, h, v, w, t=0.0):
    """A reference at ``(x, y)`` heading ``h`` with speed ``v`` (signed) turning at ``w``.

    Velocity ``v (cos h, sin h)``, centripetal acceleration ``v w (-sin h, cos h)``: then
    ``(vx ay - vy ax) / (vx^2 + vy^2) = w`` (the peers' ``w_ref``).
    """
    c, s = math.cos(h), math.sin(h)
    return RefSample(t, x, y, v * c, v * s, -v * w * s, v * w * c, h)


# ----------------------------------------------------------------------- the reference given

def test_reference_twist_forwards_and_backwards():
    x, y, h, v, w = W.reference_twist(ref_sample(1.0, 2.0, 0.3, 0.4, -0.5))
    assert (x, y, h) == (1.0, 2.0, 0.3)
    assert v == pytest.approx(0.4, abs=1e-15) and w == pytest.approx(-0.5, abs=1e-15)
    # driving backwards: the heading is opposite to the velocity (RefSample.heading of a
    # reversed trajectory); the speed along it is negative, the yaw rate is the velocity's
    back = RefSample(0.0, 0.0, 0.0, -0.3, 0.0, 0.0, -0.3 * 0.2, 0.0)
    _, _, h, v, w = W.reference_twist(back)
    assert h == 0.0 and v == pytest.approx(-0.3, abs=1e-15)
    assert w == pytest.approx((-0.3 * -0.06) / 0.09, abs=1e-15)       # = 0.2 rad/s
    assert W.reference_twist(RefSample(0.0, 1.0, 1.0, 0.0, 0.0, 0.3, 0.3, 0.7))[3:] == (0.0, 0.0)


# ----------------------------------------------------------------------- RAMSETE

def test_ramsete_defaults_and_law_on_a_hand_computed_error():
    assert (W.RAMSETE_B, W.RAMSETE_ZETA) == (2.0, 0.7)
    # robot at the origin facing +x; reference 0.1 m ahead, 0.05 m left, 0.2 rad more
    # v_ref = 0.5 m/s, w_ref = 0.3 rad/s:
    #   k = 2 * 0.7 * sqrt(0.3^2 + 2 * 0.5^2) = 1.4 * sqrt(0.59) = 1.0753604047...
    #   v = 0.5 cos(0.2) + k 0.1 = 0.4900332889 + 0.1075360405 = 0.5975693294
    #   w = 0.3 + k 0.2 + 2 * 0.5 * sinc(0.2) * 0.05
    #     = 0.3 + 0.2150720809 + 0.9933466540 * 0.05 = 0.5647394136
    cmd = W.Ramsete().step(0.0, 0.0, 0.0, ref_sample(0.1, 0.05, 0.2, 0.5, 0.3))
    # 1e-10: the hand figures are rounded to 10 decimals
    assert cmd.v == pytest.approx(0.5975693294, abs=1e-10)
    assert cmd.w == pytest.approx(0.5647394136, abs=1e-10)


def test_ramsete_error_is_taken_in_the_robot_frame():
    # robot at (1, 2) facing +y; the reference 0.05 m further in +x, 0.1 m in +y, 0.1 rad
    # more: in the robot frame e = (0.1, -0.05, 0.1).  v_ref = 0.2, w_ref = 0:
    #   k = 1.4 * sqrt(2 * 0.04) = 0.3959797975
    #   v = 0.2 cos(0.1) + k 0.1 = 0.1990008331 + 0.0395979797 = 0.2385988128
    #   w = k 0.1 + 2 * 0.2 * sinc(0.1) * (-0.05) = 0.0395979797 - 0.0199666833 = 0.0196312964
    h = math.pi / 2
    cmd = W.Ramsete().step(1.0, 2.0, h, ref_sample(1.05, 2.1, h + 0.1, 0.2, 0.0))
    assert cmd.v == pytest.approx(0.2385988128, abs=1e-10)
    assert cmd.w == pytest.approx(0.0196312964, abs=1e-10)


# ----------------------------------------------------------------------- LTV gains

def _dare_gain(v, dt, q=W.LTV_Q, r=W.LTV_R):
    """LTVUnicycleController.cpp's gain by scipy: ZOH of (A(v), B), Bryson Q, R, the DARE."""
    A = np.zeros((3, 3))
    A[1, 2] = v
    B = np.array([[1.0, 0.0], [0.0, 0.0], [0.0, 1.0]])
    M = sla.expm(np.block([[A, B], [np.zeros((2, 5))]]) * dt)
    Ad, Bd = M[:3, :3], M[:3, 3:]
    Q, R = np.diag(1 / np.square(q)), np.diag(1 / np.square(r))
    S = sla.solve_discrete_are(Ad, Bd, Q, R)
    return np.linalg.solve(Bd.T @ S @ Bd + R, Bd.T @ S @ Ad), Ad, Bd


def test_ltv_defaults():
    assert W.LTV_Q == (0.0625, 0.125, 2.0) and W.LTV_R == (1.0, 2.0)
    assert W.LTV_DT == 0.02 and W.LTV_MAX_VELOCITY == 9.0
    keys = W.table_keys()
    # from -9 m/s in 0.01 m/s steps while below 9 m/s: 1801 keys (the last 8.99999...)
    assert len(keys) == 1801 and keys[0] == -9.0 and keys[-1] < 9.0 < keys[-1] + 0.01


@pytest.mark.numerical
def test_ltv_x_channel_gain_is_the_scalar_dare_in_closed_form():
    # x decouples: A_d = 1, B_d = dt, q = 1 / 0.0625^2 = 256, r = 1 / 1^2 = 1.  The scalar
    # DARE s = s - (s dt)^2 / (dt^2 s + r) + q gives dt^2 s^2 - q dt^2 s - q r = 0, so
    # s = q/2 + sqrt(q^2/4 + q r / dt^2) = 128 + sqrt(16384 + 640000) = 938.1753019...
    # and k = dt s / (dt^2 s + r) = 18.763506 / 1.375270 = 13.64350579...
    dt = 0.02
    s = 128.0 + math.sqrt(16384.0 + 640000.0)
    k = dt * s / (dt * dt * s + 1.0)
    assert k == pytest.approx(13.64350579, abs=1e-8)
    for v in (0.5, -0.3, 1.2):
        K = W.ltv_gain(v, dt)
        # both solve the same well-conditioned DARE; 1e-9 relative is far above round-off
        assert K[0, 0] == pytest.approx(k, rel=1e-9)
        assert abs(K[0, 1]) < 1e-9 and abs(K[0, 2]) < 1e-9 and abs(K[1, 0]) < 1e-9


@pytest.mark.numerical
@pytest.mark.parametrize('v', [0.5, 0.28, -0.4, 2.0])
def test_ltv_gain_is_the_dare_gain(v):
    K_ref, _, _ = _dare_gain(v, 0.02)
    # wpimath's DARE (structure-preserving doubling) and scipy's (QZ) agree to ~1e-13 on
    # this loop; 1e-9 relative to the largest entry leaves room for either solver's tolerance
    assert np.allclose(W.ltv_gain(v, 0.02), K_ref, rtol=0, atol=1e-9 * np.abs(K_ref).max())
    assert K_ref[1, 1] * v > 0          # the y error turns the robot towards the path


@pytest.mark.numerical
def test_stock_ltv_output_at_a_table_velocity_is_v_ref_plus_K_e():
    # at a table key the interpolating map returns that key's gain exactly
    v = W.table_keys()[950]
    assert v == pytest.approx(0.5, abs=1e-9)
    K, _, _ = _dare_gain(v, 0.02)
    h, w = 0.4, 0.25
    ref = ref_sample(1.0, 0.5, h, v, w)
    x, y, th = 0.96, 0.53, h - 0.05
    c, s = math.cos(th), math.sin(th)
    e = np.array([c * (1.0 - x) + s * (0.5 - y), -s * (1.0 - x) + c * (0.5 - y), 0.05])
    u = K @ e
    cmd = W.LTVUnicycle(0.02).step(x, y, th, ref)
    # tolerance: the gains agree to 1e-9 (above) times |e| < 0.1 m plus round-off
    assert cmd.v == pytest.approx(v + u[0], abs=1e-9)
    assert cmd.w == pytest.approx(w + u[1], abs=1e-9)


# ----------------------------------------------------------------------- latency compensation

@pytest.mark.numerical
def test_latency_compensated_gain_is_K_times_closed_loop_power():
    dt, L = 0.02, 0.1                                   # L / dt = 5
    K, Ad, Bd = _dare_gain(0.5, dt)
    Kc = K @ np.linalg.matrix_power(Ad - Bd @ K, 5)
    assert np.allclose(W.ltv_gain(0.5, dt, L), Kc, rtol=0, atol=1e-9 * np.abs(Kc).max())
    # the x channel by hand: k (1 - dt k)^5 = 13.6435 * 0.727130^5 = 2.773230...
    k = W.ltv_gain(0.5, dt)[0, 0]
    assert W.ltv_gain(0.5, dt, L)[0, 0] == pytest.approx(k * (1 - dt * k) ** 5, rel=1e-12)
    assert W.ltv_gain(0.5, dt, L)[0, 0] == pytest.approx(2.77323, abs=1e-5)


@pytest.mark.numerical
def test_latency_compensation_with_a_fractional_power():
    dt, L = 0.05, 0.04                                  # a 20 Hz loop: (A_d - B_d K)^0.8
    K, Ad, Bd = _dare_gain(0.3, dt)
    Kc = K @ np.real(sla.fractional_matrix_power(Ad - Bd @ K, L / dt))
    # Eigen's MatrixPower and scipy's Schur-Pade agree to ~1e-12 here; 1e-8 is generous
    assert np.allclose(W.ltv_gain(0.3, dt, L), Kc, rtol=0, atol=1e-8 * np.abs(Kc).max())


def test_ltv_port_without_latency_is_wpimaths_ltv():
    """The port (table, interpolation, law) gives wpimath's own LTV output on random cases."""
    rng = np.random.default_rng(38)
    stock, port = W.LTVUnicycle(0.02), W.LTVLatencyCompensated(0.0, 0.02)
    worst = 0.0
    for _ in range(300):
        v = rng.uniform(-2.0, 2.0)                      # between table keys: interpolated
        h = rng.uniform(-math.pi, math.pi)
        ref = ref_sample(rng.normal(), rng.normal(), h, v, rng.normal())
        x, y, th = ref.x + 0.1 * rng.normal(), ref.y + 0.1 * rng.normal(), h + 0.3 * rng.normal()
        a, b = stock.step(x, y, th, ref), port.step(x, y, th, ref)
        worst = max(worst, abs(a.v - b.v), abs(a.w - b.w))
    # the same gains (the same LQR code) and the same interpolation: round-off only
    assert worst < 1e-12


def test_factories_read_the_base():
    pc = adapter.base_plant(0.1, 20.0, 1)
    tc = TrackerConfig(K=read_gain_file(ROOT / 'config' / 'tracker_gains.yaml'))
    peer = W.ltv_latency(tc, plant_config=pc)
    assert (peer.latency, peer.dt) == (0.1, pytest.approx(0.05))
    assert W.ltv(tc, plant_config=adapter.base_plant(0.1, 50.0, 1)).dt == pytest.approx(0.02)
    assert W.ltv(tc).dt == 0.02
    assert set(W.PEERS) == {'WPILib LTV', 'WPILib LTV + latency comp.', 'WPILib RAMSETE'}


# ----------------------------------------------------------------------- the adapter

class _Scripted:
    """Drives the base open loop (the same commands whatever the controller says), after
    the adapted controller has been called with the loop's inputs."""

    def __init__(self, adapted):
        self.adapted = adapted
        self.timing = adapted.timing

    @property
    def horizon(self):
        return self.adapted.horizon

    def reset(self, v=None):
        self.adapted.reset(v)

    def step(self, x, y, th, ref, measured_speed=None, stamp=None, stamp_ns=None,
             measured_rate=None):
        self.adapted.step(x, y, th, ref, measured_speed, stamp=stamp, stamp_ns=stamp_ns,
                          measured_rate=measured_rate)
        t = ref.t if stamp is None else stamp
        return Command(v=0.25 + 0.05 * math.sin(0.7 * t), w=0.4 * math.sin(0.3 * t))


def _config():
    return TrackerConfig(K=read_gain_file(ROOT / 'config' / 'tracker_gains.yaml'))


def test_ours_and_a_peer_are_given_identical_inputs_on_the_same_run():
    # the realistic base with latency, noise, command jitter and 20 Hz odometry
    pc = adapter.base_plant(0.1, 20.0, 2, start=(0.0, -0.1, math.pi / 4, 0.0))
    traj = Trajectory.analytic(figure_eight(radius=1.0, rate=0.2))
    runs = {name: adapter.run(f, pc, _config(), traj, 12.0, record=True, wrap=_Scripted)
            for name, f in (('ours', adapter.OURS), ('ltv', W.ltv), ('ramsete', W.ramsete))}
    ours = runs['ours'].controller
    assert len(ours.inputs) == 12.0 * 20 + 1          # one call per odometry sample
    for name in ('ltv', 'ramsete'):
        peer = runs[name].controller
        assert peer.inputs == ours.inputs             # pose, reference, speed, stamps: bit for bit
        assert peer.resets == ours.resets
        assert np.array_equal(runs[name].run.x, runs['ours'].run.x)
    x, y, th, ref, v, stamp, _, rate = ours.inputs[0]
    assert (stamp, ref.t) == (0.0, 0.0) and abs(x) < 0.01 and abs(y + 0.1) < 0.01
    assert rate == 0.0                                 # the measured twist at rest
    # the reference each is given is the trajectory at the measurement's stamp
    assert all(r == traj.sample(s) for _, _, _, r, _, s, _, _ in ours.inputs)


def test_closed_loop_runs_share_the_stamps_references_and_first_measurement():
    pc = adapter.base_plant(0.04, 50.0, 1, start=(0.0, -0.1, math.pi / 4, 0.0))
    traj = Trajectory.analytic(figure_eight(radius=1.0, rate=0.2))
    a = adapter.run(adapter.OURS, pc, _config(), traj, 5.0, record=True).controller
    b = adapter.run(W.ltv, pc, _config(), traj, 5.0, record=True).controller
    assert [i[3:] for i in a.inputs][:1] == [i[3:] for i in b.inputs][:1]
    assert a.inputs[0] == b.inputs[0]
    assert [(i[3], i[5]) for i in a.inputs] == [(i[3], i[5]) for i in b.inputs]


class _Wild:
    def __init__(self, v, w):
        self.timing = None
        self.v, self.w = v, w

    horizon = 0.0

    def reset(self, v=None):
        pass

    def step(self, *args, **kwargs):
        return Command(v=self.v, w=self.w)


def test_every_controller_gets_the_same_clamps():
    tc = TrackerConfig(K=read_gain_file(ROOT / 'config' / 'tracker_gains.yaml'),
                       max_linear_speed=1.0, max_angular_speed=2.0)
    ref = ref_sample(0.0, 0.0, 0.0, 0.1, 0.0)
    c = adapter.Adapted(_Wild(5.0, -7.0), tc).step(0.0, 0.0, 0.0, ref)
    assert (c.v, c.w, c.saturated) == (1.0, -2.0, True)
    c = adapter.Adapted(_Wild(math.nan, 0.3), tc).step(0.0, 0.0, 0.0, ref)
    assert (c.v, c.w, c.saturated) == (0.0, 0.0, True)
    c = adapter.Adapted(_Wild(0.4, -0.3), tc).step(0.0, 0.0, 0.0, ref)
    assert (c.v, c.w, c.saturated) == (0.4, -0.3, False)


def test_score_of_a_run_on_the_figure_eight():
    pc = adapter.base_plant(0.0, 50.0, 1, start=(0.0, -0.1, math.pi / 4, 0.0))
    traj = Trajectory.analytic(figure_eight(radius=1.0, rate=0.2))
    pr = adapter.run(W.ltv, pc, _config(), traj, 20.0)
    s = adapter.score(pr)
    late = pr.run.t >= 10.0
    assert s.rms == pytest.approx(float(np.sqrt(np.mean(pr.run.error[late] ** 2))), rel=1e-12)
    # the stock LTV tracks the eight within a few mm at zero latency (benchmarks/peers_table.md)
    assert 1e-4 < s.rms < 3e-3 and not s.diverged
    assert s.cross_rms <= s.rms + 1e-12                # the path is nearer than the timed point
    assert math.isnan(s.lap_delta)                     # an endless path has no arrival
    assert s.saturated == 0.0 and s.compute_med_us > 0


def test_cross_track_distance_to_a_polyline():
    qx, qy = np.array([0.0, 1.0, 2.0]), np.array([0.0, 0.0, 1.0])
    d = adapter.cross_track(np.array([0.5, 1.5, -1.0]), np.array([0.2, 0.0, 0.0]), qx, qy)
    assert d == pytest.approx([0.2, math.sqrt(0.125), 1.0], abs=1e-15)


def test_the_table_driver_finds_the_peers_and_the_bring_up_residual():
    spec = importlib.util.spec_from_file_location('peers_driver', ROOT / 'benchmarks' /
                                                  'peers.py')
    drv = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(drv)
    found, _ = drv.discover_peers()
    assert {'WPILib LTV', 'WPILib LTV + latency comp.', 'WPILib RAMSETE'} <= set(found)
    # latency-design's rule with the predictor: [0, jitter 10 ms + odometry period]
    assert drv.residual_interval(adapter.base_plant(0.1, 50.0, 1)) == pytest.approx((0, 0.03))
    assert drv.residual_interval(adapter.base_plant(0.3, 20.0, 1)) == pytest.approx((0, 0.06))
    tc = drv.our_config(drv.OURS_DEFAULT, adapter.base_plant(0.1, 50.0, 1))
    assert not tc.predicts and not tc.rate_limited
    assert (tc.max_linear_speed, tc.max_angular_speed) == (1.0, 2.0)


def test_ahead_finds_the_cells_where_ours_is_behind():
    spec = importlib.util.spec_from_file_location('peers_driver', ROOT / 'benchmarks' /
                                                  'peers.py')
    drv = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(drv)

    def m(rms):
        return {'rms': rms}
    med = {(drv.OURS_BRINGUP, 'eight', 50.0, 0.0): m(0.002), ('A', 'eight', 50.0, 0.0): m(0.001),
           ('B', 'eight', 50.0, 0.0): m(0.004),
           (drv.OURS_BRINGUP, 'eight', 50.0, 0.1): m(0.002), ('A', 'eight', 50.0, 0.1): m(0.5),
           ('B', 'eight', 50.0, 0.1): m(0.008),
           (drv.OURS_DEFAULT, 'eight', 50.0, 0.0): m(0.009),      # 0 ms: not judged
           (drv.OURS_DEFAULT, 'eight', 50.0, 0.1): m(0.004)}
    t = {'med': med, 'controllers': [drv.OURS_DEFAULT, drv.OURS_BRINGUP, 'A', 'B'],
         'stock': ['B'], 'trajs': ['eight'], 'rates': [50.0], 'lats': [0.0, 0.1]}
    a = drv.ahead(t)
    # after bring-up: 2 mm against A's 1 mm at 0 ms (ratio 2), 2 against B's 8 at 100 ms
    assert a['bringup']['worst_ratio'] == pytest.approx(2.0)
    assert a['bringup']['behind'] == ['eight 50 Hz 0 ms: A 1.00 mm vs 2.00']
    # shipped: only from 40 ms, only against the stock peer B: 4 mm against 8 mm
    assert a['default'] == {'worst_ratio': pytest.approx(0.5), 'behind': []}


def test_the_driver_picks_up_any_peer_module_with_the_factory_shape(tmp_path, monkeypatch):
    """A sibling module (as Nav2's will be) with ``PEERS`` is a row; one that fails to import
    is skipped with the reason; a factory taking ``plant_config`` is given the base."""
    import peers as peer_pkg
    (tmp_path / 'zz_fake.py').write_text(
        'from peers.wpilib import Ramsete\n'
        'SEEN = []\n'
        'def fake(tracker_config, *, plant_config=None):\n'
        '    SEEN.append(plant_config)\n'
        '    return Ramsete()\n'
        "PEERS = {'fake peer': fake}\n")
    (tmp_path / 'zz_broken.py').write_text('import a_library_that_is_not_installed\n')
    monkeypatch.setattr(peer_pkg, '__path__', [*peer_pkg.__path__, str(tmp_path)])
    spec = importlib.util.spec_from_file_location('peers_driver', ROOT / 'benchmarks' /
                                                  'peers.py')
    drv = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(drv)
    found, skipped = drv.discover_peers()
    assert found['fake peer'] == ('peers.zz_fake', 'fake peer')
    assert 'zz_broken' in skipped and 'a_library_that_is_not_installed' in skipped['zz_broken']
    pc = adapter.base_plant(0.1, 50.0, 1)
    mod = sys.modules['peers.zz_fake']
    adapter.bind(mod.fake, pc)(_config())
    assert mod.SEEN == [pc]
    for name in ('peers.zz_fake', 'peers.zz_broken'):
        sys.modules.pop(name, None)


def test_the_input_rules_clamp_a_peer_as_the_node_does_and_a_peer_copies():
    """The node, its bag replay and an in-process run send a peer's command through the
    same input rules: they hold it within the speed limits (the LTV asks 12 m/s 0.9 m
    behind its reference; before, only the node's publisher clamped it, so a replay of a
    peer's run differed by 11 m/s), and they copy the law to try a step (the LTV holds a
    wpimath object that cannot be copied: the replay stopped with a TypeError)."""
    import copy
    from nonfragile_tracker.control.simulation.wrappers import Clamped, clamp_command
    from nonfragile_tracker.interface.tracker_inputs import TrackerInputs
    tc = TrackerConfig(K=read_gain_file(ROOT / 'config' / 'tracker_gains.yaml'),
                       max_linear_speed=1.0, max_angular_speed=2.0)
    inputs = TrackerInputs(tc, controller='peers.wpilib:ltv')
    assert isinstance(inputs.tracker, Clamped)
    ref = RefSample(0.0, 0.9, 0.0, 0.28, 0.0, 0.0, 0.0, 0.0)
    raw = inputs.tracker.law.step(0.0, 0.0, 0.0, ref, 0.0, stamp=0.0)
    cmd = inputs.tracker.step(0.0, 0.0, 0.0, ref, 0.0, stamp=0.0)
    assert raw.v > 5.0 and (cmd.v, cmd.saturated) == (1.0, True), (raw, cmd)
    assert clamp_command(raw.v, raw.w, 1.0, 2.0)[:2] == (cmd.v, cmd.w)
    assert clamp_command(math.nan, 0.1, 1.0, 2.0) == (0.0, 0.0, True)
    twin = copy.deepcopy(inputs.tracker)
    assert twin.step(0.0, 0.0, 0.0, ref, 0.0, stamp=0.0) == cmd
