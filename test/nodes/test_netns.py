"""Two hosts: plant, reference and recorder in one network namespace, the tracker in another,
joined by a veth pair; the link is cut for 5 s and restored (real-time mode).

Measured from the bag (recorded next to the plant) and the tracker's log:
- the plant stops (odom speed in force 0) within ``cmd_timeout`` of its last command;
- the tracker publishes a stop within ``input_timeout`` of losing its inputs;
- both resume within 1 s of the link's return; one bag holds the whole run.

DDS discovery runs over the veth only: the namespaces have no other interface than
loopback, ``ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET`` with a multicast route on the veth,
and Fast DDS limited to UDPv4 (``FASTDDS_BUILTIN_TRANSPORTS``) so no data can take the
shared-memory shortcut between the two "hosts" (they share /dev/shm here; Fast DDS 2.14
did not take it without the setting either, but that rests on its host-id heuristics;
the test asserts that no command arrives while the link is down).  The
namespaces (named with the pid, so parallel runs do not collide) are always deleted.
"""
from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from conftest import CONFIG, kill_with_stacks
from nonfragile_tracker.bag.reader import mcap_is_complete, read_bag, read_messages

CMD_TIMEOUT = 0.5          # plant: a command older than this is replaced by a stop
INPUT_TIMEOUT = 0.5        # tracker: inputs older than this make it publish stops
CUT = 5.0                  # link down (s)
#: scheduling allowance on top of the timeouts: the plant's 10 ms step and the tracker's
#: 50 ms watchdog period, plus wake-up latency on a loaded 2-core machine
SLACK = 0.25
ADDR = {'a': '10.231.0.1', 'b': '10.231.0.2'}


def ip(*args: str) -> None:
    subprocess.run(['ip', *args], check=True, capture_output=True, text=True, timeout=10)


class TwoHosts:
    """Namespaces ``nfa<pid>``/``nfb<pid>`` joined by veth ``va<pid>``/``vb<pid>`` (/30)."""

    def __init__(self):
        pid = os.getpid()
        self.ns = {'a': f'nfa{pid}', 'b': f'nfb{pid}'}
        self.dev = {'a': f'va{pid}', 'b': f'vb{pid}'}

    def create(self) -> None:
        for ns in self.ns.values():
            ip('netns', 'add', ns)
            ip('-n', ns, 'link', 'set', 'lo', 'up')
        ip('-n', self.ns['a'], 'link', 'add', self.dev['a'], 'type', 'veth', 'peer', 'name',
           self.dev['b'], 'netns', self.ns['b'])
        for h in 'ab':
            ip('-n', self.ns[h], 'addr', 'add', f'{ADDR[h]}/30', 'dev', self.dev[h])
        self.link_up()

    def link_up(self) -> tuple[float, float]:
        """Bring the link up; the wall-clock bracket (before, after) of ``a``'s device coming
        up - the moment the link returns after :meth:`link_down` (``b``'s stays up)."""
        bracket = [time.time(), 0.0]
        for h in 'ab':
            ip('-n', self.ns[h], 'link', 'set', self.dev[h], 'up')
            if h == 'a':
                bracket[1] = time.time()
            # discovery multicast leaves through the veth (taking a link down drops the route)
            ip('-n', self.ns[h], 'route', 'replace', '224.0.0.0/4', 'dev', self.dev[h])
        return bracket[0], bracket[1]

    def link_down(self) -> tuple[float, float]:
        """Cut the link; the wall-clock bracket (before, after) of the cut."""
        t0 = time.time()
        ip('-n', self.ns['a'], 'link', 'set', self.dev['a'], 'down')
        return t0, time.time()

    def delete(self) -> None:
        for ns in self.ns.values():
            subprocess.run(['ip', 'netns', 'del', ns], capture_output=True, timeout=10)

    def start(self, host: str, node: str, env: dict, log: Path, *extra: str):
        files = ['--params-file', str(CONFIG / 'paper_scenario.yaml')]
        if node == 'tracker':
            files += ['--params-file', str(CONFIG / 'tracker_gains.yaml')]
        cmd = ['ip', 'netns', 'exec', self.ns[host], sys.executable, '-m',
               f'nonfragile_tracker.nodes.{node}', '--ros-args', *files, '-p', 'mode:=realtime',
               *extra]
        with open(log, 'w') as fh:
            return subprocess.Popen(cmd, env=env, stdout=fh, stderr=subprocess.STDOUT,
                                    stdin=subprocess.DEVNULL)


def _log_times(text: str, phrase: str) -> list[float]:
    """Wall times (s) of the rcutils log lines containing ``phrase``."""
    return [float(m.group(1)) for line in text.splitlines() if phrase in line
            for m in [re.search(r'\] \[(\d+\.\d+)\] \[', line)] if m]


@pytest.mark.ros
def test_link_cut_stops_and_resumes(tmp_path, ros_env):
    env = dict(ros_env, ROS_AUTOMATIC_DISCOVERY_RANGE='SUBNET', FASTDDS_BUILTIN_TRANSPORTS='UDPv4')
    env.pop('ROS_STATIC_PEERS', None)
    hosts = TwoHosts()
    procs: dict[str, subprocess.Popen] = {}
    logs = {n: tmp_path / f'{n}.log' for n in ('recorder', 'plant', 'reference', 'tracker')}
    bag = tmp_path / 'bag'
    try:
        hosts.create()
        procs['recorder'] = hosts.start('a', 'recorder', env, logs['recorder'], '-p',
                                        f'output:={bag}', '-p', 'flush_period:=0.2', '-p',
                                        "topics:=['odom','cmd_vel']")
        procs['plant'] = hosts.start('a', 'plant', env, logs['plant'], '-p', 'duration:=0.0',
                                     '-p', f'cmd_timeout:={CMD_TIMEOUT}')
        procs['reference'] = hosts.start('a', 'reference', env, logs['reference'])
        procs['tracker'] = hosts.start('b', 'tracker', env, logs['tracker'], '-p',
                                       f'input_timeout:={INPUT_TIMEOUT}')
        deadline = time.monotonic() + 60
        while not all(f'first message on /{t}' in logs['recorder'].read_text()
                      for t in ('odom', 'cmd_vel')):
            dead = {n: p.returncode for n, p in procs.items() if p.poll() is not None}
            assert not dead and time.monotonic() < deadline, \
                (dead, {n: f.read_text()[-800:] for n, f in logs.items()})
            time.sleep(0.05)
        time.sleep(1.5)                                  # tracking over the link
        # the link went down somewhere in [t_cut, cut_end] and came back somewhere in
        # [t_up, up_end]: the `ip` commands take a few ms, more under load (a retransmission
        # burst once arrived before a time taken after link_up() returned).  Bounds use the
        # end of a bracket that cannot fail a correct run: "at least" from the earliest,
        # "at most" from the latest possible instant; the link is certainly down in between
        t_cut, cut_end = hosts.link_down()
        time.sleep(CUT)
        t_up, up_end = hosts.link_up()
        time.sleep(3.0)
        for p in procs.values():
            p.send_signal(signal.SIGINT)
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline and any(p.poll() is None for p in procs.values()):
            time.sleep(0.05)
        codes = {n: 'hung' if p.poll() is None else p.returncode for n, p in procs.items()}
    finally:
        for p in procs.values():
            kill_with_stacks(p)                 # a hung node's log shows where
        hosts.delete()
    text = {n: f.read_text() for n, f in logs.items()}
    assert codes == dict.fromkeys(procs, 0), (codes, text)
    assert not any('Traceback' in t for t in text.values()), text
    assert not any(ns in subprocess.run(['ip', 'netns', 'list'], capture_output=True,
                                        text=True).stdout for ns in hosts.ns.values())

    # one complete bag holds the whole run: before, during and after the cut
    assert mcap_is_complete(next(bag.glob('*.mcap')))
    data = read_bag(bag, strict=False)
    odom = [(t * 1e-9, m.twist.twist.linear.x) for t, m in read_messages(bag, 'odom')]
    t_odom = np.array([t for t, _ in odom])
    v_odom = np.array([v for _, v in odom])
    t_cmd = data.receive_ns['/cmd_vel'] * 1e-9
    assert t_odom[0] < t_cut - 1.0 and t_odom[-1] > t_up + 2.0
    assert np.diff(t_odom).max() < 0.5               # the plant (same host) never went silent
    assert np.all(v_odom[t_odom < t_cut] != 0.0)

    # plant: stops within cmd_timeout of the last command it received before the cut
    last_cmd = t_cmd[t_cmd < cut_end + 0.1].max()
    assert not np.any((t_cmd > cut_end + 0.1) & (t_cmd < t_up)), 'commands crossed a cut link'
    t_stop = t_odom[(t_odom > last_cmd) & (v_odom == 0.0)].min()
    assert t_stop - last_cmd <= CMD_TIMEOUT + SLACK, (t_stop - last_cmd)
    assert t_stop - last_cmd >= CMD_TIMEOUT - 0.01     # and not before the timeout
    assert np.all(v_odom[(t_odom > t_stop) & (t_odom < t_up)] == 0.0)   # stays stopped

    # tracker: a stop within input_timeout of losing its inputs (said once, in its log)
    stops = [t for t in _log_times(text['tracker'], 'publishing stop') if t > t_cut]
    resumes = [t for t in _log_times(text['tracker'], 'resuming') if t > t_cut]
    during = [t for t in stops if t < t_up]
    assert len(during) == 1, text['tracker']                  # one stop for the cut
    assert INPUT_TIMEOUT - 0.02 <= stops[0] - t_cut, stops[0] - t_cut
    assert stops[0] - cut_end <= INPUT_TIMEOUT + SLACK, stops[0] - cut_end

    # both resume within 1 s of the link's return
    assert resumes and resumes[0] - up_end <= 1.0, resumes[0] - up_end
    t_move = t_odom[(t_odom > t_up) & (v_odom != 0.0)].min()
    assert t_move - up_end <= 1.0, t_move - up_end
    # and keep tracking.  Once in a dozen loaded runs the odometry over the returned link
    # stalled again for about input_timeout while DDS repaired the backlog of the cut: the
    # tracker then stopped and resumed once more - the same rule at work, stop and resume
    # alternating - so what is checked is that it ends tracking with every stop resumed
    assert len(stops) - len(during) <= 1 and len(resumes) == len(stops), text['tracker']
    assert resumes[-1] > stops[-1], text['tracker']
    assert np.all(v_odom[t_odom > max(t_move, resumes[-1]) + 0.5] != 0.0)
    print(f'plant stop {t_stop - last_cmd:.3f} s after its last command; tracker stop '
          f'{stops[0] - t_cut:.3f} s after the cut; resumed {resumes[0] - t_up:.3f} s '
          f'(tracker) and {t_move - t_up:.3f} s (plant) after the link returned (the ip '
          f'commands took {cut_end - t_cut:.3f} s and {up_end - t_up:.3f} s)',
          file=sys.stderr)
