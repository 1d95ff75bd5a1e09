"""The node processes' entry: the exit deadline of the DDS tear-down (nodes/entry.py)."""
from __future__ import annotations

import subprocess
import sys
import time

from conftest import ROOT
from nonfragile_tracker.nodes import entry

# a node process whose main thread is stuck in C with the GIL held (as in the Fast DDS
# participant deadlock): a catastrophic regular expression never gives the GIL back
_STUCK = '''
import re, sys
from nonfragile_tracker.nodes import entry
entry._node_process = True
print('armed', entry.arm_exit_deadline(int(sys.argv[1]), float(sys.argv[2])), flush=True)
re.match(r'(a+)+$', 'a' * 64 + 'b')
print('not reached', flush=True)
'''


def _stuck(code: int, seconds: float) -> tuple[int, str, float]:
    t0 = time.monotonic()
    proc = subprocess.run([sys.executable, '-c', _STUCK, str(code), str(seconds)], cwd=ROOT,
                          capture_output=True, text=True, timeout=60)
    return proc.returncode, proc.stdout + proc.stderr, time.monotonic() - t0


def test_a_stuck_teardown_ends_with_the_node_exit_code_and_its_stacks():
    code, out, took = _stuck(0, 1.0)
    assert code == 0 and 'armed True' in out and 'not reached' not in out
    assert 'Timeout (0:00:00.800000)!' in out and 'File "<string>", line 6' in out, out
    assert took < 20
    code, out, _ = _stuck(5, 0.5)                 # a lockstep abort keeps its code
    assert code == 5 and 'not reached' not in out


def test_the_deadline_is_never_armed_outside_a_node_process():
    assert entry._node_process is False
    assert entry.arm_exit_deadline(0, 0.01) is False
    time.sleep(0.05)                               # and this process lives on
