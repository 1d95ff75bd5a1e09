"""The MuJoCo bases behind the plant seam (control/simulation/physics.py, config/bases/):
determinism, each base's static gains, creep and slip in the encoder odometry, the firmware's
limits and timeout, and tracking a figure eight on each base with our tracker, the skid-steer
only with its identified turn gain compensated.

MuJoCo (``mujoco-core``) is pinned in requirements.txt: without it these tests fail (the first
one says what to install), they do not skip.  Figures measured on this machine are in the
docstrings; the assertions leave room for round-off across CPUs, not for a changed model.
"""
from __future__ import annotations

import math
import re
import subprocess
import sys

import numpy as np
import pytest

from conftest import CONFIG, ROOT
from nonfragile_tracker.control.simulation import physics
from nonfragile_tracker.control.simulation.errors import LoopConfigError
from nonfragile_tracker.control.simulation.plant import PlantConfig
from nonfragile_tracker.control.simulation.tracker import TrackerConfig
from nonfragile_tracker.control.simulation.timing import step_time

BASES = tuple(physics.BASES)
SPEC = 'nonfragile_tracker.control.simulation.physics:{}'


def test_mujoco_core_is_installed_at_the_pinned_version():
    pin = re.search(r'^mujoco-core==(\S+)', (ROOT / 'requirements.txt').read_text(), re.M)
    assert pin, 'requirements.txt must pin mujoco-core'
    mujoco = physics.load_mujoco()        # fails here, naming the package, when it is missing
    assert mujoco.__version__ == pin.group(1)


def test_a_missing_mujoco_is_named_with_its_package(monkeypatch):
    monkeypatch.setitem(sys.modules, 'mujoco', None)       # import mujoco -> ImportError
    with pytest.raises(LoopConfigError, match='pip install mujoco-core'):
        physics.PhysicsPlant(PlantConfig(dt=0.01), 'turtlebot3')


def test_the_bases_are_installed_and_named_by_the_seam():
    from nonfragile_tracker.control.simulation.interfaces import Plant, make_plant
    setup = (ROOT / 'setup.py').read_text()
    assert "'/config/bases', glob('config/bases/*.xml')" in setup
    assert "+ glob('config/bases/*.yaml')" in setup
    assert sorted(p.name for p in (CONFIG / 'bases').glob('*.xml')) == sorted(
        physics.BASES.values())
    import yaml
    for base in BASES:               # a scenario per base names it as the plant's model
        scenario = yaml.safe_load((CONFIG / 'bases' / f'{base}.yaml').read_text())
        assert scenario['/**/plant']['ros__parameters']['model'] == SPEC.format(base)
    for base in BASES:
        plant = make_plant(PlantConfig(dt=0.01), SPEC.format(base))
        assert isinstance(plant, physics.PhysicsPlant) and isinstance(plant, Plant)
        assert plant.path == CONFIG / 'bases' / physics.BASES[base]
        assert plant.substeps == 5 and plant.h == 0.002


@pytest.mark.parametrize('config, words', [
    (PlantConfig(dt=0.01, lag_v=0.05), 'lag_v'),
    (PlantConfig(dt=0.01, max_angular_accel=1.0), 'max_angular_accel'),
    (PlantConfig(dt=0.01, tau=0.1, A_tau=[[0, 0, 0, 0], [0.1, 0, 0, 0], [0, 0, 0, 0],
                                          [0, 0, 0.1, 0]]), 'A_tau, tau'),
    (PlantConfig(dt=0.005), 'multiple of the base\'s timestep 0.002'),
])
def test_what_a_physics_base_cannot_do_is_refused(config, words):
    with pytest.raises(LoopConfigError, match=re.escape(words)):
        physics.PhysicsPlant(config, 'turtlebot3')


def test_an_unknown_base_is_refused_with_the_names():
    with pytest.raises(LoopConfigError, match='jackal_skid'):
        physics.PhysicsPlant(PlantConfig(dt=0.01), 'husky')


# -- determinism ------------------------------------------------------------------------------

#: A run's trace: the command sequence of :func:`_trace`, hashed (run here and in a fresh
#: interpreter).
TRACE = '''
import hashlib, math
import numpy as np
from nonfragile_tracker.control.simulation.physics import PhysicsPlant
from nonfragile_tracker.control.simulation.plant import PlantConfig
def trace(base):
    p = PhysicsPlant(PlantConfig(dt=0.01, cmd_latency=0.03, odom_rate=50.0,
                                 odom_noise=(0.001, 0.001, 0.002), noise_seed=4), base)
    rows = []
    for k in range(150):
        s = p.odometry()
        if k % 2 == 0:
            p.command(0.5 * p.spec.max_linear_speed * math.sin(0.05 * k), math.cos(0.07 * k))
        p.advance()
        rows.append((p.x, p.y, p.th, p.v, p.w, *p.odom_pose, *p.torque)
                    + (() if s is None else tuple(s)))
    return hashlib.sha256(np.array([x for r in rows for x in r]).tobytes()).hexdigest()
'''


@pytest.mark.parametrize('base', BASES)
def test_two_runs_are_bit_identical_in_and_across_processes(base):
    """Latency, decimated noisy odometry, a varying command: the true states, the encoder
    odometry, the torques and the samples hash the same twice in this process, once more
    after a reset of the same plant, and in a fresh interpreter."""
    ns: dict = {}
    exec(TRACE, ns)
    first, second = ns['trace'](base), ns['trace'](base)
    assert first == second
    out = subprocess.run([sys.executable, '-c', TRACE + f'print(trace({base!r}))'],
                         capture_output=True, text=True, cwd=ROOT, timeout=120,
                         env={'PYTHONPATH': str(ROOT), 'PATH': '/usr/bin:/bin'})
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == first


def test_reset_starts_the_same_run_again():
    plant = physics.PhysicsPlant(PlantConfig(dt=0.01, x0=1.0, y0=-0.5, th0=0.7), 'jackal')
    start = (plant.x, plant.y, plant.th, plant.odom_pose)
    runs = []
    for _ in range(2):
        plant.reset()
        assert (plant.x, plant.y, plant.th, plant.odom_pose) == start
        for _ in range(50):
            plant.command(0.8, 0.5)
            plant.advance()
        runs.append((plant.x, plant.y, plant.th, plant.v, plant.odom_pose))
    assert runs[0] == runs[1]
    assert math.hypot(start[0] - 1.0, start[1] + 0.5) < 1e-4 and abs(start[2] - 0.7) < 1e-6


# -- static gains -----------------------------------------------------------------------------

#: (base, v, w, v gain range, w gain range) at steady state, the true speeds over the
#: commanded (measured: turtlebot3 0.9997 / 0.9970 at (0.15, 0) and (0.1, 1.0); jackal
#: 0.9998 / 0.9999 at (1.0, 0) and (0.5, 1.0); jackal_skid 0.9985 and 0.65 at (1.0, 0) and
#: (0.5, 1.0), 0.62 turning on the spot).
STATIC = [
    ('turtlebot3', 0.15, 0.0, (0.995, 1.002), None),
    ('turtlebot3', 0.1, 1.0, (0.995, 1.002), (0.99, 1.005)),
    ('jackal', 1.0, 0.0, (0.995, 1.002), None),
    ('jackal', 0.5, 1.0, (0.995, 1.005), (0.995, 1.005)),
    ('jackal_skid', 1.0, 0.0, (0.995, 1.002), None),
    ('jackal_skid', 0.5, 1.0, (0.99, 1.01), (0.58, 0.70)),
    ('jackal_skid', 0.0, 1.0, None, (0.58, 0.70)),
]


@pytest.mark.parametrize('base, v, w, v_range, w_range', STATIC)
def test_each_base_reaches_its_static_gains(base, v, w, v_range, w_range):
    """The two-wheel bases move as commanded to a few parts in a thousand (creep, the tyre's
    rolling radius); the skid-steer turns at about 0.6 of its command (Clearpath configures
    1.5 as the Jackal's wheel_separation_multiplier): well below 1."""
    gv, gw = physics.static_gains(base, v, w)
    if v_range:
        assert v_range[0] <= gv <= v_range[1], gv
    if w_range:
        assert w_range[0] <= gw <= w_range[1], gw
    if base == 'jackal_skid' and w:
        assert gw < 0.75


# -- odometry: creep and slip -----------------------------------------------------------------

def _drive(plant, v, w, steps):
    for _ in range(steps):
        plant.command(v, w)
        plant.advance()
    return math.hypot(plant.odom_pose[0] - plant.x, plant.odom_pose[1] - plant.y)


@pytest.mark.parametrize('base, low, high', [('turtlebot3', 1e-4, 2e-3), ('jackal', 1e-4, 5e-3),
                                              ('jackal_skid', 2e-3, 0.1)])
def test_encoder_odometry_drifts_from_the_true_pose(base, low, high):
    """4 s on an arc: the odometry integrated from the encoder ticks is not the true pose
    (measured drift: turtlebot3 0.4 mm, jackal 0.9 mm from tyre creep; the skid-steer's
    body slides sideways in the turn: 21 mm), and the true pose is what the plant reports."""
    plant = physics.PhysicsPlant(PlantConfig(dt=0.01), base)
    drift = _drive(plant, 0.6 * min(plant.spec.max_linear_speed, 0.5), 0.8, 400)
    assert low < drift < high, drift
    sample = plant.odometry()
    assert sample is not None and (sample.x, sample.y, sample.th) == plant.odom_pose


def test_wheels_that_slip_make_the_odometry_run_away(tmp_path):
    """On a floor of friction 0.1 the two-wheel Jackal's 3 m/s^2 ramp to 2 m/s asks for more
    traction than there is: the wheels spin, the encoders count 2.23 m while the base moved
    0.67 m (on the shipped floor: 2.229 against 2.228 m)."""
    text = (CONFIG / 'bases' / 'jackal.xml').read_text()
    slippery = tmp_path / 'slippery.xml'
    slippery.write_text(text.replace('friction="1.0 0.005 0.0001"', 'friction="0.1 0.005 0.0001"'))
    runs = {}
    for name, path in (('grip', CONFIG / 'bases' / 'jackal.xml'), ('slip', slippery)):
        plant = physics.PhysicsPlant(PlantConfig(dt=0.01), path)
        _drive(plant, 2.0, 0.0, 150)
        runs[name] = (plant.x, plant.odom_pose[0])
    assert abs(runs['grip'][1] - runs['grip'][0]) < 0.005
    assert runs['slip'][1] > 2.0 and runs['slip'][0] < 1.0


# -- limits and timeout -----------------------------------------------------------------------

@pytest.mark.parametrize('base', BASES)
def test_no_acceleration_over_the_limits(base):
    """A step to 80 % of the top speed, a stop, turn steps to 2 and -2 rad/s: the firmware's
    setpoint ramps at the limits exactly and the true speed follows without overshooting
    them (its PI acts on the measurement; measured turtlebot3 1.75 of 2.5 m/s^2 - its motors
    limit it - jackal 3.000 of 3.0).  The skid-steer's yaw rate judders as its wheels skid
    (stick-slip): its angular acceleration is judged on 50 ms means (measured 5.2 of 6.0)."""
    plant = physics.PhysicsPlant(PlantConfig(dt=0.01), base)
    s = plant.spec
    rows = [(plant.v, plant.w, *plant.setpoint)]
    for k in range(400):
        v, w = ((0.8 * s.max_linear_speed, 0.0) if k < 100 else (0.0, 0.0) if k < 200
                else (0.0, 2.0) if k < 300 else (0.0, -2.0))
        plant.command(v, w)
        plant.advance()
        rows.append((plant.v, plant.w, *plant.setpoint))
    a = np.diff(np.array(rows), axis=0) / plant.dt
    assert np.abs(a[:, 2]).max() <= s.max_linear_accel * (1 + 1e-9)
    assert np.abs(a[:, 3]).max() <= s.max_angular_accel * (1 + 1e-9)
    assert np.abs(a[:, 0]).max() <= s.max_linear_accel * 1.001
    if base == 'jackal_skid':
        means = np.diff(np.array(rows)[::5, 1]) / (5 * plant.dt)
        assert np.abs(means).max() <= s.max_angular_accel
    else:
        assert np.abs(a[:, 1]).max() <= s.max_angular_accel * 1.001
    assert np.abs(np.array(rows)[:, 0]).max() <= s.max_linear_speed


@pytest.mark.parametrize('base', BASES)
def test_the_command_timeout_stops_the_base(base):
    """Commands every step for 1 s, then none: the base keeps going until its timeout
    (jackal 0.25 s, turtlebot3 0.5 s) and then ramps to rest; with 0.1 s of command
    latency the timeout counts from the last command's arrival."""
    for latency in (0.0, 0.1):
        plant = physics.PhysicsPlant(PlantConfig(dt=0.01, cmd_latency=latency), base)
        timeout = plant.spec.cmd_timeout
        v = 0.5 * plant.spec.max_linear_speed
        for _ in range(100):
            plant.command(v, 0.0)
            plant.advance()
        last = 99 + int(round(latency / plant.dt))          # the step the last one arrives
        while plant.k <= last + int(round(timeout / plant.dt)) - 1:
            assert not plant.timed_out and plant.setpoint[0] == v
            plant.advance()
        plant.advance()
        assert plant.timed_out and plant.setpoint[0] < v
        for _ in range(150):
            plant.advance()
        assert plant.timed_out and abs(plant.v) < 2e-3 and plant.setpoint == (0.0, 0.0)
        plant.command(v, 0.0)
        for _ in range(int(round(latency / plant.dt)) + 1):
            plant.advance()
        assert not plant.timed_out


def test_command_latency_and_stalls_are_the_transport_of_the_kinematic_plant():
    """A command acts exactly ``cmd_latency`` later (the setpoint's first move); during a
    stall the firmware brakes whatever it is sent, then follows the newest command."""
    moved = {}
    for latency in (0.0, 0.12):
        plant = physics.PhysicsPlant(PlantConfig(dt=0.01, cmd_latency=latency), 'turtlebot3')
        for k in range(30):
            plant.command(0.1, 0.0)
            plant.advance()
            if plant.setpoint[0] > 0 and latency not in moved:
                moved[latency] = k
    assert moved[0.12] - moved[0.0] == 12
    plant = physics.PhysicsPlant(PlantConfig(dt=0.01, stalls=((1.0, 0.5),)), 'jackal')
    speeds = []
    for _ in range(250):
        plant.command(1.0, 0.0)
        plant.advance()
        speeds.append(plant.v)
    assert speeds[99] > 0.99 and speeds[148] < 0.005 and speeds[240] > 0.99


# -- identification and tracking --------------------------------------------------------------

def _identify(base: str):
    """Step commands at 20 Hz for 20 s (random levels held 1 s), 50 Hz odometry, then
    ``identify_latency`` on what the base's odometry said, and the side slip from the true
    pose beside it (an external pose with 1 mm of noise: ``identify --truth``); the
    identification carries the side-slip table when it is significant."""
    from dataclasses import replace
    from nonfragile_tracker.control.identification.identify import (
        CommandSamples, OdometrySamples, identify_latency)
    from nonfragile_tracker.control.identification.slip import identify_side_slip
    plant = physics.PhysicsPlant(PlantConfig(dt=0.01, odom_rate=50.0), base)
    rng = np.random.default_rng(3)
    vmax = min(plant.spec.max_linear_speed, 1.0)
    levels = [(rng.uniform(0.1, 0.5) * vmax, rng.uniform(-1.0, 1.0)) for _ in range(20)]
    cmd, odom, truth = [], [], []
    for k in range(2000):
        sample = plant.odometry()
        if sample is not None:
            t = step_time(sample.step, plant.dt)
            odom.append((t, sample.x, sample.y, sample.th, sample.v, sample.w))
            truth.append((t, plant.x + rng.normal(0.0, 1e-3), plant.y + rng.normal(0.0, 1e-3),
                          plant.th))
        if k % 5 == 0:
            v, w = levels[k // 100]
            plant.command(v, w)
            cmd.append((step_time(k, plant.dt), v, w))
        plant.advance()
    c, o = np.array(cmd).T, np.array(odom).T
    ident = identify_latency(CommandSamples(*c), OdometrySamples(*o))
    slip = identify_side_slip(OdometrySamples(*o), OdometrySamples(*np.array(truth).T))
    if slip.significant:
        ident = replace(ident, side_slip_rates=slip.rates, side_slip=slip.coefficients)
    return ident, slip


@pytest.fixture(scope='module')
def identified_with_slip():
    """Each base identified once (about 2 s each), with its side slip."""
    return {base: _identify(base) for base in BASES}


@pytest.fixture(scope='module')
def identified(identified_with_slip):
    """Each base's identification."""
    return {base: pair[0] for base, pair in identified_with_slip.items()}


def test_identification_measures_the_skid_steers_turn_gain(identified):
    """From its own odometry (gyro heading) the skid-steer's turn gain is identified with
    its 95 % interval, which holds the truth at a mid-range command (measured 0.6405 in
    0.6345-0.6458, truth 0.6370 at (0.3 m/s, 0.5 rad/s)); the two-wheel bases' gains are 1
    (measured 1.000 / 1.002 and 1.000 / 1.006; the TurtleBot3's w interval, 1.0008-1.0133,
    misses its truth 1.000: its excitation nears the motors' no-load speed)."""
    skid = identified['jackal_skid']
    truth = physics.static_gains('jackal_skid', 0.3, 0.5)[1]
    assert 0.6 < skid.gain_w < 0.7 and abs(skid.gain_w - truth) < 0.04, (skid.gain_w, truth)
    assert skid.gain_w_low <= truth <= skid.gain_w_high, (skid.gain_w_low, truth,
                                                          skid.gain_w_high)
    assert skid.gain_w_high - skid.gain_w_low < 0.03
    assert abs(skid.gain_v - 1.0) < 0.01
    jackal = identified['jackal']
    assert jackal.gain_v_low <= 1.0 <= jackal.gain_v_high
    assert jackal.gain_w_low <= 1.0 <= jackal.gain_w_high
    for base in ('turtlebot3', 'jackal'):
        assert abs(identified[base].gain_v - 1.0) < 0.01
        assert abs(identified[base].gain_w - 1.0) < 0.02
    # the limits bind and are seen, but low (issue 39 item 3 is open): measured 2.17 of
    # 3.0 m/s^2 and 4.49 of 6.0 rad/s^2
    assert 0.6 * 3.0 < skid.max_linear_accel <= 1.1 * 3.0
    assert 0.6 * 6.0 < skid.max_angular_accel <= 1.1 * 6.0


#: (base, figure-eight radius (m), rate (rad/s), seconds): the Jackals on the package's
#: figure eight (r = 1 m at 0.2 rad/s, up to 0.28 m/s: config/latency_scenario.yaml), the
#: TurtleBot3 on a smaller, faster one (up to 0.17 m/s of its 0.22).
EIGHTS = {'turtlebot3': (0.4, 0.3, 25.0), 'jackal': (1.0, 0.2, 25.0),
          'jackal_skid': (1.0, 0.2, 25.0)}


def _track(base, ident, compensate=True, slip=False, seed=None):
    """The figure eight with our tracker (the shipped gain) on ``base``, its predictor set
    from the identification, the gains compensated or not, the side slip (``slip``) too or
    not, 1 mm / 1 mrad odometry noise with ``seed``: (true-pose RMS after 5 s, odometry-frame
    RMS (what the tracker sees), final odometry drift), all in m."""
    from nonfragile_tracker.control.simulation.follow import simulate_following
    from nonfragile_tracker.control.simulation.gains import read_gain_file
    from nonfragile_tracker.control.simulation.reference import figure_eight
    from nonfragile_tracker.control.simulation.trajectory import Trajectory
    radius, rate, seconds = EIGHTS[base]
    path = figure_eight(radius=radius, rate=rate)
    odom = []

    class Logged(physics.PhysicsPlant):
        def advance(self) -> None:
            super().advance()
            odom.append(self.odom_pose)

    noise = {} if seed is None else dict(odom_noise=(1e-3, 1e-3, 1e-3), noise_seed=seed)
    pc = PlantConfig(dt=0.01, th0=path.rest_heading, **noise)
    spec = physics.PhysicsPlant(pc, base).spec
    table = dict(side_slip_rates=ident.side_slip_rates, side_slip=ident.side_slip) if slip \
        else {}
    tc = TrackerConfig(K=read_gain_file(CONFIG / 'tracker_gains.yaml'),
                       max_linear_speed=spec.max_linear_speed,
                       max_angular_speed=spec.max_angular_speed,
                       predict_latency=ident.latency_s, predict_lag_v=ident.tau_v_s,
                       predict_lag_w=ident.tau_w_s,
                       gain_v=ident.gain_v if compensate else 1.0,
                       gain_w=ident.gain_w if compensate else 1.0, **table)
    run = simulate_following(pc, tc, Trajectory.analytic(path), int(round(seconds / pc.dt)),
                             plant=lambda c: Logged(c, base))
    o = np.array([(pc.x0, pc.y0, pc.th0)] + odom)
    after = run.t >= 5.0
    seen = np.hypot(o[:, 0] - run.xd, o[:, 1] - run.yd)
    drift = math.hypot(o[-1, 0] - run.x[-1], o[-1, 1] - run.y[-1])
    return (math.sqrt(float(np.mean(run.error[after] ** 2))),
            math.sqrt(float(np.mean(seen[after] ** 2))), drift)


@pytest.mark.parametrize('base', ['turtlebot3', 'jackal'])
def test_the_two_wheel_bases_track_a_figure_eight_within_3_mm(base, identified):
    """Identified, then tracked with the shipped gain and the predictor from the
    identification: true-pose RMS after 5 s (measured turtlebot3 0.78 mm, jackal 1.08 mm),
    the odometry drift beside it (0.36 and 0.58 mm at the end)."""
    true_rms, seen_rms, drift = _track(base, identified[base])
    assert true_rms <= 3e-3, (true_rms, seen_rms, drift)
    assert drift < 3e-3


def test_the_skid_steer_tracks_only_with_its_turn_gain_compensated(identified):
    """The same figure eight on the skid-steer: without compensation the base turns at 0.64
    of what the tracker asks and it tracks 17.9 mm RMS off even in its own odometry (true
    pose 27.9 mm); with the identified gain (0.641) it tracks its odometry within 1.0 mm.
    Its true pose stays 15.6 mm off: the body slides sideways in the turns and the encoders
    do not see it (16 mm of drift at the end, with or without compensation); the side slip
    identified from an external pose closes that (the next tests)."""
    ident = identified['jackal_skid']
    without = _track('jackal_skid', ident, compensate=False)
    with_ = _track('jackal_skid', ident)
    assert without[1] > 10e-3 and with_[1] < 3e-3, (without, with_)
    assert with_[0] < 0.7 * without[0] and with_[0] < 20e-3, (without, with_)
    assert with_[2] > 5e-3            # the drift is the skid's, not the tracker's


def test_the_side_slip_is_found_on_the_skid_steer_only(identified_with_slip):
    """From the true pose beside the odometry (1 mm noise) the skid-steer's slide is
    significant and outward (c > 0 where it turns: measured 0.034 s at 0.25 rad/s, 0.070 s
    at 0.5 rad/s, the window drift 3.5 -> 2.1 mm); the two-wheel bases' is not (drift
    1.4 mm, unexplained noise: no table, nothing compensated)."""
    ident, slip = identified_with_slip['jackal_skid']
    assert slip.significant and ident.side_slip == slip.coefficients, slip
    assert slip.rates[:2] == (0.25, 0.5), slip
    assert 0.03 < slip.coefficients[1] < 0.12 and slip.low[1] > 0.0, slip
    assert slip.residual_rms < 0.8 * slip.drift_rms
    for base in ('turtlebot3', 'jackal'):
        ident, slip = identified_with_slip[base]
        assert not slip.significant and ident.side_slip == (), slip


def test_the_skid_steer_tracks_its_true_pose_within_10_mm_with_its_side_slip(identified):
    """Issue 39's 10 mm on the skid-steer: with the turn gain and the side slip identified
    from the true pose compensated, the figure eight's true-pose RMS after 5 s, median of
    three odometry-noise seeds (the skid's contacts make single runs spread by a few mm), is
    within 10 mm (measured 2.0-3.6, median 2.2 mm), against 15-18 mm (median 17.6) with the
    turn gain alone; the tracker then holds its estimate of the true pose, not the odometry
    (15 mm from it: the slide)."""
    ident = identified['jackal_skid']
    gain_only = [_track('jackal_skid', ident, seed=s)[0] for s in (1, 2, 3)]
    slip = [_track('jackal_skid', ident, slip=True, seed=s)[0] for s in (1, 2, 3)]
    assert float(np.median(slip)) <= 10e-3, (slip, gain_only)
    assert float(np.median(gain_only)) > 12e-3, (slip, gain_only)
    assert float(np.median(slip)) < 0.6 * float(np.median(gain_only)), (slip, gain_only)


@pytest.mark.parametrize('base, v0', [('turtlebot3', 0.1), ('jackal', 0.5), ('jackal_skid', 0.5)])
def test_a_base_started_at_speed_keeps_it(base, v0):
    """``v0``: the body and wheels start at that speed and the firmware's setpoint and
    integrators with them, so the held command keeps it within 1 % (measured: at least
    0.993, 0.996, 0.992 of it over the first second)."""
    plant = physics.PhysicsPlant(PlantConfig(dt=0.01, v0=v0), base)
    assert plant.setpoint == (v0, 0.0) and abs(plant.v - v0) < 1e-3 * v0
    speeds = []
    for _ in range(100):
        plant.command(v0, 0.0)
        plant.advance()
        speeds.append(plant.v)
    assert 0.99 * v0 < min(speeds) and max(speeds) < 1.001 * v0
