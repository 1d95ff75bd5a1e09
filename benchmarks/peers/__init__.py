"""Peers: the trackers users run instead of ours, ported faithfully with stock defaults (issue 38).

Not part of the package: benchmarks only.  :mod:`.wpilib` holds WPILib's LTV unicycle and
RAMSETE controllers (robotpy-wpimath); :mod:`.nav2_rpp` and :mod:`.nav2_mppi` are Nav2
Jazzy's Regulated Pure Pursuit and MPPI controllers (numpy ports; :mod:`.nav2_common` holds
what both run through in the Nav2 bring-up: the path, the controller server's rate and goal
checker, the velocity smoother).  Each peer module exposes the one factory shape the table
driver (``benchmarks/peers.py``) picks up:

``PEERS``
    a dict ``label -> factory``; ``factory(tracker_config)`` returns a
    :class:`~nonfragile_tracker.control.simulation.interfaces.Controller` (the factory
    shape of ``simulate_following(..., controller=...)``).  A factory that also takes the
    keyword ``plant_config`` (a :class:`~nonfragile_tracker.control.simulation.plant.PlantConfig`)
    is given the base it runs on - what a user who measured the base would set (e.g. the
    latency a latency-compensated variant assumes); one that takes ``trajectory`` is given
    the trajectory (a path follower is handed the path).  The tracker config carries the
    speed limits and nothing of our gain that a peer should read.

``VARIANTS`` (optional)
    the labels of ``PEERS`` that are not the library as it ships (set up per base, e.g. a
    latency fix); the others are the "stock" peers of issue 38's comparison.

A module whose import fails (its library missing) is skipped by the driver with the reason.
:mod:`.adapter` runs any such factory, and ours, through the same loop on the same base.
"""
