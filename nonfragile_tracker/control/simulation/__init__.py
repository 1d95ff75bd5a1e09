"""Simulation: the step functions the nodes run, and the in-process loops over them.

The unicycle and its linearization (:mod:`.model`), the actuator, sensor and latency
models (:mod:`.actuator`, :mod:`.sensors`, :mod:`.predictor`), the tracker's step from the
odometry stamps (:mod:`.timing`), paths and timed
trajectories within limits (:mod:`.reference`, :mod:`.trajectory`, :mod:`.limits`), the
plant and tracker step functions (:mod:`.loop`, :mod:`.follow`) and the gain file they
read (:mod:`.gains`), and the loops that run them in process, one case or many at once
(:mod:`.simulate`, :mod:`.batch`, :mod:`.study`, :mod:`.metrics`).  A lockstep ROS run of
the nodes equals these loops to 1e-9.
Its errors are in :mod:`.errors`, under the package's root error.

Notes
-----
Layer rule: this part imports only numpy/scipy, the package's foundation and the shared
:mod:`nonfragile_tracker.control.validate`; never
:mod:`nonfragile_tracker.control.synthesis` (so never cvxpy: a node starts without it) nor
:mod:`nonfragile_tracker.control.identification`.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

from .. import lazy_exports

__all__ = [
    # errors
    'SingularSpeedError', 'PathError', 'TrajectoryError', 'LoopConfigError', 'GainFileError',
    'BatchError',
    # model
    'double_integrator_model', 'inputs_from_u', 'u_from_inputs', 'xi_from_state',
    # actuator
    'ActuatorModel',
    # predictor
    'invert_lag', 'LatencyPredictor',
    # reference
    'circle', 'figure_eight', 'make_path', 'Path', 'RefSample',
    # trajectory
    'analytic_knots', 'from_poses', 'from_states', 'from_waypoints', 'load_waypoints',
    'read_waypoint_file', 'time_law', 'Trajectory', 'TrajectorySamples',
    # limits
    'LIMIT_NAMES', 'Limits', 'retime',
    # follow
    'Follower', 'MAX_START_DISTANCE', 'path_errors', 'REST_SPEED', 'simulate_following',
    'start_offset', 'START_TOLERANCE', 'trajectory_time',
    # loop
    'Command', 'delay_steps', 'odometry_period_steps', 'PlantConfig', 'quaternion_to_yaw',
    'Tracker', 'TrackerConfig', 'UnicyclePlant', 'validate_gain', 'yaw_to_quaternion',
    # simulate
    'report_override', 'run_loop', 'simulate_delay_loop', 'simulate_tracking',
    # timing
    'PeriodEstimator', 'period_disagreement',
    # batch
    'BatchCases', 'PathBatch', 'perturbation_schedule', 'sample_deltas', 'simulate_batch',
    'simulate_delay_loop_batch',
    # study
    'plot_study', 'run_study', 'StudySpec',
    # metrics
    'tracking_metrics', 'TrackingMetrics',
    # gains
    'DESIGN_SECTION', 'gain_from_parameters', 'read_gain_design', 'read_gain_file',
    'write_gain_file',
]

if TYPE_CHECKING:
    from .errors import (SingularSpeedError, PathError, TrajectoryError, LoopConfigError,
                         GainFileError, BatchError)
    from .model import double_integrator_model, inputs_from_u, u_from_inputs, xi_from_state
    from .actuator import ActuatorModel
    from .predictor import invert_lag, LatencyPredictor
    from .reference import circle, figure_eight, make_path, Path, RefSample
    from .trajectory import (analytic_knots, from_poses, from_states, from_waypoints,
                             load_waypoints, read_waypoint_file, time_law, Trajectory,
                             TrajectorySamples)
    from .limits import LIMIT_NAMES, Limits, retime
    from .follow import (Follower, MAX_START_DISTANCE, path_errors, REST_SPEED, simulate_following,
                         start_offset, START_TOLERANCE, trajectory_time)
    from .loop import (Command, delay_steps, odometry_period_steps, PlantConfig, quaternion_to_yaw,
                       Tracker, TrackerConfig, UnicyclePlant, validate_gain, yaw_to_quaternion)
    from .simulate import report_override, run_loop, simulate_delay_loop, simulate_tracking
    from .timing import PeriodEstimator, period_disagreement
    from .batch import (BatchCases, PathBatch, perturbation_schedule, sample_deltas, simulate_batch,
                        simulate_delay_loop_batch)
    from .study import plot_study, run_study, StudySpec
    from .metrics import tracking_metrics, TrackingMetrics
    from .gains import (DESIGN_SECTION, gain_from_parameters, read_gain_design, read_gain_file,
                        write_gain_file)
else:
    __getattr__, __dir__ = lazy_exports(__name__)
