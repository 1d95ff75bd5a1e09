"""Identification: command latency and actuator lags from commands and odometry.

Offline identification from a recording (:mod:`.identify`, :mod:`.lag_fit`), its records
and file (:mod:`.records`), the bring-up's designed excitation (:mod:`.excitation`), and
the tracker's runtime certificate monitor, which estimates the same quantities over a
sliding window and compares them with the gain's certificate (:mod:`.monitor`); errors in
:mod:`.errors`.  Import a name from its module: the part re-exports nothing.

See doc/theory.md, sections "Latency identification" and "Latency monitor", and
doc/developing.md, section "Lint and types" (the layer rule: simulation may be imported,
synthesis never).
"""
