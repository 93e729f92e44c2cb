"""Power models of a small-scale linear Fresnel reflector (pure numpy, no rclpy).

Built on the 3-D ray model :mod:`sslfr_planner.raytrace` (the geometry of every ray,
its landing point on the tube, end losses and the illuminated length) with the
optical constants of seed 000 Table 3; docs/optics.md derives everything and lists
the assumptions the seeds leave open.

* :func:`power`: power absorbed by the tube, seed 000 eqs. 18-23 evaluated on the
  traced rays: DNI * eta_i * cos(theta_i) * (mirror area whose rays reach the tube
  directly + rho_rc * area whose rays enter the cavity and miss it). ``incidence``
  chooses theta_i: the 3-D angle between the sun and the mirror's normal (the
  physics, default), or its projection on the plane perpendicular to the rows
  (seed 000's reading of eq. 18, as its transversal study (Figs. 21-24) evaluates it;
  it leaves out the cosine loss of the sun's longitudinal angle).
* :func:`power_seed001`: seed 001 annex eq. 20, DNI * eta_opt * IAM_i * l_a,i * l_ci,i,
  with the illuminated length l_a,i traced in 3-D (replaces eqs. 30-32).
* :func:`transversal_capture`: seed 000 eqs. 17-24 in closed form for the transversal
  plane (the reference the trace reproduces at solar noon and for a sun in that plane;
  used by the simulated absorber).
* :func:`installation_area`, :func:`lcoe`: seed 000 eqs. 26-29, seed 001 eqs. 21-25.

Frames and signs: :mod:`sslfr_planner.raytrace` and docs/conventions.md. All angles
radians, lengths metres, irradiance W/m^2, power W.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from .. import geometry as _geometry
from .. import raytrace
from ..collector import FieldGeometry

#: how the mirrors' fixed offsets psi_i are set (docs/optics.md, "mirror aim")
AIMS = ('focused', 'fixed')
#: which angle theta_i of seed 000 eq. 18 multiplies the mirror's area
INCIDENCES = ('3d', 'transversal')


@dataclass(frozen=True)
class OpticalParameters:
    """Optical constants of an SSLFR and the model's open assumptions (seed 000 Table 3).

    Attributes
    ----------
    geometry : FieldGeometry
        The mirror field and receiver (one definition, shared with the tracker).
    reflectivity : float
        rho of the mirrors [-].
    cleanliness_mirror, cleanliness_glass : float
        CI_m, CI_g [-].
    transmissivity_low, transmissivity_high : float
        tau of the glass for alpha_i <= 20 deg and alpha_i > 20 deg [-] (seed 000 Table 3
        gives 0.87 and 0.85 up to 30 deg; 0.85 is kept beyond: an assumption).
    absorptivity : float
        alpha_b of the tube [-].
    cavity_reflectivity : float
        rho_rc of the receiver cavity for rays that miss the tube [-] (seed 000 leaves
        it to its ref. 65: 0.90, an assumption).
    cavity_aperture : float
        Width A of the receiver cavity's opening in the receiver plane [m]: rays that
        miss the tube inside it reach the tube after one cavity reflection, rays
        outside it are lost (not in the seeds: 0.12 m, an assumption).
    mirror_aim : str
        'focused': each mirror's offset psi_i = -atan(x_i / h_eff) sends its rays to the
        tube at the receiver's actual distance h_eff = h cos(beta_a) / cos(beta_a -
        beta_M) from the tilted rows, as seed 000 eqs. 11-14 state the mirrors are
        adjusted ("reaches the focal point after a single reflection"); 'fixed': the
        offsets of eq. 14 set once for the untilted height h (one drive, offsets
        fixed at assembly): tilting both rows and tube by b brings the tube to h cos b
        from the rows and defocuses the outer mirrors.
    """

    geometry: FieldGeometry = field(default_factory=FieldGeometry)
    reflectivity: float = 0.94
    cleanliness_mirror: float = 0.96
    cleanliness_glass: float = 0.96
    transmissivity_low: float = 0.87
    transmissivity_high: float = 0.85
    absorptivity: float = 0.95
    cavity_reflectivity: float = 0.90
    cavity_aperture: float = 0.12
    mirror_aim: str = 'focused'

    def __post_init__(self):
        if not isinstance(self.geometry, FieldGeometry):
            raise ValueError(f'geometry must be a FieldGeometry, got {self.geometry!r}')
        if self.geometry.tube_diameter <= 0:
            raise ValueError('tube_diameter must be > 0 m for the optical model')
        if not self.cavity_aperture >= self.geometry.tube_diameter:
            raise ValueError('cavity_aperture must be >= tube_diameter')
        if self.mirror_aim not in AIMS:
            raise ValueError(f'mirror_aim must be one of {", ".join(AIMS)}, got {self.mirror_aim!r}')
        for name in ('reflectivity', 'cleanliness_mirror', 'cleanliness_glass', 'transmissivity_low',
                     'transmissivity_high', 'absorptivity', 'cavity_reflectivity'):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0.0 <= value <= 1.0:
                raise ValueError(f'{name} must be in [0, 1], got {value!r}')


def optical_yield(p: OpticalParameters) -> np.ndarray:
    """Total optical yield eta_opt per mirror [-] (seed 000 eq. 19, seed 001 eq. 26).

    eta_opt = rho * CI_m * CI_g * tau * alpha_b, with tau from seed 000 Table 3
    chosen by the mirror's |alpha_i| (0.87 up to 20 deg, 0.85 above).
    """
    alpha = np.abs(p.geometry.receiver_angles())
    tau = np.where(alpha <= np.radians(20.0), p.transmissivity_low, p.transmissivity_high)
    return p.reflectivity * p.cleanliness_mirror * p.cleanliness_glass * tau * p.absorptivity


def receiver_distance(beta_m, beta_a, geometry: FieldGeometry):
    """Distance h_eff from the tilted rows' plane to the tube's axis at the row centre [m].

    h_eff = h cos(beta_a) / cos(beta_a - beta_M), h = f + D/2: the tube's axis crosses
    the plane through the central row's centre perpendicular to the rows at that
    distance along the rows' normal (h for horizontal rows, h cos b for beta_M = beta_a = b).
    """
    bm = np.asarray(beta_m, dtype=float)
    ba = np.asarray(beta_a, dtype=float)
    return geometry.aim_height * np.cos(ba) / np.cos(ba - bm)


def mirror_offsets(beta_m, beta_a, p: OpticalParameters):
    """Offsets psi_i of the mirrors from the central one [rad], (..., 2n+1) (``mirror_aim``)."""
    g = p.geometry
    if p.mirror_aim == 'fixed':
        return g.receiver_angles()
    h = receiver_distance(beta_m, beta_a, g)
    return -np.arctan(g.mirror_positions() / np.asarray(h)[..., None])


def trace(sun, beta_0, beta_m, beta_a, p: OpticalParameters, tube=None) -> raytrace.Trace:
    """:func:`sslfr_planner.raytrace.trace` with the mirrors aimed as ``p.mirror_aim`` says.

    ``tube`` = (L_a^r, L_a^l) [m] overrides the geometry's tube placement.
    """
    g = p.geometry if tube is None else placed(p.geometry, tube)
    return raytrace.trace(sun, beta_0, beta_m, beta_a, g, offsets=mirror_offsets(beta_m, beta_a, p))


def placed(geometry: FieldGeometry, tube) -> FieldGeometry:
    """``geometry`` with the absorber tube at (L_a^r, L_a^l) = ``tube`` [m]."""
    return replace(geometry, tube_right=float(tube[0]), tube_left=float(tube[1]))


def incidence_factor(tr: raytrace.Trace, sun, beta_m, incidence: str = '3d'):
    """cos theta_i of seed 000 eq. 18 per mirror [-]: 3-D, or projected on the plane
    perpendicular to the rows (cos theta_i / cos theta_perp, theta_perp the sun's angle
    to that plane)."""
    if incidence == '3d':
        return tr.cos_incidence
    if incidence != 'transversal':
        raise ValueError(f'incidence must be one of {", ".join(INCIDENCES)}, got {incidence!r}')
    r, _ = raytrace.structure_vectors(beta_m)
    along = np.sum(np.asarray(sun, dtype=float) * r, axis=-1)
    return tr.cos_incidence / np.sqrt(np.clip(1.0 - along ** 2, 1e-12, None))[..., None]


def power(dni, sun, beta_0, beta_m, beta_a, p: OpticalParameters, incidence: str = '3d', tube=None,
          per_mirror: bool = False, endless: bool = False):
    """Power absorbed by the tube [W] (seed 000 eqs. 18-23 on the 3-D trace).

    Parameters
    ----------
    dni : array_like
        Direct normal irradiance [W/m^2] (0 with the sun down).
    sun : array_like, (..., 3)
        Unit vector toward the sun (:func:`sslfr_planner.raytrace.sun_vector`).
    beta_0, beta_m, beta_a : array_like
        Central mirror, mobile structure and tube tilts actually held [rad]; a tracking
        error is beta_0 - its ideal value (seed 000 eq. 17).
    p : OpticalParameters
    incidence : str
        '3d' or 'transversal' (module docstring).
    tube : (float, float), optional
        (L_a^r, L_a^l) [m] instead of the geometry's tube.
    per_mirror : bool
        Return (..., 2n+1) instead of the sum.
    endless : bool
        An endless tube (no end losses: the transversal study of seed 000 section 5.2).
    """
    tr = trace(sun, beta_0, beta_m, beta_a, p, tube)
    cap = raytrace.receiver_capture(tr, p.cavity_aperture, p.cavity_reflectivity,
                                    tube=(-np.inf, np.inf) if endless else None)
    q = (np.asarray(dni, dtype=float)[..., None] * optical_yield(p)
         * incidence_factor(tr, sun, beta_m, incidence) * cap)
    return q if per_mirror else q.sum(axis=-1)


def arc_illuminated(tr: raytrace.Trace, p: OpticalParameters):
    """Length of the tube circumference lit by each mirror, l_ci [m] (seed 001 eq. 33).

    pi D / 2 when the beam is at least D wide across the ray, else D arcsin(w_i / D);
    w_i = W_M |e_q| / (1/kappa) is the traced beam width across the ray (eq. 34's
    W_ai cos alpha_i).
    """
    w = p.geometry.mirror_width * np.abs(tr.e_q) / tr.aperture_scale
    return p.geometry.tube_diameter * np.arcsin(np.clip(w / p.geometry.tube_diameter, 0.0, 1.0))


def power_seed001(dni, sun, beta_0, beta_m, beta_a, p: OpticalParameters, tube=None, per_mirror=False):
    """Power absorbed by the tube as seed 001 annex eq. 20 scores it [W].

    Q = sum_i DNI * eta_opt * IAM_i * l_a,i * l_ci,i with IAM_i the cosine of the 3-D
    incidence angle (eqs. 27-28, not legible in the seed: derived), l_a,i the tube
    length lit by mirror i (:func:`sslfr_planner.raytrace.lit_length`, replacing eqs.
    30-32) and l_ci,i from eq. 33. This scores the lit tube *area*, so a steeper tube
    (longer lit length for the same rays) raises Q: what drives the seed's optimum
    beta_a = latitude. Not an energy balance (docs/optics.md).
    """
    tr = trace(sun, beta_0, beta_m, beta_a, p, tube)
    q = (np.asarray(dni, dtype=float)[..., None] * optical_yield(p) * tr.cos_incidence
         * raytrace.lit_length(tr) * arc_illuminated(tr, p))
    return q if per_mirror else q.sum(axis=-1)


def ideal_tilts(transversal, p: OpticalParameters) -> np.ndarray:
    """Ideal tilt of every mirror in the transversal plane [rad], (..., 2n+1) (seed 000 eqs. 11-15)."""
    g = p.geometry
    return _geometry.mirror_tilts(transversal, g.mirror_positions(), g.receiver_height, g.tube_diameter)


def transversal_capture(transversal, p: OpticalParameters, error=0.0, tilts=None):
    """Width of each mirror's reflected beam caught by the absorber [m], closed form (..., 2n+1).

    Seed 000 eqs. 18 and 20-23 in the transversal plane (horizontal rows, sun in the
    plane perpendicular to them): the beam reflected by mirror i is w_i = W_M cos(theta_i)
    wide across the ray; with a tracking error epsilon (eq. 17: beta_i^e = beta_i -
    epsilon) the reflected ray turns by -2 epsilon, its centre crosses the focal plane
    OO' away from the focal point and the beam occupies [r_i, l_i] = centre -/+ w_i/2
    across the ray (eq. 21). The part inside [-D/2, D/2] hits the tube (eq. 22); the
    rest, l_cr (eq. 23), is redirected by the cavity with reflectivity rho_rc as far as
    it enters the cavity's opening. :func:`power` computes the same from the 3-D trace
    (equal in this plane: tested). The power of mirror i is DNI * eta_i * L * C_i.

    Parameters
    ----------
    transversal : array_like
        Transversal incidence angle theta_t [rad], west (afternoon) positive.
    p : OpticalParameters
    error : float or array_like
        Tracking error epsilon [rad], broadcast against ``transversal``.
    tilts : array_like, optional
        Actual mirror tilts [rad] (..., 2n+1) instead of ideal tilts minus ``error``.
    """
    g = p.geometry
    tt = np.asarray(transversal, dtype=float)
    if tilts is None:
        beta = ideal_tilts(tt, p) - np.asarray(error, dtype=float)[..., None]
    else:
        beta = np.asarray(tilts, dtype=float)
    tt = tt[..., None]
    theta_i = np.abs(tt - beta)
    psi_e = 2.0 * beta - tt
    width = g.mirror_width * np.clip(np.cos(theta_i), 0.0, None)
    offset = g.mirror_positions() + g.aim_height * np.tan(psi_e)
    centre = offset * np.cos(psi_e)  # across the ray
    lo = centre - width / 2.0
    hi = centre + width / 2.0
    half = g.tube_diameter / 2.0
    direct = np.clip(np.minimum(hi, half) - np.maximum(lo, -half), 0.0, None)
    aperture = p.cavity_aperture / 2.0 * np.abs(np.cos(psi_e))  # across the ray
    entering = np.clip(np.minimum(hi, aperture) - np.maximum(lo, -aperture), 0.0, None)
    upward = np.cos(psi_e) > 0.0  # a ray reflected downward never reaches the receiver
    return np.where(upward, direct + (entering - direct) * p.cavity_reflectivity, 0.0)


def reflector_length(beta_m, beta_a, geometry: FieldGeometry, tube=None):
    """Reflector (installation) length L [m] (seed 001 eqs. 23-25).

    Horizontal footprint of the rows (L_M cos beta_M / 2 each side of the centre) and
    of the tube's ends (|L_a| cos beta_a), the larger reach on each side: eqs. 23-25 are
    the three cases of this maximum; the case where the tube overflows on both sides,
    which the seed does not list, follows the same rule.
    """
    right, left = geometry.tube if tube is None else tube
    half_row = geometry.mirror_length / 2.0 * np.cos(beta_m)
    reach_p = np.maximum(half_row, np.maximum(left, 0.0) * np.cos(beta_a))
    reach_n = np.maximum(half_row, np.maximum(-np.asarray(right), 0.0) * np.cos(beta_a))
    return reach_p + reach_n


def installation_area(beta_m, beta_a, geometry: FieldGeometry, tube=None):
    """Area required for the installation A = W L [m^2] (seed 000 eq. 27, seed 001 eq. 21)."""
    return geometry.field_width() * reflector_length(beta_m, beta_a, geometry, tube=tube)


def lcoe(costs_per_year, energy_per_year, discount_rate: float) -> float:
    """Levelized cost of energy [currency / energy unit] (seed 000 eq. 29).

    LCOE = sum_i (DC_i + IC_i + M_i + F_i)/(1+r)^i / sum_i E_i/(1+r)^i, i = 1..m.

    Parameters
    ----------
    costs_per_year : array_like
        Total cost DC_i + IC_i + M_i + F_i in each year i = 1..m [currency].
    energy_per_year : array_like
        Energy absorbed in each year E_i [kWh, or any energy unit].
    discount_rate : float
        Real discount rate r [-].
    """
    c = np.asarray(costs_per_year, dtype=float)
    e = np.asarray(energy_per_year, dtype=float)
    if c.shape != e.shape or c.ndim != 1 or c.size == 0:
        raise ValueError('costs and energies must be 1-D arrays of the same length (one per year)')
    if discount_rate <= -1.0:
        raise ValueError('discount rate must be > -1')
    factor = (1.0 + discount_rate) ** -np.arange(1, c.size + 1)
    denominator = float(np.sum(e * factor))
    if denominator <= 0:
        raise ValueError('the discounted energy is zero: LCOE undefined')
    return float(np.sum(c * factor) / denominator)
