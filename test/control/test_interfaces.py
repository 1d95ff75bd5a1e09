"""The two seams: a second controller and a second plant, each one new file, plug into every
loop (in-process simulation, the Follower, the tracker's input rules that the node and the bag
replay feed) by name, with nothing registered; bad names and wrong objects are refused."""
import math
import sys
import textwrap

import numpy as np
import pytest

from nonfragile_tracker.control.simulation.errors import LoopConfigError
from nonfragile_tracker.control.simulation.follow import simulate_following
from nonfragile_tracker.control.simulation.gains import read_gain_file
from nonfragile_tracker.control.simulation.interfaces import (Controller, Plant, load_factory,
                                                              make_controller, make_plant)
from nonfragile_tracker.control.simulation.plant import PlantConfig, UnicyclePlant
from nonfragile_tracker.control.simulation.tracker import Tracker, TrackerConfig
from nonfragile_tracker.control.simulation.reference import circle
from nonfragile_tracker.control.simulation.simulate import run_loop, simulate_tracking
from nonfragile_tracker.control.simulation.trajectory import Trajectory

from conftest import CONFIG
from seam_files import KANAYAMA, SKID


@pytest.fixture
def new_files(tmp_path, monkeypatch):
    """The two new files, importable by name (as a user's package on PYTHONPATH is)."""
    (tmp_path / 'my_law.py').write_text(textwrap.dedent(KANAYAMA))
    (tmp_path / 'my_base.py').write_text(textwrap.dedent(SKID))
    monkeypatch.syspath_prepend(str(tmp_path))
    yield tmp_path
    for name in ('my_law', 'my_base'):
        sys.modules.pop(name, None)


def _tracker_config(**kw):
    return TrackerConfig(K=read_gain_file(CONFIG / 'tracker_gains.yaml'), **kw)


def _figure():
    return circle(radius=1.0, rate=0.2), PlantConfig(dt=0.01, x0=1.05, y0=0.0, th0=math.pi / 2,
                                                      v0=0.2)


def test_our_law_and_the_unicycle_satisfy_the_protocols():
    tc = _tracker_config()
    assert isinstance(Tracker(tc), Controller)
    assert isinstance(UnicyclePlant(PlantConfig()), Plant)
    assert type(make_controller(tc)) is Tracker
    assert type(make_plant(PlantConfig())) is UnicyclePlant
    assert Tracker(tc).horizon == 0.0
    assert Tracker(_tracker_config(predict_latency=0.04, predict_odom_latency=0.01)
                   ).horizon == pytest.approx(0.05)


def test_a_second_controller_is_one_file_and_a_name(new_files):
    path, plant = _figure()
    tc = _tracker_config(controller='my_law:Kanayama')
    run = simulate_tracking(plant, tc, path, 2000)
    err = run.error
    # it tracks: 5 cm off at the start, within 2 mm after 10 s
    assert err[0] == pytest.approx(0.05, abs=1e-9)
    assert float(np.sqrt(np.mean(err[1000:] ** 2))) < 2e-3
    # and it is not our law: the same run with our law differs
    ours = simulate_tracking(plant, _tracker_config(), path, 2000)
    assert np.max(np.abs(ours.cmd_w - run.cmd_w)) > 1e-3


def test_the_follower_and_the_input_rules_take_it(new_files):
    from nonfragile_tracker.interface.tracker_inputs import TrackerInputs
    path, plant = _figure()
    traj = Trajectory.analytic(path)
    tc = _tracker_config(controller='my_law:Kanayama')
    run = simulate_following(plant, tc, traj, 1200)
    # the Follower runs the law as the plain loop does: the same run to round-off
    direct = simulate_tracking(plant, tc, path, 1200)
    assert np.max(np.abs(run.error - direct.error)) < 1e-9
    assert float(run.error[-1]) < 0.2 * float(run.error[0])
    inputs = TrackerInputs(tc)           # the law, held within the speed limits as ours
    assert type(inputs.tracker).__name__ == 'Clamped'
    assert type(inputs.tracker.law).__name__ == 'Kanayama'
    assert type(inputs.fork().tracker.law).__name__ == 'Kanayama'


def test_a_second_plant_is_one_file_and_a_name(new_files):
    path, plant = _figure()
    tc = _tracker_config()
    skid = simulate_tracking(plant, tc, path, 3000, plant='my_base:Skid')
    ideal = simulate_tracking(plant, tc, path, 3000)
    # the 30 % turn deficit is felt (the paper's plant tracks it far better) and the run is the
    # plant's: run_loop logged its true pose
    assert float(np.max(skid.error[2000:])) > 3 * float(np.max(ideal.error[2000:]))
    assert float(np.max(skid.error[2000:])) < 0.05
    # run_loop takes a plant object directly
    again = run_loop(make_plant(plant, 'my_base:Skid'), 3000,
                     lambda m, th, k, ref: Tracker(tc).step(m.x, m.y, th, ref, m.v),
                     lambda k: path.sample(k * 0.01))
    assert again.t[-1] == pytest.approx(30.0)


@pytest.mark.parametrize('spec, words', [
    ('no_colon', 'package.module:name'),
    ('a:b:c', 'package.module:name'),
    ('no_such_module_x:Law', 'cannot be imported'),
    ('math:no_such_law', 'no callable'),
])
def test_a_bad_name_is_refused_with_what_to_do(spec, words):
    with pytest.raises(LoopConfigError, match=words):
        load_factory(spec)
    assert issubclass(LoopConfigError, ValueError)


def test_a_factory_that_makes_no_controller_or_plant_is_refused():
    tc = _tracker_config()
    with pytest.raises(LoopConfigError, match='lacks timing, horizon, reset or step'):
        make_controller(tc, lambda c: object())
    with pytest.raises(LoopConfigError, match='lacks x, y, th'):
        make_plant(PlantConfig(), lambda c: object())
    with pytest.raises(LoopConfigError, match='controller must be a string'):
        _tracker_config(controller=3)


def test_the_tracker_parameters_carry_the_controller(new_files):
    from nonfragile_tracker.interface.msgconv import tracker_config
    from nonfragile_tracker.nodes.tracker import PARAMS
    values = {p.name: p.default for p in PARAMS}
    values.update(K=list(np.ravel(read_gain_file(CONFIG / 'tracker_gains.yaml'))))
    assert tracker_config(values).controller == ''          # the default law
    values['controller'] = 'my_law:Kanayama'
    assert tracker_config(values).controller == 'my_law:Kanayama'
    values['controller'] = 'my_law:Nope'
    with pytest.raises(LoopConfigError, match='no callable'):
        tracker_config(values)


def test_one_mapping_from_plant_parameters_keeps_every_field():
    # study --scenario used to keep five of them and drop the odometry rate, noise and limits
    from nonfragile_tracker.interface.scenario import plant_config
    params = {'dt': 0.005, 'odom_rate': 50.0, 'odom_noise': [0.001, 0.001, 0.002],
              'max_linear_accel': 1.0, 'max_angular_accel': 3.0, 'lag_v': 0.05,
              'cmd_latency': 0.04, 'cmd_latency_schedule': [1.0, 0.02], 'noise_seed': 3,
              'initial_pose': [1.0, 2.0, 0.5], 'initial_speed': 0.1}
    pc = plant_config(params)
    assert (pc.dt, pc.odom_rate, pc.odom_noise, pc.max_linear_accel, pc.max_angular_accel,
            pc.lag_v, pc.cmd_latency, pc.cmd_latency_schedule, pc.noise_seed) == (
        0.005, 50.0, (0.001, 0.001, 0.002), 1.0, 3.0, 0.05, 0.04, (1.0, 0.02), 3)
    assert (pc.x0, pc.y0, pc.th0, pc.v0) == (1.0, 2.0, 0.5, 0.1)


def test_the_scenario_cache_hands_each_caller_its_own_copy(tmp_path):
    from nonfragile_tracker.interface.scenario import node_parameters
    a = node_parameters('plant')
    a['initial_pose'].append(99.0)
    b = node_parameters('plant')
    assert len(b['initial_pose']) == 3
    f = tmp_path / 's.yaml'
    f.write_text('plant:\n  ros__parameters:\n    dt: 0.01\n')
    assert node_parameters('plant', f)['dt'] == 0.01
    f.write_text('plant:\n  ros__parameters:\n    dt: 0.02\n    tau: 0.1\n')
    assert node_parameters('plant', f)['dt'] == 0.02         # a file written again is read


def test_the_predictor_is_a_part_any_law_can_be_wrapped_with(new_files):
    """Kanayama's law on a figure eight through a 50 ms actuator lag: 100 ms of command
    latency triples its error; wrapped with our predictor (latency and lag assumed right) it
    tracks as it does without the latency (the predictor removes the dead time; the lag,
    which our law also inverts, the wrapper leaves to the law)."""
    from my_law import Kanayama
    from nonfragile_tracker.control.simulation.reference import figure_eight
    from nonfragile_tracker.control.simulation.wrappers import Predicted
    path = figure_eight(radius=1.0, rate=0.3)
    r0 = path.sample(0.0)
    tc = _tracker_config()

    def rms(latency, controller):
        plant = PlantConfig(dt=0.01, x0=r0.x, y0=r0.y, th0=r0.heading,
                            v0=math.hypot(r0.vx, r0.vy), cmd_latency=latency, lag_v=0.05,
                            lag_w=0.05)
        run = simulate_tracking(plant, tc, path, 4000, controller=controller)
        return float(np.sqrt(np.mean(run.error[1000:] ** 2)))

    no_latency = rms(0.0, Kanayama)
    bare = rms(0.1, Kanayama)
    wrapped = rms(0.1, lambda c: Predicted(Kanayama(c), 0.1, lag_v=0.05, lag_w=0.05))
    assert bare > 2.5 * no_latency
    assert wrapped == pytest.approx(no_latency, rel=0.05), (no_latency, bare, wrapped)
    assert Predicted(Kanayama(tc), 0.1, 0.02).horizon == pytest.approx(0.12)


def test_the_rate_limit_is_a_part_any_law_can_be_wrapped_with(new_files):
    from my_law import Kanayama
    from nonfragile_tracker.control.simulation.wrappers import RateLimited
    path, plant = _figure()
    plant = PlantConfig(dt=0.01, x0=1.05, y0=0.0, th0=math.pi / 2 + 0.5, v0=0.2)
    tc = _tracker_config()
    run = simulate_tracking(plant, tc, path, 1000,
                            controller=lambda c: RateLimited(Kanayama(c), 0.5, 1.0))
    free = simulate_tracking(plant, tc, path, 1000, controller=Kanayama)
    dv, dw = np.abs(np.diff(run.cmd_v)), np.abs(np.diff(run.cmd_w))
    assert np.max(dv) <= 0.5 * 0.01 + 1e-12 and np.max(dw) <= 1.0 * 0.01 + 1e-12
    # the law alone starts turning at once; limited, the first command is the start state
    # (v0, 0), as our law's is, and the two agree once the turn is reached
    assert abs(free.cmd_w[0]) > 0.05 and run.cmd_w[0] == 0.0 and run.cmd_v[0] == 0.2
    assert np.max(np.abs(run.cmd_w[300:] - free.cmd_w[300:])) < 1e-3
