"""``bag report`` says whether a run stayed inside its certificate: the tracker's monitor
over the recorded commands and odometry, against a gain file's record (``--gains``) or the
parameters recorded with the run (``params.yaml``)."""
import math

import numpy as np
import pytest
import yaml
from geometry_msgs.msg import Twist
from nav_msgs.msg import Odometry
from rclpy.serialization import serialize_message

from nonfragile_tracker.interface import topics
from nonfragile_tracker.bag.report import (certificate_check, certificate_source,
                                           format_certificate)
from nonfragile_tracker.bag.writer import BagWriter
from nonfragile_tracker.cli import main
from nonfragile_tracker.control.simulation.gains import write_gain_file
from nonfragile_tracker.control.simulation.plant import PlantConfig, UnicyclePlant
from nonfragile_tracker.control.simulation.timing import step_time_ns
from nonfragile_tracker.control.simulation.model import yaw_to_quaternion

#: Depends on linear algebra: make test runs it again under a second BLAS kernel (Makefile).
pytestmark = pytest.mark.numerical

DT, STEP, DURATION = 0.01, 10.0, 20.0
K = [[-1.0, -1.5, 0.0, 0.0], [0.0, 0.0, -1.0, -1.5]]


def write_step_bag(bag):
    """Random command steps through the plant; latency 100 ms, 250 ms from 10 s."""
    rng = np.random.default_rng(5)
    p = UnicyclePlant(PlantConfig(dt=DT, cmd_latency=0.1, lag_v=0.05, lag_w=0.05,
                                  odom_rate=50.0, cmd_latency_schedule=(STEP, 0.25)))
    conns = {'/odom': topics.TYPES[topics.ODOM], '/cmd_vel': topics.TYPES[topics.CMD_VEL]}
    with BagWriter(bag, connections=conns) as w:
        v = om = 0.0
        for k in range(int(round(DURATION / DT))):
            ns = step_time_ns(k, DT)
            if k % 30 == 0:
                v, om = rng.uniform(-0.5, 0.5), rng.uniform(-1.5, 1.5)
            m = p.odometry()
            if m is not None:
                odom = Odometry()
                odom.header.frame_id, odom.child_frame_id = topics.ODOM_FRAME, topics.BASE_FRAME
                odom.header.stamp.sec, odom.header.stamp.nanosec = divmod(
                    step_time_ns(m.step, DT), 10**9)
                pose = odom.pose.pose
                pose.position.x, pose.position.y = m.x, m.y
                q = yaw_to_quaternion(m.th)
                pose.orientation.z, pose.orientation.w = q[2], q[3]
                odom.twist.twist.linear.x, odom.twist.twist.angular.z = m.v, m.w
                w.write('/odom', ns, serialize_message(odom))
            if k % 2 == 0:
                cmd = Twist()
                cmd.linear.x, cmd.angular.z = v, om
                w.write('/cmd_vel', ns + 1000, serialize_message(cmd))
                p.command(v, om)
            p.advance()


@pytest.fixture(scope='module')
def run_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp('cert')
    write_step_bag(d / 'bag')
    return d


def test_fraction_inside_the_certificate_of_a_gain_file(run_dir, tmp_path):
    """Certified delay [0, 0.1] s with the 50 ms lag, predict_latency 0.1 s, dt 0.02 s: latency certified in
    [0.1, 0.18] s.  Windows (4 s, every 1 s) ending at 4..19 s (the last odometry at
    19.98 s): those ending by 10 s see 100 ms only, those from 14 s 250 ms only."""
    gains = write_gain_file(tmp_path / 'g.yaml', K, extra={'predict_latency': 0.1, 'dt': 0.02},
                            design={'latency_interval': [0.0, 0.1], 'certified_h_max': 0.2,
                                    'actuator_lag': 0.05, 'lag_certified_h_max': 0.1})
    cert, params, source = certificate_source(run_dir / 'bag', gains)
    assert cert.interval(0.1) == pytest.approx((0.1, 0.18))
    chk = certificate_check(run_dir / 'bag', cert, params, source=source)
    assert chk.t.size == 16
    assert chk.t[0] == pytest.approx(4.0) and chk.t[-1] == pytest.approx(19.0)
    early, late = chk.t <= STEP, chk.t >= STEP + 4.0
    assert np.all(np.abs(chk.latency[early] - 0.1) <= DT)            # one plant step
    assert np.all(np.abs(chk.latency[late] - 0.25) <= DT)
    assert np.all(chk.levels[early] == 0) and np.all(chk.levels[late] == 2)
    assert chk.inside + chk.outside + chk.unknown == pytest.approx(1.0)
    assert 7 / 16 <= chk.inside <= 10 / 16 and 6 / 16 <= chk.outside <= 9 / 16
    # a window straddling the step: the estimate follows the larger part of it
    assert STEP < chk.first_outside <= STEP + 3.0
    text = format_certificate(chk)
    assert 'certified latency [0.1000, 0.1800] s' in text
    assert f'time inside the certified interval: {100 * chk.inside:.1f} %' in text


def test_cli_reads_the_run_directorys_params_or_gains(run_dir, tmp_path, capsys):
    bag = run_dir / 'bag'
    (run_dir / 'params.yaml').write_text(yaml.safe_dump({'/**/tracker': {'ros__parameters': {
        'dt': 0.02, 'predict_latency': 0.1, 'certified_residual': [0.0, 0.4],
        'certified_lag': 0.05}}}))
    assert main(['bag', 'report', str(bag), '--no-plots']) == 0
    out = capsys.readouterr().out
    assert 'params.yaml):' in out and 'certified latency [0.1000, 0.4800] s' in out
    # the windows straddling the step are unknown (interval too wide), none outside
    inside = float(out.split('time inside the certified interval: ')[1].split(' %')[0])
    assert inside >= 75.0 and 'outside: 0.0 %' in out
    gains = write_gain_file(tmp_path / 'g.yaml', K, extra={'predict_latency': 0.1, 'dt': 0.02},
                            design={'certified_latency': 0.05})
    assert main(['bag', 'report', str(bag), '--no-plots', '--gains', str(gains)]) == 0
    out = capsys.readouterr().out
    assert 'certified latency [0.1000, 0.1300] s' in out
    assert 'first outside at t = ' in out
    assert not math.isnan(float(out.split('first outside at t = ')[1].split(' s')[0]))
