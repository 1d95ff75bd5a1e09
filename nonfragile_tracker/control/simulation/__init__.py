"""Simulation: the step functions the nodes run, and the in-process loops over them.

The unicycle and its linearization (:mod:`.model`), the actuator, sensor and latency
models (:mod:`.actuator`, :mod:`.sensors`, :mod:`.predictor`), the step from the odometry
stamps (:mod:`.timing`), paths and trajectories within limits (:mod:`.reference`,
:mod:`.trajectory`, :mod:`.limits`), the tracking law (:mod:`.law`), the tracker and plant
step functions (:mod:`~.simulation.tracker`, :mod:`~.simulation.plant`, :mod:`.follow`),
the gain file (:mod:`.gains`), and the loops that run them in process (:mod:`.simulate`,
:mod:`.batch`, :mod:`.study`, :mod:`.metrics`); errors in :mod:`.errors`.  Import a name
from its module: the part re-exports nothing.

See doc/developing.md, sections "Layout" (``nonfragile_tracker/control/simulation/``) and
"Lint and types" (the layer rule: no synthesis, so no cvxpy, and no identification).
"""
