"""The physics rows of the peers' table (benchmarks/peers_physics.py): the adapter hands every
controller the same MuJoCo base (``adapter.run(..., plant=)``), and the base's odometry is
what each controller is given at its first step."""
from __future__ import annotations

import sys


from conftest import ROOT

import mujoco  # noqa: E402, F401  (pinned in requirements.txt: missing, fail, not skip)
import wpimath  # noqa: E402, F401  (the peer: missing, fail at collection, not skip)
if str(ROOT / 'benchmarks') not in sys.path:
    sys.path.insert(0, str(ROOT / 'benchmarks'))

from peers import adapter, wpilib as W  # noqa: E402

from nonfragile_tracker.control.simulation import physics  # noqa: E402
from nonfragile_tracker.control.simulation.gains import read_gain_file  # noqa: E402
from nonfragile_tracker.control.simulation.plant import PlantConfig  # noqa: E402
from nonfragile_tracker.control.simulation.reference import figure_eight  # noqa: E402
from nonfragile_tracker.control.simulation.tracker import TrackerConfig  # noqa: E402
from nonfragile_tracker.control.simulation.trajectory import Trajectory  # noqa: E402


def test_every_controller_gets_the_same_physics_base():
    pc = PlantConfig(dt=0.01, x0=0.0, y0=-0.1, th0=0.785, cmd_latency=0.02,
                     cmd_latency_jitter=0.01, odom_rate=50.0, odom_noise=(1e-3,) * 3,
                     noise_seed=4)
    tc = TrackerConfig(K=read_gain_file(ROOT / 'config' / 'tracker_gains.yaml'),
                       max_linear_speed=1.0, max_angular_speed=2.0)
    traj = Trajectory.analytic(figure_eight(radius=1.0, rate=0.2))
    made = []

    def plant(config):
        p = physics.PhysicsPlant(config, 'jackal')
        made.append((config, p.path, p.spec))
        return p

    runs = [adapter.run(f, pc, tc, traj, 0.5, record=True, plant=plant)
            for f in (adapter.OURS, W.ltv)]
    assert len(made) == 2 and made[0] == made[1] and made[0][0] == pc
    first = [r.controller.inputs[0][:3] for r in runs]
    assert first[0] == first[1]                     # the same odometry at the first step
    assert runs[0].run.x[0] == runs[1].run.x[0]     # the same true start
    assert runs[0].run.cmd_v[-1] != runs[1].run.cmd_v[-1]    # and two different laws ran
