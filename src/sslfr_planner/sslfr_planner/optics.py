"""Optical model of a small-scale linear Fresnel reflector (pure numpy, no rclpy).

Two published power models are implemented, each as the seed states it, with the
quantities the seeds leave to unavailable references derived from the geometry
(derivations and assumptions: docs/optics.md):

* seed 000 eqs. 17-24: transversal power per mirror with and without a tracking
  error epsilon (the width of the reflected beam caught by the absorber tube, with the
  part that misses the tube redirected by the receiver cavity at reflectivity rho_rc);
* seed 001 annex eqs. 20-35: power per mirror as DNI * eta_opt * IAM_i * l_a * l_ci,
  used by the seed for the energy-to-area ratio and the optimum tilt search.

Frames and signs (docs/optics.md has a figure):

* transversal plane (perpendicular to the rows): x positive to the WEST, angles from
  the vertical positive toward the west. theta_t > 0 in the afternoon (seed 000 eq. 9).
  Mirror i sits at x_i = -L_i (left, east, ``side = -1``) or +L_i (right, west,
  ``side = +1``); the central mirror at 0. Mirror tilts beta are positive toward the
  west (counter-clockwise seen from the south, as seed 000 section 2.4.1).
* longitudinal plane (containing the rows): p positive toward the SUN's side of the
  meridian (south in the northern hemisphere), angles from the vertical positive toward
  +p. theta_l > 0 when the sun is on the +p side. beta_M and beta_a > 0 lower the +p end
  of the mirror rows and of the absorber tube (they face the sun). Absorber tube
  positions along the tube are measured from the point above the row centre, positive
  toward +p ("left" in seed 000 section 5.1's sign convention: L_a^l > 0, L_a^r < 0).

All angles are radians, lengths metres, irradiance W/m^2, power W.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import geometry
from .geometry import projection_angles  # noqa: F401 - part of this module's API (seed 000 eqs. 9-10)


@dataclass(frozen=True)
class OpticalParameters:
    """SSLFR optical and geometric constants (defaults: seed 000 Table 3).

    Attributes
    ----------
    n_per_side : int
        Mirrors on each side of the central mirror, n [-] (2n + 1 in all).
    mirror_width : float
        W_M [m].
    mirror_length : float
        L_M [m].
    gap : float
        d, separation between two consecutive mirrors [m].
    tube_diameter : float
        D [m].
    receiver_height : float
        f, height of the receiver above the mirror pivots [m].
    tube_left : float
        L_a^l, position of the tube's +p ("left") end along the tube [m].
    tube_right : float
        L_a^r, position of the tube's other end [m] (negative: on the -p side).
    reflectivity : float
        rho of the mirrors [-].
    cleanliness_mirror, cleanliness_glass : float
        CI_m, CI_g [-].
    transmissivity_low, transmissivity_high : float
        tau of the glass for alpha_i <= 20 deg and alpha_i > 20 deg [-] (seed 000 Table 3
        gives 0.87 and 0.85; the seed's range stops at 30 deg and the higher value is
        kept beyond it: an assumption, docs/optics.md).
    absorptivity : float
        alpha_b of the tube [-].
    cavity_reflectivity : float
        rho_rc of the receiver cavity for rays that miss the tube [-]. Not given by the
        seeds (left to their ref. 65): 0.90, an assumption (docs/optics.md).
    cavity_aperture : float
        Width of the receiver cavity's opening in the focal plane [m]: rays that miss
        the tube inside it reach the tube after one cavity reflection, rays outside it
        are lost. Not given by the seeds: 0.12 m, an assumption (docs/optics.md).
    """

    n_per_side: int = 12
    mirror_width: float = 0.06
    mirror_length: float = 2.0
    gap: float = 0.024
    tube_diameter: float = 0.0486
    receiver_height: float = 1.5
    tube_left: float = 1.005
    tube_right: float = -1.005
    reflectivity: float = 0.94
    cleanliness_mirror: float = 0.96
    cleanliness_glass: float = 0.96
    transmissivity_low: float = 0.87
    transmissivity_high: float = 0.85
    absorptivity: float = 0.95
    cavity_reflectivity: float = 0.90
    cavity_aperture: float = 0.12

    def __post_init__(self):
        checks = [
            (self.n_per_side >= 0, 'n_per_side must be >= 0'),
            (self.mirror_width > 0, 'mirror_width must be > 0 m'),
            (self.mirror_length > 0, 'mirror_length must be > 0 m'),
            (self.gap >= 0, 'gap must be >= 0 m'),
            (self.tube_diameter > 0, 'tube_diameter must be > 0 m'),
            (self.receiver_height > 0, 'receiver_height must be > 0 m'),
            (self.tube_left > self.tube_right, 'tube_left must be > tube_right'),
            (self.cavity_aperture >= self.tube_diameter, 'cavity_aperture must be >= tube_diameter'),
        ]
        for name in ('reflectivity', 'cleanliness_mirror', 'cleanliness_glass', 'transmissivity_low',
                     'transmissivity_high', 'absorptivity', 'cavity_reflectivity'):
            value = getattr(self, name)
            checks.append((0.0 <= value <= 1.0, f'{name} must be in [0, 1], got {value}'))
        for ok, text in checks:
            if not ok:
                raise ValueError(text)

    @property
    def n_mirrors(self) -> int:
        """2n + 1 [-]."""
        return 2 * self.n_per_side + 1


def mirror_positions(p: OpticalParameters) -> np.ndarray:
    """Transversal positions x_i of the 2n+1 mirrors, west positive [m].

    Seed 000 eq. 15: L_i = i (W_M + d); left mirrors at -L_i, right at +L_i. Ordered
    from the n-th left mirror (``nL``) through the central one (``C``) to ``nR``.
    """
    return geometry.mirror_positions(p.n_per_side, p.mirror_width, p.gap)


def mirror_labels(p: OpticalParameters) -> list[str]:
    """Labels as in seed 000 Figs. 21-24: '12L', ..., '1L', 'C', '1R', ..., '12R'."""
    n = p.n_per_side
    return [f'{n - k}L' for k in range(n)] + ['C'] + [f'{k}R' for k in range(1, n + 1)]


def aim_height(p: OpticalParameters) -> float:
    """Height of the aim point above the mirror pivots, f + D/2 [m] (seed 000 eq. 14)."""
    return p.receiver_height + p.tube_diameter / 2.0


def receiver_angles(p: OpticalParameters) -> np.ndarray:
    """Signed angle from the vertical of the ray from each mirror to the aim point [rad].

    Seed 000 eq. 14 gives its magnitude alpha_i = arctan(L_i / (f + D/2)); the sign
    is west-positive, so a mirror on the west side (x_i > 0) sends its ray east:
    psi_i = -arctan(x_i / (f + D/2)).
    """
    return geometry.receiver_angles(mirror_positions(p), p.receiver_height, p.tube_diameter)


def optical_yield(p: OpticalParameters) -> np.ndarray:
    """Total optical yield eta_opt per mirror [-] (seed 000 eq. 19, seed 001 eq. 26).

    eta_opt = rho * CI_m * CI_g * tau * alpha_b, with tau from seed 000 Table 3
    chosen by the mirror's |alpha_i| (0.87 up to 20 deg, 0.85 above).
    """
    alpha = np.abs(receiver_angles(p))
    tau = np.where(alpha <= np.radians(20.0), p.transmissivity_low, p.transmissivity_high)
    return p.reflectivity * p.cleanliness_mirror * p.cleanliness_glass * tau * p.absorptivity


def ideal_tilts(transversal: np.ndarray, p: OpticalParameters) -> np.ndarray:
    """Ideal tilt of every mirror, west positive [rad], shape (..., 2n+1).

    The mirror normal bisects the sun's transversal direction and the direction to
    the aim point: beta_i = (theta_t + psi_i) / 2. This is seed 000 eqs. 11-13 with the
    seed's left/right sign cases folded into the signed psi_i (beta_0 = theta_t / 2 for
    the central mirror, eq. 13).
    """
    return geometry.mirror_tilts(transversal, mirror_positions(p), p.receiver_height, p.tube_diameter)


def transversal_capture(transversal, p: OpticalParameters, error=0.0, tilts=None):
    """Width of each mirror's reflected beam caught by the absorber [m], shape (..., 2n+1).

    Seed 000 eqs. 18 and 20-23 in one formula: the beam reflected by mirror i is
    w_i = W_M cos(theta_i) wide (perpendicular to the ray; theta_i is the angle between
    the sun's transversal direction and the mirror normal). With a tracking error
    epsilon (eq. 17: beta_i^e = beta_i - epsilon) the reflected ray turns by -2 epsilon,
    its centre crosses the horizontal focal plane OO' away from the focal point, and the
    beam occupies [r_i, l_i] = centre -/+ w_i/2 across the ray (eq. 21). The part inside
    [-D/2, D/2] hits the tube directly (eq. 22); the rest, l_cr (eq. 23), is redirected
    by the cavity with reflectivity rho_rc as far as it enters the cavity's aperture
    (``cavity_aperture``, an assumption: a far-off beam, e.g. a stowed mirror, is lost).
    With epsilon = 0 this reduces to eq. 18's three cases (w_i < D: w_i; w_i = D: D;
    w_i > D: D + (w_i - D) rho_rc).

    Parameters
    ----------
    transversal : array_like
        Transversal incidence angle theta_t [rad], west (afternoon) positive.
    p : OpticalParameters
    error : float or array_like
        Tracking error epsilon [rad] (seed 000 eq. 17), broadcast against ``transversal``.
    tilts : array_like, optional
        Actual mirror tilts [rad] (..., 2n+1) instead of ideal tilts minus ``error``.

    Returns
    -------
    numpy.ndarray
        Effective caught width C_i [m]; the power of mirror i is
        DNI * eta_i * l_abs * C_i (eqs. 18, 20).
    """
    tt = np.asarray(transversal, dtype=float)
    if tilts is None:
        beta = ideal_tilts(tt, p) - np.asarray(error, dtype=float)[..., None]
    else:
        beta = np.asarray(tilts, dtype=float)
    tt = tt[..., None]
    # incidence angle on the mirror (transversal plane) and the reflected direction
    theta_i = np.abs(tt - beta)
    psi_e = 2.0 * beta - tt
    width = p.mirror_width * np.clip(np.cos(theta_i), 0.0, None)
    x = mirror_positions(p)
    h = aim_height(p)
    # where the reflected centre ray crosses the focal plane (OO', seed 000 eq. 21)
    offset = x + h * np.tan(psi_e)
    centre = offset * np.cos(psi_e)  # across the ray
    lo = centre - width / 2.0
    hi = centre + width / 2.0
    half = p.tube_diameter / 2.0
    direct = np.clip(np.minimum(hi, half) - np.maximum(lo, -half), 0.0, None)
    aperture = p.cavity_aperture / 2.0 * np.abs(np.cos(psi_e))  # across the ray
    entering = np.clip(np.minimum(hi, aperture) - np.maximum(lo, -aperture), 0.0, None)
    upward = np.cos(psi_e) > 0.0  # a ray reflected downward never reaches the receiver
    return np.where(upward, direct + (entering - direct) * p.cavity_reflectivity, 0.0)


def longitudinal_reflection_angle(longitudinal, beta_m):
    """mu = 2 beta_M - theta_l [rad] (seed 001 eq. 3).

    Angle from the vertical, +p positive, of the longitudinal projection of the rays
    reflected by rows tilted by beta_M when the sun's longitudinal angle is theta_l.
    """
    return 2.0 * np.asarray(beta_m, dtype=float) - np.asarray(longitudinal, dtype=float)


def tube_hit_position(s, mu, beta_m, beta_a, p: OpticalParameters):
    """Position along the absorber tube hit by the ray from row coordinate s [m].

    Derived from the longitudinal geometry (docs/optics.md), replacing seed 001
    eqs. 31-32: a row point s (along the row, +p positive) is at
    (s cos beta_M, -s sin beta_M); its reflected ray leaves at mu from the vertical;
    the tube passes through (0, f) with direction (cos beta_a, -sin beta_a). Then

        u(s) = (s cos(beta_M - mu) + f sin mu) / cos(mu - beta_a).
    """
    s = np.asarray(s, dtype=float)
    return (s * np.cos(beta_m - mu) + p.receiver_height * np.sin(mu)) / np.cos(mu - beta_a)


def illuminated_length(longitudinal, beta_m, beta_a, p: OpticalParameters, tube=None):
    """Length of the absorber tube illuminated by the rows, l_a [m] (seed 001 eqs. 30-32).

    The rays from the two row ends (s = +/- L_M/2) bound the illuminated segment; its
    overlap with the physical tube [L_a^r, L_a^l] is the illuminated length (the rest are
    end losses). ``tube`` = (right_end, left_end) overrides the parameters' tube.
    Returns 0 when the reflected rays run away from the tube (|mu - beta_a| >= pi/2).
    """
    mu = longitudinal_reflection_angle(longitudinal, beta_m)
    half = p.mirror_length / 2.0
    right, left = (p.tube_right, p.tube_left) if tube is None else tube
    with np.errstate(divide='ignore', invalid='ignore'):
        u1 = tube_hit_position(-half, mu, beta_m, beta_a, p)
        u2 = tube_hit_position(half, mu, beta_m, beta_a, p)
        lo = np.minimum(u1, u2)
        hi = np.maximum(u1, u2)
        length = np.clip(np.minimum(hi, left) - np.maximum(lo, right), 0.0, None)
    valid = np.cos(mu - np.asarray(beta_a, dtype=float)) > 1e-9
    return np.where(valid, length, 0.0)


def sun_vector(zenith, azimuth, collector_azimuth=0.0):
    """Unit vector toward the sun in the collector frame (west, sun-side p, up) [-].

    ``azimuth`` is clockwise from north [rad]; ``collector_azimuth`` is the azimuth of
    the collector's axis (0: north-south; seed 004 eqs. 1-2). The p axis points to the
    south for a north-south collector (the sun's side in the northern hemisphere).
    Returns an array (..., 3).
    """
    z = np.asarray(zenith, dtype=float)
    a = np.asarray(azimuth, dtype=float) - collector_azimuth
    west = -np.sin(z) * np.sin(a)
    south = -np.sin(z) * np.cos(a)
    up = np.cos(z)
    return np.stack(np.broadcast_arrays(west, south, up), axis=-1)


def incidence_cosines(zenith, azimuth, beta_m, p: OpticalParameters, collector_azimuth=0.0,
                      tilts=None):
    """cos of the 3-D angle between the sun and each mirror's normal [-] (..., 2n+1).

    The incidence angle modifier IAM_i of seed 001 eqs. 27-28, derived from the
    geometry (docs/optics.md): the normal of a row tilted longitudinally by beta_M and
    turned by beta_i about its axis is n_i = cos beta_i (0, sin beta_M, cos beta_M)
    + sin beta_i (1, 0, 0) in (west, p, up). With ``tilts`` None the mirrors are at
    their ideal tilts for the transversal angle measured in the plane perpendicular
    to the tilted rows. Negative cosines (sun behind a mirror) are clipped to 0.
    """
    v = sun_vector(zenith, azimuth, collector_azimuth)
    bm = np.asarray(beta_m, dtype=float)
    if tilts is None:
        along_normal = v[..., 1] * np.sin(bm) + v[..., 2] * np.cos(bm)
        tt = np.arctan2(v[..., 0], along_normal)
        tilts = ideal_tilts(tt, p)
    tilts = np.asarray(tilts, dtype=float)
    bm = bm[..., None]
    cos_i = (np.cos(tilts) * (v[..., 1, None] * np.sin(bm) + v[..., 2, None] * np.cos(bm))
             + np.sin(tilts) * v[..., 0, None])
    return np.clip(cos_i, 0.0, 1.0)


def arc_illuminated(transversal, p: OpticalParameters):
    """Length of the tube circumference illuminated by each mirror, l_ci [m].

    Seed 001 eq. 33: pi D / 2 if W_ai cos alpha_i >= D, else D arcsin(W_ai cos alpha_i / D),
    where W_ai cos alpha_i = W_M cos theta_i is the beam width across the ray (eq. 34).
    """
    tt = np.asarray(transversal, dtype=float)
    theta_i = np.abs(tt[..., None] - ideal_tilts(tt, p))
    w = p.mirror_width * np.cos(theta_i)
    ratio = np.clip(w / p.tube_diameter, 0.0, 1.0)
    return p.tube_diameter * np.arcsin(ratio)


def power_seed000(dni, zenith, azimuth, beta_m, beta_a, p: OpticalParameters, error=0.0,
                  collector_azimuth=0.0, per_mirror=False):
    """Power absorbed by the tube, seed 000 eqs. 18 and 20 [W].

    Q = sum_i DNI * eta_i * l_abs * C_i with l_abs the illuminated tube length
    (:func:`illuminated_length`) and C_i the caught beam width
    (:func:`transversal_capture`, tracking error ``error`` [rad]).
    Zero when the sun is below the horizon. ``per_mirror`` returns (..., 2n+1).
    """
    z = np.asarray(zenith, dtype=float)
    tt, tl = projection_angles(z, azimuth, collector_azimuth)
    cap = transversal_capture(tt, p, error=error)
    l_abs = illuminated_length(tl, beta_m, beta_a, p)
    up = z < np.pi / 2
    q = (np.asarray(dni, dtype=float) * np.where(up, l_abs, 0.0))[..., None] * optical_yield(p) * cap
    return q if per_mirror else q.sum(axis=-1)


def power_seed001(dni, zenith, azimuth, beta_m, beta_a, p: OpticalParameters,
                  collector_azimuth=0.0, tube=None, per_mirror=False):
    """Power absorbed by the tube, seed 001 annex eq. 20 integrand [W].

    Q = sum_i DNI * eta_opt * IAM_i * A_eff,i with A_eff,i = l_a * l_ci (eq. 29),
    l_a from :func:`illuminated_length` (eqs. 30-32), l_ci from :func:`arc_illuminated`
    (eq. 33) and IAM_i from :func:`incidence_cosines` (eqs. 27-28). This is the seed's
    model as published: it scores the illuminated tube area, so tilting the tube
    (longer illuminated length) raises Q, which is what drives the seed's optimum
    beta_a = latitude (docs/optics.md discusses it).
    """
    z = np.asarray(zenith, dtype=float)
    tt, tl = projection_angles(z, azimuth, collector_azimuth)
    iam = incidence_cosines(z, azimuth, beta_m, p, collector_azimuth)
    arc = arc_illuminated(tt, p)
    l_a = illuminated_length(tl, beta_m, beta_a, p, tube=tube)
    up = z < np.pi / 2
    q = (np.asarray(dni, dtype=float) * np.where(up, l_a, 0.0))[..., None] * optical_yield(p) * iam * arc
    return q if per_mirror else q.sum(axis=-1)


def field_width(p: OpticalParameters) -> float:
    """Mirror field width W = 2 n (W_M + d) + W_M [m] (seed 000 eq. 28, seed 001 eq. 22)."""
    return 2 * p.n_per_side * (p.mirror_width + p.gap) + p.mirror_width


def reflector_length(beta_m, beta_a, p: OpticalParameters, tube=None):
    """Reflector (installation) length L [m] (seed 001 eqs. 23-25).

    Horizontal footprint of the row (L_M cos beta_M) and of the tube ends
    (|L_a| cos beta_a) measured from the row centre: the larger reach on each side.
    Eqs. 23-25 are the three cases of this maximum (tube inside the row's projection,
    overflowing on one side or the other); the case where it overflows on both sides,
    which the seed does not list, follows the same rule.
    """
    right, left = (p.tube_right, p.tube_left) if tube is None else tube
    half_row = p.mirror_length / 2.0 * np.cos(beta_m)
    reach_p = np.maximum(half_row, np.maximum(left, 0.0) * np.cos(beta_a))
    reach_n = np.maximum(half_row, np.maximum(-right, 0.0) * np.cos(beta_a))
    return reach_p + reach_n


def installation_area(beta_m, beta_a, p: OpticalParameters, tube=None):
    """Area required for the installation A = W L [m^2] (seed 000 eq. 27, seed 001 eq. 21)."""
    return field_width(p) * reflector_length(beta_m, beta_a, p, tube=tube)


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
