"""SSLFR planner: ephemeris (NREL SPA), tracker geometry, planner node, optical analysis."""
