"""Synthesis and certificates: gains with a proof, and what a given gain is certified for.

The math of the paper and its extensions, as plain numpy/scipy/cvxpy: problem files
(:mod:`.problem`), the Theorem 1 LMI synthesis with its independent verification
(:mod:`.lmi`), the delay-dependent (:mod:`.delay_dependent`) and command-latency
(:mod:`.input_delay`, :mod:`.latency_design`) designs, design searches (:mod:`.design`,
:mod:`.search`, :mod:`.sweep`), the exact delay analysis of one gain (:mod:`.delay`,
:mod:`.analysis`) and the region of attraction under saturation (:mod:`.saturation`).
Its errors are in :mod:`.errors`, under the package's root error.

Notes
-----
Layer rule: this part imports the shared :mod:`nonfragile_tracker.control.validate` and
:mod:`nonfragile_tracker.control.identification` (a latency design starts from an
identification), never :mod:`nonfragile_tracker.control.simulation`; the simulation does
not import it either, so the nodes run without cvxpy.  Derivations: ``doc/theory.md``.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

from .. import lazy_exports

__all__ = [
    # errors
    'ProblemError', 'LmiError', 'InfeasibleError', 'SolverFailure', 'CertificateError',
    # problem
    'is_stabilizable', 'load_problem', 'Problem', 'problem_from_mapping',
    # search
    'largest_feasible',
    # lmi
    'certified_perturbation_scale', 'certify_gain', 'CertifyResult', 'SynthesisResult',
    'synthesize', 'UntrustedGainWarning', 'verify_certificate',
    # design
    'at_gain_norm', 'max_decay_rate', 'max_perturbation_scale', 'min_gain_norm', 'shifted_problem',
    # delay_dependent
    'max_certified_delay', 'synthesize_delay_dependent', 'verify_delay_dependent',
    # input_delay
    'certified_input_delay_of_gain', 'certify_input_delay', 'max_certified_input_delay',
    'max_input_delay_decay_rate', 'synthesize_input_delay', 'verify_input_delay',
    # latency_design
    'design_for_latency', 'exact_figures', 'lagged_problem', 'latency_figures',
    'plan_from_identification',
    # analysis
    'analyse_gain', 'format_analysis',
    # delay
    'closed_loop_matrix', 'delay_margin', 'fragility_margin', 'FragilityResult', 'is_stable',
    'rightmost_roots', 'RootsResult', 'spectral_abscissa', 'worst_case_abscissa',
    # saturation
    'format_saturation', 'premise_failure', 'saturation_certificate', 'SaturationLimits',
    'verify_saturation',
    # sweep
    'design_point', 'pareto_front', 'plot_sweep', 'records_for_json', 'run_sweep', 'sweep_points',
    'sweep_table', 'SweepPoint',
]

if TYPE_CHECKING:
    from .errors import ProblemError, LmiError, InfeasibleError, SolverFailure, CertificateError
    from .problem import is_stabilizable, load_problem, Problem, problem_from_mapping
    from .search import largest_feasible
    from .lmi import (certified_perturbation_scale, certify_gain, CertifyResult, SynthesisResult,
                      synthesize, UntrustedGainWarning, verify_certificate)
    from .design import (at_gain_norm, max_decay_rate, max_perturbation_scale, min_gain_norm,
                         shifted_problem)
    from .delay_dependent import (max_certified_delay, synthesize_delay_dependent,
                                  verify_delay_dependent)
    from .input_delay import (certified_input_delay_of_gain, certify_input_delay,
                              max_certified_input_delay, max_input_delay_decay_rate,
                              synthesize_input_delay, verify_input_delay)
    from .latency_design import (design_for_latency, exact_figures, lagged_problem, latency_figures,
                                 plan_from_identification)
    from .analysis import analyse_gain, format_analysis
    from .delay import (closed_loop_matrix, delay_margin, fragility_margin, FragilityResult,
                        is_stable, rightmost_roots, RootsResult, spectral_abscissa,
                        worst_case_abscissa)
    from .saturation import (format_saturation, premise_failure, saturation_certificate,
                             SaturationLimits, verify_saturation)
    from .sweep import (design_point, pareto_front, plot_sweep, records_for_json, run_sweep,
                        sweep_points, sweep_table, SweepPoint)
else:
    __getattr__, __dir__ = lazy_exports(__name__)
