"""3-D ray model of a linear Fresnel collector with tilting rows and tube (pure numpy).

One trace serves both the tracker and the offline analysis: the planner's
``continuous`` law and the mirrors' command come from it (:mod:`sslfr_planner.laws`,
:mod:`sslfr_planner.tracking_table`), and so do the power, end losses and illuminated
length of :mod:`sslfr_planner.analysis`. Everything is vectorised over any leading
shape (instants) and the 2n+1 mirrors (last axis).

Frame (docs/optics.md has the figure; :class:`~sslfr_planner.collector.FieldGeometry`):
x west (across the rows), p along the rows toward the collector's +p end (south for
a north-south collector), z up. The mobile structure pivots about the x axis through
the central row's centre: tilted by beta_M (> 0 lowers the +p end) its rows run along
r = (0, cos beta_M, -sin beta_M) and their untilted normal is m = (0, sin beta_M,
cos beta_M). Mirror i pivots about its own row line through (x_i, 0, 0) and is turned
by beta_i = beta_0 + psi_i / 2 (west positive), psi_i the fixed offset of seed 000
eqs. 11-14, so its normal is n_i = cos beta_i m + sin beta_i x. The absorber tube's
axis passes through (0, 0, h), h = f + D/2, with direction a = (0, cos beta_a,
-sin beta_a); positions along it, u, are measured from that pivot, +p positive.

The receiver plane is the plane through the tube's axis spanned by a and x (seed 000's
focal plane OO', tilted with the tube). A ray reflected at a mirror point crosses it at
lateral offset e (west positive) and tube position u. All rays of one mirror at one
instant are parallel, so e and u are affine in the point's coordinates on the mirror,
q across its width (-W_M/2..W_M/2, along b_i = cos beta_i x - sin beta_i m) and s
along its length (-L_M/2..L_M/2, along r): e = e0 + e_q q + e_s s, u likewise. A ray
hits the tube when its distance to the axis is at most D/2, i.e. |e| <= D / (2 kappa)
with kappa = (w . n_r) / |w x a| (the seed's "across the ray" projection, n_r the
plane's normal); it enters the receiver cavity when |e| <= A/2 (A the cavity's opening).
The area of mirror whose rays satisfy such bounds is the area of a convex polygon: the
mirror's rectangle clipped by the slabs, computed exactly
(:func:`mirror_area_hitting`). A flat mirror, parallel rays (no sun shape, no slope
error), no shading or blocking between rows, as the seeds assume.

Units: metres and radians; sun vectors are unit vectors toward the sun.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .collector import FieldGeometry

#: rows of the clipping work arrays handled at once (memory ~ 100 MB at 8 vertices)
_CHUNK = 65536


# --- sun and frames ------------------------------------------------------------------

def sun_vector(zenith, azimuth, collector_azimuth=0.0) -> np.ndarray:
    """Unit vector toward the sun in the collector frame (x west, p, z up), shape (..., 3).

    ``zenith`` [rad], ``azimuth`` clockwise from north [rad], ``collector_azimuth`` the
    azimuth of the collector's axis [rad] (0: north-south, +p toward the south;
    seed 004 eqs. 1-2). For a north-south collector this is (-sin z sin a,
    -sin z cos a, cos z).
    """
    z = np.asarray(zenith, dtype=float)
    rel = np.asarray(azimuth, dtype=float) - collector_azimuth
    sz = np.sin(z)
    return np.stack(np.broadcast_arrays(-sz * np.sin(rel), -sz * np.cos(rel), np.cos(z)), axis=-1)


def transversal_angle(sun, beta_m=0.0):
    """Sun's angle in the plane perpendicular to the (tilted) rows, from the rows' normal [rad].

    theta_t' = atan2(v_x, v . m), m = (0, sin beta_M, cos beta_M), west (afternoon)
    positive. For beta_M = 0 this is seed 000 eq. 9's theta_t; with the structure tilted
    it is the angle the mirrors must follow, since they turn about the tilted rows.
    """
    v = np.asarray(sun, dtype=float)
    bm = np.asarray(beta_m, dtype=float)
    return np.arctan2(v[..., 0], v[..., 1] * np.sin(bm) + v[..., 2] * np.cos(bm))


def central_mirror_tilt(sun, beta_m=0.0):
    """Tilt beta_0 of the central mirror that sends its rays onto the tube's axis [rad].

    beta_0 = theta_t' / 2 (:func:`transversal_angle`): seed 000 eq. 13 in the frame of
    the tilted rows. Exact for the central mirror whatever beta_a: its reflected ray
    then stays in the plane x = 0, which contains the tube's axis.
    """
    return transversal_angle(sun, beta_m) / 2.0


def structure_vectors(beta_m):
    """(r, m): unit vectors along the tilted rows and of their untilted normal, (..., 3)."""
    bm = np.asarray(beta_m, dtype=float)
    c, s = np.cos(bm), np.sin(bm)
    zero = np.zeros_like(c)
    return np.stack([zero, c, -s], axis=-1), np.stack([zero, s, c], axis=-1)


def tube_vectors(beta_a):
    """(a, n_r): unit vector along the tube and normal of the receiver plane, (..., 3)."""
    ba = np.asarray(beta_a, dtype=float)
    c, s = np.cos(ba), np.sin(ba)
    zero = np.zeros_like(c)
    return np.stack([zero, c, -s], axis=-1), np.stack([zero, s, c], axis=-1)


def mirror_normals(beta_0, beta_m, geometry: FieldGeometry, offsets=None):
    """(n_i, b_i): unit normal and width direction of every mirror, shape (..., 2n+1, 3).

    beta_i = beta_0 + psi_i / 2 (the mirrors share one drive; seed 000 eqs. 11-15),
    n_i = cos beta_i m + sin beta_i x, b_i = cos beta_i x - sin beta_i m.
    """
    psi = geometry.receiver_angles() if offsets is None else offsets
    beta = np.asarray(beta_0, dtype=float)[..., None] + psi / 2.0
    _, m = structure_vectors(beta_m)
    m = np.asarray(m)[..., None, :]
    c, s = np.cos(beta)[..., None], np.sin(beta)[..., None]
    ex = np.array([1.0, 0.0, 0.0])
    return c * m + s * ex, c * ex - s * m


def reflect(sun, normal):
    """Reflected ray direction w = 2 (v . n) n - v (unit vectors, (..., 3))."""
    v = np.asarray(sun, dtype=float)
    n = np.asarray(normal, dtype=float)
    return 2.0 * np.sum(v * n, axis=-1, keepdims=True) * n - v


# --- the trace ---------------------------------------------------------------------------

@dataclass
class Trace:
    """Rays of every mirror at every instant, shape (..., 2n+1) for each array.

    Attributes
    ----------
    cos_incidence : numpy.ndarray
        cos theta_i, the 3-D angle between the sun and the mirror's normal [-]
        (0 where the sun is behind the mirror).
    e0, e_q, e_s : numpy.ndarray
        Lateral offset in the receiver plane of the ray from mirror point (q, s):
        e0 + e_q q + e_s s [m], west positive.
    u0, u_q, u_s : numpy.ndarray
        Position along the tube where that ray crosses the receiver plane [m].
    tube_half : numpy.ndarray
        Bound on |e| of the rays that hit the tube, D / (2 kappa) [m].
    aperture_scale : numpy.ndarray
        e of a ray divided by its distance across the ray from the axis (1 / kappa) [-].
    valid : numpy.ndarray of bool
        Sun in front of the mirror and reflected rays going up to the receiver plane.
    geometry : FieldGeometry
    """

    cos_incidence: np.ndarray
    e0: np.ndarray
    e_q: np.ndarray
    e_s: np.ndarray
    u0: np.ndarray
    u_q: np.ndarray
    u_s: np.ndarray
    tube_half: np.ndarray
    aperture_scale: np.ndarray
    valid: np.ndarray
    geometry: FieldGeometry

    def u_at(self, s, q=0.0):
        """Tube position [m] of the ray from row coordinate ``s`` [m] (and ``q``)."""
        return self.u0 + self.u_q * q + self.u_s * s

    def hit_segment(self):
        """(u_lo, u_hi): tube positions reached by the centre line of each mirror [m]."""
        half = self.geometry.mirror_length / 2.0
        a, b = self.u_at(-half), self.u_at(half)
        return np.minimum(a, b), np.maximum(a, b)

    def displacement(self):
        """Longitudinal displacement of each mirror's central ray: u(q=0, s=0) [m].

        The rays of a row land on [u(-L_M/2), u(+L_M/2)]; with the tube parallel to
        the rows (beta_a = beta_M) and u0 = 0 they land straight across from where they
        were reflected, the end losses the seeds minimise vanish.
        """
        return self.u0


@dataclass
class Rays:
    """Reflected rays of every mirror (shape (..., 2n+1) arrays, (..., 2n+1, 3) vectors)."""

    normal: np.ndarray      # n_i
    width_dir: np.ndarray   # b_i
    row_dir: np.ndarray     # r (broadcast per mirror)
    reflected: np.ndarray   # w_i
    cos_incidence: np.ndarray
    beta_m: np.ndarray      # (...,)


def rays(sun, beta_0, beta_m, geometry: FieldGeometry, offsets=None) -> Rays:
    """Mirror normals and reflected directions (the part of :func:`trace` before the tube).

    ``offsets``: the mirrors' offsets psi_i [rad], (2n+1,) or (..., 2n+1); None: seed
    000 eq. 14's psi_i = -atan(x_i / h), fixed at assembly (one drive for all mirrors).
    """
    v = np.asarray(sun, dtype=float)
    shape = np.broadcast_shapes(v.shape[:-1], np.shape(beta_0), np.shape(beta_m))
    v = np.broadcast_to(v, shape + (3,))
    bm = np.broadcast_to(np.asarray(beta_m, dtype=float), shape)
    n, b = mirror_normals(np.broadcast_to(np.asarray(beta_0, dtype=float), shape), bm, geometry, offsets)
    r, _ = structure_vectors(bm)
    vv = v[..., None, :]
    cos_i = _dot(vv, n)
    w = 2.0 * cos_i[..., None] * n - vv
    return Rays(n, b, np.broadcast_to(r[..., None, :], n.shape), w, cos_i, bm)


def _dot(p, q):
    """Dot product over the last axis (length 3) of broadcastable arrays: three
    multiply-adds instead of ``np.sum(p * q, axis=-1)`` (numpy reduces a length-3 last
    axis slowly; the seed 001 tilt search spent half its time there)."""
    return p[..., 0] * q[..., 0] + p[..., 1] * q[..., 1] + p[..., 2] * q[..., 2]


def trace(sun, beta_0, beta_m, beta_a, geometry: FieldGeometry, offsets=None, reflected: Rays | None = None) -> Trace:
    """Trace the rays of every mirror to the receiver plane (module docstring).

    Parameters
    ----------
    sun : array_like, (..., 3)
        Unit vector toward the sun in the collector frame (:func:`sun_vector`).
    beta_0 : array_like
        Central mirror tilt [rad], west positive (the ``mirrors`` joint).
    beta_m, beta_a : array_like
        Mobile structure and tube tilts [rad], > 0 lowers the +p end.
    geometry : FieldGeometry
    offsets : array_like, optional
        Mirror offsets psi_i [rad] (:func:`rays`).
    reflected : Rays, optional
        :func:`rays` already computed for (sun, beta_0, beta_m) (reused across tube tilts).

    Returns
    -------
    Trace
    """
    ry = rays(sun, beta_0, beta_m, geometry, offsets) if reflected is None else reflected
    w, b, r, cos_i = ry.reflected, ry.width_dir, ry.row_dir, ry.cos_incidence
    ba = np.broadcast_to(np.asarray(beta_a, dtype=float), np.broadcast_shapes(ry.beta_m.shape, np.shape(beta_a)))
    a, nr = tube_vectors(ba)
    a, nr = a[..., None, :], nr[..., None, :]
    w_nr = _dot(w, nr)
    w_a = _dot(w, a)
    x = geometry.mirror_positions()
    h = geometry.aim_height
    going_up = w_nr > 1e-9
    safe = np.where(going_up, w_nr, 1.0)
    # ray from P: t(P) = (T0 - P) . n_r / (w . n_r), crossing X = P + t w; T0 = (0, 0, h);
    # n_r and a have no x component, so e = X_x and u = (X - T0) . a = P . a + t w . a + h sin(beta_a)
    t0 = h * nr[..., 2] / safe
    e0 = x + t0 * w[..., 0]
    u0 = t0 * w_a + h * np.sin(ba)[..., None]
    b_nr, r_nr = _dot(b, nr), _dot(r, nr)
    e_q = b[..., 0] - b_nr * w[..., 0] / safe
    e_s = -r_nr * w[..., 0] / safe                     # r has no x component
    u_q = _dot(b, a) - b_nr * w_a / safe
    u_s = _dot(r, a) - r_nr * w_a / safe
    cross = np.sqrt(np.clip(1.0 - w_a ** 2, 1e-300, None))  # |w x a|
    scale = cross / safe                                # e per unit distance across the ray
    valid = (cos_i > 0.0) & going_up & (t0 > 0.0)
    return Trace(np.clip(cos_i, 0.0, 1.0), e0, e_q, e_s, u0, u_q, u_s,
                 geometry.tube_diameter / 2.0 * scale, scale, valid, geometry)


# --- exact capture: the mirror's rectangle clipped by slabs --------------------------------

def _clip(px, py, cnt, a, b, c):
    """Clip convex polygons (vertices px, py (N, V), counts cnt (N,)) by a q + b s <= c.

    Sutherland-Hodgman, vectorised; returns polygons with at most V + 1 vertices.
    Polygons wholly inside the half-plane are kept as they are, wholly outside emptied;
    only the others are clipped (most rows, most of the time: the work stays small).
    """
    nrows, nv = px.shape
    k = np.arange(nv)
    live = k[None, :] < cnt[:, None]
    d = a[:, None] * px + b[:, None] * py - c[:, None]
    inside = d <= 0.0
    out_n = nv + 1  # a convex polygon gains at most one vertex per half-plane
    ox = np.concatenate([px, np.zeros((nrows, 1))], axis=1)
    oy = np.concatenate([py, np.zeros((nrows, 1))], axis=1)
    ocnt = cnt.copy()
    ocnt[~np.any(live & inside, axis=1)] = 0
    work = np.flatnonzero(np.any(live & ~inside, axis=1) & np.any(live & inside, axis=1))
    if work.size == 0:
        return ox, oy, ocnt
    px, py, d, live, inside, cnt = px[work], py[work], d[work], live[work], inside[work], cnt[work]
    n = work.size
    nxt = np.where(k[None, :] + 1 < cnt[:, None], k[None, :] + 1, 0)
    qx = np.take_along_axis(px, nxt, axis=1)
    qy = np.take_along_axis(py, nxt, axis=1)
    dq = np.take_along_axis(d, nxt, axis=1)
    crosses = live & ((d < 0.0) & (dq > 0.0) | (d > 0.0) & (dq < 0.0))
    with np.errstate(divide='ignore', invalid='ignore'):
        f = np.where(crosses, d / (d - dq), 0.0)
    ix, iy = px + f * (qx - px), py + f * (qy - py)
    # candidates in order: vertex k (if inside), then the crossing on edge k (if any)
    cx = np.stack([px, ix], axis=2).reshape(n, 2 * nv)
    cy = np.stack([py, iy], axis=2).reshape(n, 2 * nv)
    keep = np.stack([live & inside, crosses], axis=2).reshape(n, 2 * nv)
    order = np.argsort(~keep, axis=1, kind='stable')[:, :out_n]
    ox[work] = np.take_along_axis(cx, order, axis=1)
    oy[work] = np.take_along_axis(cy, order, axis=1)
    ocnt[work] = np.minimum(keep.sum(axis=1), out_n)
    return ox, oy, ocnt


def _area(px, py, cnt):
    """Shoelace area of convex polygons (N, V) with vertex counts cnt."""
    nv = px.shape[1]
    k = np.arange(nv)
    nxt = np.where(k[None, :] + 1 < cnt[:, None], k[None, :] + 1, 0)
    qx = np.take_along_axis(px, nxt, axis=1)
    qy = np.take_along_axis(py, nxt, axis=1)
    term = np.where(k[None, :] < cnt[:, None], px * qy - qx * py, 0.0)
    return np.abs(term.sum(axis=1)) / 2.0


def _slab(px, py, cnt, f0, fq, fs, lo, hi):
    """Clip by lo <= f0 + fq q + fs s <= hi."""
    px, py, cnt = _clip(px, py, cnt, fq, fs, hi - f0)
    return _clip(px, py, cnt, -fq, -fs, f0 - lo)


def mirror_area_hitting(tr: Trace, e_half, tube=None) -> np.ndarray:
    """Area of each mirror whose reflected rays satisfy |e| <= e_half and u in ``tube`` [m^2].

    Exact for the model (flat mirror, parallel rays): the mirror's rectangle
    [-W_M/2, W_M/2] x [-L_M/2, L_M/2] in (q, s) clipped by the two slabs.
    ``tube`` = (u_min, u_max) [m]; None: the geometry's tube; (-inf, inf): an endless
    tube (a transversal study, as seed 000 section 5.2). ``e_half`` broadcasts against
    the trace; a sequence of such bounds gives one result per bound (stacked on a new
    first axis), sharing the clipping by the tube's ends. Invalid rays
    (:attr:`Trace.valid`) give 0.
    """
    many = isinstance(e_half, (list, tuple))
    bounds = list(e_half) if many else [e_half]
    g = tr.geometry
    lo_u, hi_u = g.tube if tube is None else tube
    shape = tr.e0.shape
    ehs = [np.broadcast_to(np.asarray(b, dtype=float), shape).reshape(-1) for b in bounds]
    flat = [np.asarray(getattr(tr, k)).reshape(-1) for k in ('e0', 'e_q', 'e_s', 'u0', 'u_q', 'u_s')]
    valid = np.asarray(tr.valid).reshape(-1)
    out = np.zeros((len(bounds), valid.size))
    hw, hl = g.mirror_width / 2.0, g.mirror_length / 2.0
    rect_x = np.array([-hw, hw, hw, -hw])
    rect_y = np.array([-hl, -hl, hl, hl])
    idx = np.flatnonzero(valid)
    for start in range(0, idx.size, _CHUNK):
        sel = idx[start:start + _CHUNK]
        n = sel.size
        e0, eq, es, u0, uq, us = (x[sel] for x in flat)
        px = np.broadcast_to(rect_x, (n, 4)).copy()
        py = np.broadcast_to(rect_y, (n, 4)).copy()
        cnt = np.full(n, 4)
        if np.isfinite(hi_u):
            px, py, cnt = _clip(px, py, cnt, uq, us, hi_u - u0)
        if np.isfinite(lo_u):
            px, py, cnt = _clip(px, py, cnt, -uq, -us, u0 - lo_u)
        for k, eh in enumerate(ehs):
            h = eh[sel]
            out[k, sel] = _area(*_slab(px, py, cnt, e0, eq, es, -h, h))
    out = out.reshape((len(bounds),) + shape)
    return out if many else out[0]


def receiver_capture(tr: Trace, cavity_aperture: float, cavity_reflectivity: float, tube=None):
    """Effective mirror area feeding the tube [m^2], per mirror (seed 000 eqs. 18, 20-23 in 3-D).

    Rays entering the receiver cavity's opening (|e| <= A/2) inside the tube's length
    reach the tube: directly when they pass within D/2 of its axis, else after one
    reflection on the cavity (reflectivity rho_rc). Rays outside the opening are lost.
    Multiply by DNI, eta_opt and :attr:`Trace.cos_incidence` for the power [W].
    """
    half_open = cavity_aperture / 2.0
    direct, entering = mirror_area_hitting(tr, [np.minimum(tr.tube_half, half_open), half_open], tube)
    return direct + cavity_reflectivity * (entering - direct)


def lit_length(tr: Trace, tube=None) -> np.ndarray:
    """Length of the tube lit by each mirror's centre line [m] (seed 001 eqs. 30-32 in 3-D)."""
    lo_u, hi_u = tr.geometry.tube if tube is None else tube
    lo, hi = tr.hit_segment()
    return np.where(tr.valid, np.clip(np.minimum(hi, hi_u) - np.maximum(lo, lo_u), 0.0, None), 0.0)
