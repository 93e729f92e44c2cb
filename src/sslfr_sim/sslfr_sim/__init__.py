"""Simulation of the SSLFR tracker, never imported by the product: simulated boards that
speak the board protocol like the firmware, over a real pty (``sim_board`` console
script) or behind a simulated XBee coordinator; the firmware in simavr (``fw_board``);
simulated days (``scenario``, ``faults``) and the ``sslfr sim`` command (``sim_cli``).

Board kinds are looked up in :data:`KINDS` (``--kind`` of ``sim_board``): name ->
``'module:Class'``; the class derives from :class:`sslfr_sim.base.SimBoard`
and provides ``from_options(options: dict, rng)``. Sensor-board models register
here with one line each.
"""

KINDS: dict[str, str] = {
    'axis': 'sslfr_sim.axis:AxisSim',
    'actuator': 'sslfr_sim.actuator:ActuatorSim',
    'axis_noswitch': 'sslfr_sim.switchless:SwitchlessAxisSim',
    'gps': 'sslfr_sim.sensors:GpsSim',
    'absorber': 'sslfr_sim.sensors:AbsorberSim',
    'irradiance': 'sslfr_sim.sensors:IrradianceSim',
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
