"""Offline analysis of an SSLFR: power models, annual energy, EAR, LCOE, tilt search,
beam irradiance and the ``sslfr analyse`` command (seed 000 section 5, seed 001).

Analysis-only code: the tracker (planner node, day tables, laws) never imports this
package; it shares the 3-D ray model :mod:`sslfr_planner.raytrace` and the collector
geometry :class:`sslfr_planner.collector.FieldGeometry` with it. Modules:
:mod:`.optics` (power models), :mod:`.performance` (error table, year, tilt search,
day energy), :mod:`.beam` (DNI), :mod:`.cli` (``sslfr analyse``).
"""
