"""SSLFR tracker bringup: node set, CLI, recorder, replay and report."""
