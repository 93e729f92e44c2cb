"""The safety supervisor's limits and clocks (pure Python, no rclpy).

:class:`SafetyConfig` holds every tunable limit of the rules (units in the field
comments); :func:`with_changes` makes a validated copy. The node builds it from its
parameters (:mod:`sslfr_safety.params`). The clocks are what the core reads:
:class:`SystemClock` in the node (through ROS STEADY_TIME), :class:`FakeClock` in tests.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

from sslfr_common.contract import JOINTS, SWITCH_POSITION, SWITCHES, driver_node

#: Watchable nodes (default node names, docs/architecture.md).
WATCHABLE = ('planner', *(driver_node(j) for j in JOINTS), 'absorber_board', 'irradiance', 'gps')


class SystemClock:
    """Real clocks: ``steady()`` = CLOCK_MONOTONIC [s], ``wall()`` = Unix time [s]."""

    @staticmethod
    def steady() -> float:
        return time.monotonic()

    @staticmethod
    def wall() -> float:
        return time.time()


class FakeClock:
    """Injectable clock for tests: steady and wall time advanced/stepped by hand."""

    def __init__(self, steady: float = 1000.0, wall: float = 1_750_000_000.0):
        self._steady = float(steady)
        self._wall = float(wall)

    def steady(self) -> float:
        return self._steady

    def wall(self) -> float:
        return self._wall

    def advance(self, dt: float) -> None:
        """Let ``dt`` [s] pass on both clocks."""
        self._steady += dt
        self._wall += dt

    def step_wall(self, dt: float) -> None:
        """Step only the wall clock by ``dt`` [s] (NTP/GPS correction, operator)."""
        self._wall += dt


@dataclass(frozen=True)
class SafetyConfig:
    """Tunable limits. Units: degC, K, s, rad, W/m^2 as named.

    ``watchdogs`` maps a node name (:data:`WATCHABLE`) to ``(timeout [s], action)``
    with action ``'WARN'`` or ``'STOW'``. ``present``: the watchable nodes this
    collector's node set runs (its description's movements and boards): the axes
    judged are theirs (:attr:`joints`) and a node absent from it is never watched.
    """

    temperature_limit: float = 150.0      # [degC] seed 000 section 3.5.3
    hysteresis: float = 10.0              # [K] must cool below limit - hysteresis
    cool_hold: float = 60.0               # [s] ... for this long before reset
    auto_reset: bool = False              # clear temperature latches without a call
    silent_timeout: float = 2.0           # [s] thermocouple silent while TRACKING
    sensor_recover_hold: float = 2.0      # [s] valid samples before a sensor fault clears
    sensor_fault_latched: bool = False    # thermocouple faults also need safety/reset
    stuck_timeout: float = 300.0          # [s] no change while the sun is on the receiver
    stuck_tolerance: float = 0.0          # [K] a change must exceed this
    stuck_min_beam: float = 200.0         # [W/m^2] beam at which the sun counts as on
    valid_min: float = -40.0              # [degC] plausible thermocouple range
    valid_max: float = 1100.0             # [degC]
    switch_window: float = 0.05           # [rad] closure expected within this of nominal
    switch_lookback: float = 1.0          # [s] measured angles that make up the axis' path
    switch_positions: dict = field(default_factory=lambda: dict(SWITCH_POSITION))
    stuck_switch_travel: float = 0.1      # [rad] travel with a switch closed at homing
    status_max_age: float = 1.0           # [s] axis status older than this is unknown
    beam_max_age: float = 5.0             # [s] beam older than this is unknown
    startup_grace: float = 10.0           # [s] before never-heard nodes count as silent
    require_site_and_time: bool = True
    trust_system_clock: bool = True       # a plausible system clock counts as time
    min_valid_unix_time: float = 1_704_067_200.0  # [s] 2024-01-01T00:00Z
    # wind (issue 35; defaults and their sources: src/sslfr_safety/README.md "Wind")
    wind_enabled: bool = False            # an anemometer is fitted: judge `wind`
    wind_gust_limit: float = 20.0         # [m/s] 3 s gust above this -> wind stow
    wind_mean_limit: float = 14.0         # [m/s] 10 min mean above this -> wind stow
    wind_hysteresis: float = 3.0          # [m/s] release only below mean_limit - this ...
    wind_hold: float = 1800.0             # [s] ... held for this long
    wind_silent_warn: float = 10.0        # [s] no wind message for this long -> WARN
    wind_silent_stow: float = 60.0        # [s] ... for this long -> treated as wind (0 = never)
    wind_stuck_window: float = 1800.0     # [s] 0 m/s all along while the beam swings -> WARN
    wind_stuck_beam_swing: float = 300.0  # [W/m^2] beam max - min over that window
    watchdogs: dict = field(default_factory=lambda: {
        'planner': (5.0, 'STOW'),
        **{driver_node(joint): (2.0, 'STOW') for joint in JOINTS},
        'absorber_board': (2.0, 'STOW'),
        'irradiance': (5.0, 'WARN'),
        'gps': (5.0, 'WARN'),
    })
    present: tuple = WATCHABLE

    @property
    def joints(self) -> tuple[str, ...]:
        """The collector's movements (contract order): those whose driver is present."""
        return tuple(j for j in JOINTS if driver_node(j) in self.present)

    def validate(self) -> None:
        """Raise ValueError naming the first bad value."""
        def pos(name, v, zero_ok=False):
            if not (isinstance(v, (int, float)) and math.isfinite(v) and (v >= 0 if zero_ok else v > 0)):
                raise ValueError(f'{name} must be a finite {"non-negative" if zero_ok else "positive"} '
                                 f'number, got {v!r}')
        if not (math.isfinite(self.temperature_limit) and -40.0 < self.temperature_limit < 1100.0):
            raise ValueError(f'temperature_limit must be in (-40, 1100) degC, got {self.temperature_limit!r}')
        pos('hysteresis', self.hysteresis, zero_ok=True)
        pos('cool_hold', self.cool_hold, zero_ok=True)
        pos('silent_timeout', self.silent_timeout)
        pos('sensor_recover_hold', self.sensor_recover_hold, zero_ok=True)
        pos('stuck_timeout', self.stuck_timeout)
        pos('stuck_tolerance', self.stuck_tolerance, zero_ok=True)
        pos('stuck_min_beam', self.stuck_min_beam, zero_ok=True)
        pos('switch_window', self.switch_window, zero_ok=True)
        pos('switch_lookback', self.switch_lookback, zero_ok=True)
        pos('stuck_switch_travel', self.stuck_switch_travel)
        pos('status_max_age', self.status_max_age)
        pos('beam_max_age', self.beam_max_age)
        pos('startup_grace', self.startup_grace, zero_ok=True)
        pos('wind_gust_limit', self.wind_gust_limit)
        pos('wind_mean_limit', self.wind_mean_limit)
        pos('wind_hysteresis', self.wind_hysteresis, zero_ok=True)
        if not self.wind_hysteresis < self.wind_mean_limit:
            raise ValueError(f'wind_hysteresis {self.wind_hysteresis} must be < wind_mean_limit '
                             f'{self.wind_mean_limit} (the release threshold is their difference)')
        pos('wind_hold', self.wind_hold, zero_ok=True)
        pos('wind_silent_warn', self.wind_silent_warn)
        pos('wind_silent_stow', self.wind_silent_stow, zero_ok=True)
        if self.wind_silent_stow and self.wind_silent_stow < self.wind_silent_warn:
            raise ValueError(f'wind_silent_stow {self.wind_silent_stow} s must be 0 (never) or >= '
                             f'wind_silent_warn {self.wind_silent_warn} s')
        pos('wind_stuck_window', self.wind_stuck_window)
        pos('wind_stuck_beam_swing', self.wind_stuck_beam_swing)
        if not (self.valid_min < self.valid_max):
            raise ValueError(f'valid_min {self.valid_min} must be < valid_max {self.valid_max}')
        if set(self.switch_positions) != set(SWITCHES) or not all(
                math.isfinite(v) for v in self.switch_positions.values()):
            raise ValueError(f'switch_positions needs finite angles for exactly {SWITCHES}')
        unknown = [n for n in self.present if n not in WATCHABLE]
        if unknown:
            raise ValueError(f'present nodes {unknown} unknown; known: {", ".join(WATCHABLE)}')
        for node, spec in self.watchdogs.items():
            if node not in self.present:
                raise ValueError(f'watchdog node {node!r} is not in this collector\'s node set '
                                 f'({", ".join(self.present)})')
            if node not in WATCHABLE:
                raise ValueError(f'watchdog node {node!r} unknown; known: {", ".join(WATCHABLE)}')
            timeout, action = spec
            pos(f'watchdog {node} timeout', timeout)
            if action not in ('WARN', 'STOW'):
                raise ValueError(f'watchdog {node} action must be WARN or STOW, got {action!r}')


def with_changes(config: SafetyConfig, **changes) -> SafetyConfig:
    """A validated copy of ``config`` with ``changes`` applied (raises ValueError)."""
    new = replace(config, **changes)
    new.validate()
    return new
