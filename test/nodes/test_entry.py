"""The node processes' entry (nodes/entry.py) and the exit deadline of the DDS tear-down
(nodes/workarounds.py)."""
from __future__ import annotations

import signal
import subprocess
import sys
import time

from conftest import ROOT
from nonfragile_tracker.nodes import workarounds

# a node process whose main thread is stuck in C with the GIL held (as in the Fast DDS
# participant deadlock): a catastrophic regular expression never gives the GIL back
_STUCK = '''
import re, sys
from nonfragile_tracker.nodes import workarounds
workarounds.mark_node_process()
print('armed', workarounds.arm_exit_deadline(int(sys.argv[1]), float(sys.argv[2])), flush=True)
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
    assert workarounds._node_process is False
    assert workarounds.arm_exit_deadline(0, 0.01) is False
    time.sleep(0.05)                               # and this process lives on


_AS_MAIN = '''
import runpy, sys, types
fake = types.ModuleType('nonfragile_tracker.nodes.reference')

def main(args):
    import nonfragile_tracker.nodes.entry as imported    # what the node modules import
    from nonfragile_tracker.nodes import workarounds
    ran_here = sys._getframe(1).f_globals is vars(imported)     # entry.main called this
    return 7 if ran_here and workarounds._node_process else 3

fake.main = main
sys.modules['nonfragile_tracker.nodes.reference'] = fake
sys.argv = ['entry', 'reference']
runpy.run_module('nonfragile_tracker.nodes.entry', run_name='__main__', alter_sys=True)
'''


def test_python_dash_m_runs_the_importable_module():
    """``python -m nonfragile_tracker.nodes.entry NODE`` (the runner's and the tests' way to
    start a node) runs main() of the module the node code imports (whose stop flag the
    nodes read; ``__main__`` is a second copy) and marks the process as a node process (the
    exit deadline is armed)."""
    proc = subprocess.run([sys.executable, '-c', _AS_MAIN], cwd=ROOT, capture_output=True,
                          text=True, timeout=60)
    assert proc.returncode == 7, proc.stdout + proc.stderr


# a node process whose rclpy shut-down hangs in C with the GIL held, as the Fast DDS
# participant deadlock does: run() must still end it with the node's own exit code
_STUCK_SHUTDOWN = '''
import re, sys
import rclpy
def stuck(*args, **kwargs):
    re.match(r'(a+)+$', 'a' * 64 + 'b')
rclpy.try_shutdown = stuck
from nonfragile_tracker.nodes import entry, workarounds
workarounds.TEARDOWN_DEADLINE_S = 1.0
sys.exit(entry.main('plant', ['plant', '--ros-args', *sys.argv[1:]]))
'''


def _node_with_stuck_shutdown(ros_env, *ros_args: str, stop_after: float | None = None):
    proc = subprocess.Popen([sys.executable, '-c', _STUCK_SHUTDOWN, *ros_args], cwd=ROOT,
                            env=ros_env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True)
    try:
        if stop_after is not None:
            time.sleep(stop_after)
            proc.send_signal(signal.SIGINT)
        out, _ = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return proc.returncode, out


def test_run_ends_a_stuck_teardown_with_the_refusal_code(ros_env):
    code, out = _node_with_stuck_shutdown(ros_env, '-p', 'dt:=-1.0')
    assert code == 2, out
    assert '[FATAL]' in out and 'Timeout (0:00:00.800000)!' in out and 'Traceback' not in out


def test_run_ends_a_stuck_teardown_after_sigint_with_0(ros_env):
    code, out = _node_with_stuck_shutdown(ros_env, stop_after=4.0)
    assert code == 0, out
    assert 'started;' in out and 'Timeout (0:00:00.800000)!' in out and 'Traceback' not in out


def _importing(body: str) -> str:
    """A script running node ``reference`` whose module import runs ``body`` (the
    ``exec_module`` of a finder put first on ``sys.meta_path``), then ``main`` returns 9."""
    body = '\n'.join('        ' + line for line in body.strip().splitlines())
    return f'''
import gc, importlib.abc, importlib.util, os, signal, sys, time, weakref

class Finder(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    def find_spec(self, name, path, target=None):
        if name == 'nonfragile_tracker.nodes.reference':
            return importlib.util.spec_from_loader(name, self)
    def create_module(self, spec):
        return None
    def exec_module(self, module):
{body}
        module.main = lambda args: 9

sys.meta_path.insert(0, Finder())
from nonfragile_tracker.nodes import entry
sys.exit(entry.main('reference', ['reference']))
'''


# a node module whose import takes 30 s (numpy, rclpy, scipy ... on a busy machine: seconds)
_SLOW_IMPORT = _importing('''
print('importing', flush=True)
t_end = time.monotonic() + 30.0
while time.monotonic() < t_end:     # bytecodes (a long import) ...
    time.sleep(0.05)                # ... and C calls
''')


def test_a_stop_signal_ends_the_node_module_import_at_once():
    """Ctrl-C while the node module is still importing (issue 30: ``ros2 launch`` start
    every node at once, and the imports took seconds; the signal was acted on after them):
    the import stops where it is, the process ends with 0, no traceback."""
    proc = subprocess.Popen([sys.executable, '-c', _SLOW_IMPORT], cwd=ROOT, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    try:
        assert proc.stdout.readline().strip() == 'importing'
        proc.send_signal(signal.SIGINT)
        t0 = time.monotonic()
        code = proc.wait(30)
        took = time.monotonic() - t0
        out = proc.stdout.read()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert code == 0 and 'Traceback' not in out, out
    assert took < 10                # 30 s if the import ran to its end (a few ms here)


# a signal that lands in a weakref callback while the node module imports (importlib's
# module-lock callback in the suite): Python cannot raise there, it reports the exception
_SIGNAL_IN_A_CALLBACK = _importing('''
class Obj: pass
o = Obj()
ref = weakref.ref(o, lambda r: os.kill(os.getpid(), signal.SIGINT))
del o                           # the callback runs, the handler raises in it
gc.collect()
print('imported', flush=True)
''')


def test_a_stop_signal_in_a_callback_during_the_import_ends_quietly():
    """The signal lands in a weakref callback during the import (Python cannot raise
    there): no "Exception ignored" traceback, and the stop is honoured (exit 0, the node's
    main never runs)."""
    out = subprocess.run([sys.executable, '-c', _SIGNAL_IN_A_CALLBACK], cwd=ROOT, text=True,
                         capture_output=True, timeout=60)
    assert 'imported' in out.stdout            # the import went on past the signal
    assert out.returncode == 0 and 'Traceback' not in out.stderr, out.stderr
    assert 'Exception ignored' not in out.stderr, out.stderr


def test_a_signal_handled_as_its_import_handler_is_set_stops_quietly(monkeypatch):
    """A stop signal pending (or arriving) right when _import_node swaps in its raising
    handler is handled at once, inside signal.signal's return: the _StopImport must not
    escape as a traceback (seen once: Ctrl-C 0.3 s after ros2 launch, the reference node
    exited 1 with a traceback from line ``signal.signal(sig, _stop_import)``)."""
    from nonfragile_tracker.nodes import entry
    real = signal.signal
    imported = []

    def delivering(sig, handler):
        old = real(sig, handler)
        if handler is entry._stop_import and sig == signal.SIGINT:
            handler(sig, None)                      # the pending signal, handled now
        return old

    monkeypatch.setattr(entry.signal, 'signal', delivering)
    monkeypatch.setattr(entry.importlib, 'import_module', lambda n: imported.append(n))
    monkeypatch.setattr(entry, '_received', [])
    saved = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        assert entry._import_node('reference') is None
        assert imported == [] and entry.stop_requested()
        # the handlers only note again afterwards
        assert all(signal.getsignal(s) is entry._note for s in (signal.SIGINT, signal.SIGTERM))
    finally:
        for s, h in saved.items():
            real(s, h)
