"""Identification: command latency and actuator lags from commands and odometry.

Offline identification from a recording and its file (:mod:`.identify`), in-process
recordings of a simulated base to identify (:mod:`.recording`), and the tracker's runtime
certificate monitor, which estimates the same quantities over a sliding window and
compares them with the gain's certificate (:mod:`.monitor`).
Its errors are in :mod:`.errors`, under the package's root error.  Import a name from
its module (``from nonfragile_tracker.control.simulation.loop import Tracker``): the
part re-exports nothing, so importing it loads none of its modules.

Notes
-----
Layer rule: this part may import :mod:`nonfragile_tracker.control.simulation` (a recording
drives the simulated loop) and the shared :mod:`nonfragile_tracker.control.validate`,
never :mod:`nonfragile_tracker.control.synthesis`; the synthesis imports it (a latency
design starts from an identification).
"""
