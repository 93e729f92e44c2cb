"""Python side of the graph contract, shared by every package of the tracker.

Installed by the ``sslfr_interfaces`` package (the lowest layer of the workspace:
the planner, the drivers and the bring-up all depend on it, it depends on nothing of
theirs):

- :mod:`sslfr_common.contract`: the facts of the graph contract (joint names, ranges,
  stow positions, step angle, switch table, phase/mode/level/link codes), once;
- :mod:`sslfr_common.params`: parameter tables (pure: the CLI validates site configs
  with the same tables the nodes declare);
- :mod:`sslfr_common.node`: node plumbing (the Jazzy main pattern once, signals,
  the log bridge, parameter declaration and run-time guard; re-exports the time
  conversions);
- :mod:`sslfr_common.timeconv`: ROS time messages <-> float seconds (pure, for the
  cores that read or build messages without rclpy).
"""
