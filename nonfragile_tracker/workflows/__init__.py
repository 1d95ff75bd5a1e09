"""Runs made of nodes, bags and designs: the library under the CLI's commands.

:mod:`.runner` (lockstep, real-time and composed runs of the four nodes),
:mod:`.dds_replay` (a bag replayed over DDS into a tracker node), :mod:`.golden` (the
golden bags), :mod:`.reproduce` (the paper's reproduction report) and
:mod:`.commissioning` (the bring-up's identify, design, files and report; run by the
bring-up node in a child process).  The highest layer below the commands.

See doc/developing.md, section "Layout".
"""
