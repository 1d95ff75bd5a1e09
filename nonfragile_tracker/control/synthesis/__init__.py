"""Synthesis and certificates: gains with a proof, and what a given gain is certified for.

The math of the paper and its extensions, as plain numpy/scipy/cvxpy: problem files
(:mod:`.problem`), the Theorem 1 LMI synthesis with its independent verification
(:mod:`.lmi`), the delay-dependent (:mod:`.delay_dependent`) and command-latency
(:mod:`.input_delay`, :mod:`.latency_design`) designs, design searches (:mod:`.design`,
:mod:`.search`, :mod:`.sweep`), the exact delay analysis of one gain (:mod:`.delay`,
:mod:`.analysis`) and the region of attraction under saturation (:mod:`.saturation`);
errors in :mod:`.errors`.  Import a name from its module: the part re-exports nothing.

See doc/theory.md (the derivations) and doc/developing.md, sections "Layout"
(``nonfragile_tracker/control/synthesis/``) and "Lint and types" (the layer rule).
"""
