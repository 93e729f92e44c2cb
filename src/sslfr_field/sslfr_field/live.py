"""The field page's live state: every collector at a glance (pure, no rclpy).

The field page node feeds plain facts decoded from each collector's topics
(``tracker/phase``, ``safety/state``, ``axes/<axis>/status``, the absorber
temperatures, ``irradiance/beam``, ``tracker/sun``, ``absorber/thermal_power`` where a
flow meter counts) with the steady time they arrived; :meth:`FieldState.snapshot`
gives the page its JSON: per collector phase and mode, safety level and reasons,
axis states and errors [rad], temperatures [degC], beam irradiance [W/m^2], flow
[m^3/s] and thermal power [W] (null: no flow meter heard), the energy of the day
[kWh] (:mod:`sslfr_field.energy`: absorbed, from the beam and the optical model; thermal,
delivered; null: not computable), and the link health: ``ok`` while something arrived within ``lost_after`` seconds (steady
clock), ``lost`` after that, ``never`` before the first message. NaN (unknown) is sent
as null.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from sslfr_common.contract import JOINTS

from .energy import DayIntegral

#: [s, steady] a collector silent this long is shown lost (its safety heartbeat is >= 10 Hz)
DEFAULT_LOST_AFTER = 5.0


def _num(x) -> float | None:
    try:
        x = float(x)
    except (TypeError, ValueError):
        return None
    return x if math.isfinite(x) else None


@dataclass
class CollectorView:
    """What the page knows of one collector."""

    id: str
    namespace: str
    page: str = ''                     # the collector's own operator page (URL), '' if unknown
    phase: str = ''
    mode: str = ''
    phase_reason: str = ''
    safety_level: str = ''
    safety_reasons: list = field(default_factory=list)
    axes: dict = field(default_factory=dict)          # axis -> {'state', 'error', 'measured'}
    temperatures: dict = field(default_factory=dict)  # 'inlet'/'outlet' -> degC
    beam: float | None = None                         # W/m^2
    flow: float | None = None                         # m^3/s (a flow meter only)
    thermal_power: float | None = None                # W, useful (m_dot c_p (T_out - T_in))
    sun: tuple | None = None                          # (zenith, azimuth) [rad] of tracker/sun
    absorbed: DayIntegral = field(default_factory=DayIntegral)   # J today (UTC day of ROS time)
    thermal: DayIntegral = field(default_factory=DayIntegral)    # J today, delivered
    last_heard: float | None = None                   # steady time [s]
    phase_heard: float | None = None                  # steady time [s] of the last tracker/phase (the planner)
    safety_heard: float | None = None                 # steady time [s] of the last safety/state
    messages: int = 0


class FieldState:
    """The live state of every collector of a field (called from one thread)."""

    def __init__(self, collectors, lost_after: float = DEFAULT_LOST_AFTER, models: dict | None = None):
        """``collectors``: (id, namespace, page URL) triples; ``models``: id ->
        absorbed-power model (:class:`sslfr_field.energy.AbsorbedModel`: ``joints`` and
        ``model(beam, zenith, azimuth, {axis: angle}) -> W``) of the collectors whose
        absorbed energy can be computed."""
        self.views = {cid: CollectorView(cid, nsp, page) for cid, nsp, page in collectors}
        self.models = dict(models or {})
        self.lost_after = float(lost_after)
        self.version = 0

    def _heard(self, cid: str, now: float) -> CollectorView:
        v = self.views[cid]
        v.last_heard = now
        v.messages += 1
        self.version += 1
        return v

    def on_phase(self, cid: str, now: float, phase: str, mode: str, reason: str) -> None:
        v = self._heard(cid, now)
        v.phase, v.mode, v.phase_reason = phase, mode, reason
        v.phase_heard = now

    def on_safety(self, cid: str, now: float, level: str, reasons) -> None:
        v = self._heard(cid, now)
        v.safety_level, v.safety_reasons = level, [str(r) for r in reasons]
        v.safety_heard = now

    def on_axis(self, cid: str, now: float, axis: str, state: str, error: float, measured: float) -> None:
        if axis not in JOINTS:
            return
        v = self._heard(cid, now)
        v.axes[axis] = {'state': state, 'error': _num(error), 'measured': _num(measured)}

    def on_temperature(self, cid: str, now: float, which: str, degc: float) -> None:
        v = self._heard(cid, now)
        v.temperatures[which] = _num(degc)

    def on_beam(self, cid: str, now: float, beam: float, stamp: float = math.nan) -> None:
        """A beam sample [W/m^2] taken at ``stamp`` [s, ROS time]: with the collector's
        optical model, the latest sun and every axis' measured angle, one absorbed-power
        sample of the day (unknown: NaN, which ends the running trapezoid)."""
        v = self._heard(cid, now)
        v.beam = _num(beam)
        model = self.models.get(cid)
        if model is None:
            return
        angles = {a: (v.axes.get(a) or {}).get('measured') for a in model.joints}
        if v.sun is None or v.beam is None or any(x is None for x in angles.values()):
            watts = math.nan
        else:
            watts = model(v.beam, v.sun[0], v.sun[1], angles)
        v.absorbed.add(stamp, watts)

    def on_sun(self, cid: str, now: float, zenith: float, azimuth: float) -> None:
        v = self._heard(cid, now)
        z, a = _num(zenith), _num(azimuth)
        v.sun = None if z is None or a is None else (z, a)

    def on_thermal(self, cid: str, now: float, flow: float, power: float, stamp: float = math.nan) -> None:
        """``absorber/thermal_power``: flow [m^3/s] and useful power [W] at ``stamp`` [s,
        ROS time], one sample of the day's delivered energy."""
        v = self._heard(cid, now)
        v.flow, v.thermal_power = _num(flow), _num(power)
        v.thermal.add(stamp, math.nan if v.thermal_power is None else v.thermal_power)

    def link(self, cid: str, now: float) -> str:
        """'ok', 'lost' (silent for more than ``lost_after`` s) or 'never'."""
        v = self.views[cid]
        if v.last_heard is None:
            return 'never'
        return 'ok' if now - v.last_heard <= self.lost_after else 'lost'

    def snapshot(self, now: float, ros_now: float | None = None) -> dict:
        """The page's JSON (plain types; unknown numbers are None). ``ros_now`` [s, ROS
        time]: an energy of an earlier day than ``ros_now``'s is shown unknown."""
        out = []
        for cid, v in self.views.items():
            absorbed, thermal = v.absorbed.kwh(ros_now), v.thermal.kwh(ros_now)
            out.append({'id': cid, 'namespace': v.namespace, 'page': v.page, 'phase': v.phase, 'mode': v.mode,
                        'phase_reason': v.phase_reason, 'safety_level': v.safety_level,
                        'safety_reasons': list(v.safety_reasons), 'axes': {k: dict(v.axes[k]) for k in JOINTS if k in v.axes},
                        'temperatures': dict(v.temperatures), 'beam': v.beam, 'flow': v.flow,
                        'thermal_power': v.thermal_power,
                        'energy_today': {'absorbed_kwh': None if absorbed is None else round(absorbed, 4),
                                         'thermal_kwh': None if thermal is None else round(thermal, 4)},
                        'link': self.link(cid, now),
                        'last_heard_s': None if v.last_heard is None else round(now - v.last_heard, 2),
                        # the planner republishes the phase every second, safety its state ten
                        # times a second: an old one on a live link is a process the station
                        # no longer hears (the page says so; its values are the last heard)
                        'phase_age_s': None if v.phase_heard is None else round(now - v.phase_heard, 2),
                        'safety_age_s': None if v.safety_heard is None else round(now - v.safety_heard, 2),
                        'messages': v.messages})
        counts = {}
        for c in out:
            counts[c['link']] = counts.get(c['link'], 0) + 1
        return {'collectors': out, 'links': counts}
