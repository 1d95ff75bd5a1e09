"""Simulation: the step functions the nodes run, and the in-process loops over them.

The unicycle and its linearization (:mod:`.model`), the actuator, sensor and latency
models (:mod:`.actuator`, :mod:`.sensors`, :mod:`.predictor`), the tracker's step from the
odometry stamps (:mod:`.timing`), paths and timed
trajectories within limits (:mod:`.reference`, :mod:`.trajectory`, :mod:`.limits`), the
tracking law in its scalar and vector forms (:mod:`.law`), the
plant and tracker step functions (:mod:`.loop`, :mod:`.follow`) and the gain file they
read (:mod:`.gains`), and the loops that run them in process, one case or many at once
(:mod:`.simulate`, :mod:`.batch`, :mod:`.study`, :mod:`.metrics`).  A lockstep ROS run of
the nodes equals these loops to 1e-9.
Its errors are in :mod:`.errors`, under the package's root error.  Import a name from
its module (``from nonfragile_tracker.control.simulation.loop import Tracker``): the
part re-exports nothing, so importing it loads none of its modules.

Notes
-----
Layer rule: this part imports only numpy/scipy, the package's foundation and the shared
:mod:`nonfragile_tracker.control.validate`; never
:mod:`nonfragile_tracker.control.synthesis` (so never cvxpy: a node starts without it) nor
:mod:`nonfragile_tracker.control.identification`.
"""
