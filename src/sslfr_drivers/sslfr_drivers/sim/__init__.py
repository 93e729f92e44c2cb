"""Simulated boards: they speak the board protocol like the firmware, over a real pty
(``sim_board`` console script) or behind a simulated XBee coordinator.

Board kinds are looked up in :data:`KINDS` (``--kind`` of ``sim_board``): name ->
``'module:Class'``; the class derives from :class:`sslfr_drivers.sim.base.SimBoard`
and provides ``from_options(options: dict, rng)``. Sensor-board models register
here with one line each.
"""

KINDS: dict[str, str] = {
    'axis': 'sslfr_drivers.sim.axis:AxisSim',
    'gps': 'sslfr_drivers.sim.sensors:GpsSim',
    'absorber': 'sslfr_drivers.sim.sensors:AbsorberSim',
    'irradiance': 'sslfr_drivers.sim.sensors:IrradianceSim',
}


def board_class(kind: str):
    """Import and return the simulated-board class registered for ``kind``."""
    import importlib
    try:
        spec = KINDS[kind]
    except KeyError:
        raise ValueError(f'unknown board kind {kind!r}; known: {", ".join(sorted(KINDS))}') from None
    module, _, name = spec.partition(':')
    return getattr(importlib.import_module(module), name)
