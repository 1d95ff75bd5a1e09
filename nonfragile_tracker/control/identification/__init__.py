"""Identification: command latency and actuator lags from commands and odometry.

Offline identification from a recording and its file (:mod:`.identify`), in-process
recordings of a simulated base to identify (:mod:`.recording`), and the tracker's runtime
certificate monitor, which estimates the same quantities over a sliding window and
compares them with the gain's certificate (:mod:`.monitor`).
Its errors are in :mod:`.errors`, under the package's root error.

Notes
-----
Layer rule: this part may import :mod:`nonfragile_tracker.control.simulation` (a recording
drives the simulated loop) and the shared :mod:`nonfragile_tracker.control.validate`,
never :mod:`nonfragile_tracker.control.synthesis`; the synthesis imports it (a latency
design starts from an identification).
"""
from __future__ import annotations

from typing import TYPE_CHECKING

from .. import lazy_exports

__all__ = [
    # errors
    'IdentificationError', 'NotEnoughDataError', 'InsufficientExcitationError', 'PoorFitError',
    'IdentificationFileError', 'MonitorError',
    # identify
    'commands_follow_odometry', 'CommandSamples', 'Identification', 'identify_latency',
    'measurement_to_command_delay', 'OdometrySamples', 'read_identification',
    'write_identification',
    # recording
    'joystick_steps', 'load_cases', 'record_case', 'record_open_loop', 'record_tracking',
    # monitor
    'adapted_prediction', 'Certificate', 'certificate_from_design', 'certificate_from_parameters',
    'estimate_latency', 'evaluate', 'LatencyEstimate', 'LEVEL_NAMES', 'MonitorSettings',
    'MonitorWorker',
]

if TYPE_CHECKING:
    from .errors import (IdentificationError, NotEnoughDataError, InsufficientExcitationError,
                         PoorFitError, IdentificationFileError, MonitorError)
    from .identify import (commands_follow_odometry, CommandSamples, Identification,
                           identify_latency, measurement_to_command_delay, OdometrySamples,
                           read_identification, write_identification)
    from .recording import (joystick_steps, load_cases, record_case, record_open_loop,
                            record_tracking)
    from .monitor import (adapted_prediction, Certificate, certificate_from_design,
                          certificate_from_parameters, estimate_latency, evaluate, LatencyEstimate,
                          LEVEL_NAMES, MonitorSettings, MonitorWorker)
else:
    __getattr__, __dir__ = lazy_exports(__name__)
