"""Synthesis and certificates: gains with a proof, and what a given gain is certified for.

The math of the paper and its extensions, as plain numpy/scipy/cvxpy: problem files
(:mod:`.problem`), the Theorem 1 LMI synthesis with its independent verification
(:mod:`.lmi`), the delay-dependent (:mod:`.delay_dependent`) and command-latency
(:mod:`.input_delay`, :mod:`.latency_design`) designs, design searches (:mod:`.design`,
:mod:`.search`, :mod:`.sweep`), the exact delay analysis of one gain (:mod:`.delay`,
:mod:`.analysis`) and the region of attraction under saturation (:mod:`.saturation`).
Its errors are in :mod:`.errors`, under the package's root error.  Import a name from
its module (``from nonfragile_tracker.control.simulation.loop import Tracker``): the
part re-exports nothing, so importing it loads none of its modules.

Notes
-----
Layer rule: this part imports the shared :mod:`nonfragile_tracker.control.validate` and
:mod:`nonfragile_tracker.control.identification` (a latency design starts from an
identification), never :mod:`nonfragile_tracker.control.simulation`; the simulation does
not import it either, so the nodes run without cvxpy.  Derivations: ``doc/theory.md``.
"""
