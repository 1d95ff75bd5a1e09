"""The ROS-free control core, in three parts.

:mod:`~nonfragile_tracker.control.synthesis`
    Gains and their certificates (numpy/scipy/cvxpy).
:mod:`~nonfragile_tracker.control.simulation`
    The step functions the nodes run and the in-process loops over them (no cvxpy).
:mod:`~nonfragile_tracker.control.identification`
    Latency and lags from commands and odometry; the runtime certificate monitor.

:mod:`~nonfragile_tracker.control.validate`, the one shape/number validator, is shared by
the three.  Arrows: synthesis -> identification -> simulation; none between synthesis and
simulation.  Nothing here imports rclpy, rosbags or the package's ROS layers.  Names are
imported from their modules (``from nonfragile_tracker.control.simulation.loop import
Tracker``); the packages themselves hold only their docstrings.
"""
