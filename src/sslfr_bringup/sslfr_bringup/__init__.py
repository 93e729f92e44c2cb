"""SSLFR tracker bringup: the node set, the launch file, the process supervisor and the sslfr command."""
