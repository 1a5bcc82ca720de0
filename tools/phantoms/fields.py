"""Analytic deformation fields of the phantom scenes (numpy only, no Blender).

A scene deforms a band of tissue by a closed-form map x = phi(X, side, t) of the rest
coordinates X (mm), the side of a cut a point belongs to (+1 / -1) and the normalised time
t in [0, 1]. There is no finite-element model anywhere: the maps are sums of smooth
kinematic modes (hourglass stretch, lateral spread, bowing, twist, pinch, bulge, dent) and,
for cut scenes, a rotation of the two flaps about the moving cut front that is discontinuous
only across the opened part of the cut path. phi(X, side, 0) is the identity for every scene.

Rest frame (= world frame at frame 0): x to the right, y up along the band, z out of the front
face (towards the camera); the band covers [-W/2, W/2] x [0, H] x [-T/2, T/2] and its bottom
edge y = 0 is held.
"""

import math

import numpy as np

SCENARIOS = {
    "stretch": "no cut; pulled to 170-190 % of its length with an hourglass waist",
    "precut": "a slit from the top or a side edge present from frame 0; the flaps turn about "
    "its tip into a V",
    "cut-straight": "a straight cut from a side or the top edge advancing while filmed",
    "cut-curved": "an arc- or S-shaped cut advancing while filmed",
    "cut-v": "a vertical cut from the top edge advancing while the halves splay into a V",
    "tear": "a jagged tear advancing in jerks while the band is pulled apart",
    "strain": "no cut; a twisted and a pinched region and a local bulge on a stretched band",
    "instrument": "no cut; a metallic grasper slides over the band and dents it",
}
CUT_SCENARIOS = ("precut", "cut-straight", "cut-curved", "cut-v", "tear")


def smoothstep(t0, t1, t):
    """C1 ramp from 0 at t0 to 1 at t1 (vectorised over t)."""
    u = np.clip((np.asarray(t, dtype=float) - t0) / (t1 - t0), 0.0, 1.0)
    return u * u * (3.0 - 2.0 * u)


def _rotate2(v, angle):
    """Rotates 2D vectors v (n x 2) counter-clockwise by per-row angles (n,)."""
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([c * v[:, 0] - s * v[:, 1], s * v[:, 0] + c * v[:, 1]], axis=1)


def _segment_distance(points, a, b):
    """Distance of points (n x 2) to segments a -> b (m x 2 each): (n, m) array and the
    parameter along each segment in [0, 1]."""
    d = b - a
    len2 = np.maximum((d * d).sum(axis=1), 1e-18)
    rel = points[:, None, :] - a[None, :, :]
    u = np.clip((rel * d[None, :, :]).sum(axis=2) / len2[None, :], 0.0, 1.0)
    closest = a[None, :, :] + u[:, :, None] * d[None, :, :]
    return np.linalg.norm(points[:, None, :] - closest, axis=2), u


def polyline_distance(points, poly, chunk=4096):
    """Distance (n,) of 2D points to a polyline (m x 2, m >= 2); inf for an empty polyline."""
    points = np.asarray(points, dtype=float)
    if poly is None or len(poly) < 2:
        return np.full(len(points), np.inf)
    out = np.empty(len(points))
    for i in range(0, len(points), chunk):
        dist, _ = _segment_distance(points[i : i + chunk], poly[:-1], poly[1:])
        out[i : i + chunk] = dist.min(axis=1)
    return out


class CutPath:
    """A cut through the band's thickness along a rest-frame polyline in the xy plane.

    `points` (n x 2) runs from the mouth (on the band's boundary) to the final tip inside the
    band. `progress(t)` is the arc length (mm) the cut front has reached at time t; behind it
    the two sides may separate, ahead of it they coincide. The straight continuation of the
    last segment from the tip to the boundary (`extension`) closes the partition of the band
    into the two sides, side(X) = +1 left of the path seen from the tip towards the mouth.
    """

    def __init__(self, points, band, progress, precut, description):
        self.points = np.asarray(points, dtype=float)
        seg = np.linalg.norm(np.diff(self.points, axis=0), axis=1)
        self.arclength = np.concatenate([[0.0], np.cumsum(seg)])
        self.length_mm = float(self.arclength[-1])
        self.band = band
        self.progress = progress  # callable t -> front arc length (mm)
        self.precut = precut
        self.description = description
        tip = self.points[-1]
        direction = tip - self.points[-2]
        direction /= np.linalg.norm(direction)
        self.extension = np.array([tip, band.exit_point(tip, direction)])
        # Partition polygon: path, extension, then the boundary back to the mouth.
        boundary = band.boundary_between(self.extension[1], self.points[0])
        self._polygon = np.concatenate([self.points, self.extension[1:], boundary])
        # Which polygon region is left of the first segment seen from the tip.
        a, b = self.points[1], self.points[0]
        d = (b - a) / np.linalg.norm(b - a)
        probe = 0.5 * (a + b) + 1e-3 * np.array([-d[1], d[0]])
        self._left_inside = bool(self._inside(probe[None, :])[0])

    def point_at(self, s):
        """Rest point (2,) at arc length s (clamped to the path)."""
        s = float(np.clip(s, 0.0, self.length_mm))
        return np.array([np.interp(s, self.arclength, self.points[:, k]) for k in range(2)])

    def front(self, t):
        return float(np.clip(self.progress(t), 0.0, self.length_mm))

    def opened_polyline(self, f):
        """The part of the path behind the front at arc length f (mouth -> front)."""
        if f <= 1e-9:
            return None
        keep = self.arclength < f
        return np.concatenate([self.points[keep], [self.point_at(f)]])

    def uncut_polyline(self, f):
        """The part of the path ahead of the front, continued by the extension."""
        keep = self.arclength > f
        return np.concatenate([[self.point_at(f)], self.points[keep], self.extension[1:]])

    def _inside(self, xy):
        """Even-odd test against the partition polygon (path, extension, boundary)."""
        poly = self._polygon
        inside = np.zeros(len(xy), dtype=bool)
        for (ax, ay), (bx, by) in zip(poly, np.roll(poly, -1, axis=0)):
            if ay == by:
                continue
            cond = (ay > xy[:, 1]) != (by > xy[:, 1])
            xcross = ax + (xy[:, 1] - ay) * (bx - ax) / (by - ay)
            inside ^= cond & (xy[:, 0] < xcross)
        return inside

    def side(self, xy):
        """+1 / -1 per 2D point (n x 2): +1 left of the path seen from the tip towards the mouth
        (and of its extension). Points on the path itself get an arbitrary side: the mesh gives
        the copies of cut vertices theirs."""
        xy = np.asarray(xy, dtype=float)
        # Points on the band's outline lie on the polygon's edges: test them a hair inside.
        center = np.array([0.0, self.band.H / 2])
        xy = center + (xy - center) * (1.0 - 1e-9)
        return np.where(self._inside(xy) == self._left_inside, 1, -1)

    def crossing_arclength(self, p, q):
        """Arc length where segment p -> q (2D) crosses the path, or None."""
        a, b = self.points[:-1], self.points[1:]
        r = q - p
        s = b - a
        denom = r[0] * s[:, 1] - r[1] * s[:, 0]
        ap = a - p
        with np.errstate(divide="ignore", invalid="ignore"):
            u = (ap[:, 0] * s[:, 1] - ap[:, 1] * s[:, 0]) / denom
            v = (ap[:, 0] * r[1] - ap[:, 1] * r[0]) / denom
        hit = (np.abs(denom) > 1e-12) & (u >= 0) & (u <= 1) & (v >= 0) & (v <= 1)
        if not hit.any():
            return None
        k = int(np.argmax(hit))
        return float(self.arclength[k] + v[k] * np.linalg.norm(s[k]))


class Band:
    def __init__(self, width, height, thickness):
        self.W, self.H, self.T = float(width), float(height), float(thickness)

    def corners(self):
        w = self.W / 2
        return np.array([[-w, 0.0], [w, 0.0], [w, self.H], [-w, self.H]])

    def _perimeter_param(self, p):
        """Position along the counter-clockwise boundary, starting at the bottom-left corner."""
        w, h = self.W / 2, self.H
        x, y = p
        if abs(y) < 1e-6:
            return x + w
        if abs(x - w) < 1e-6:
            return 2 * w + y
        if abs(y - h) < 1e-6:
            return 2 * w + h + (w - x)
        return 4 * w + h + (h - y)

    def boundary_between(self, p, q):
        """Boundary corners met going counter-clockwise from p to q (both on the boundary),
        excluding p, including q."""
        perim = 2 * (self.W + self.H)
        sp, sq = self._perimeter_param(p), self._perimeter_param(q)
        if sq <= sp:
            sq += perim
        out = []
        corners = self.corners()
        cparams = [self._perimeter_param(c) for c in corners]
        for lap in (0.0, perim):
            for c, s in zip(corners, cparams):
                if sp < s + lap < sq:
                    out.append((s + lap, c))
        out.sort(key=lambda e: e[0])
        return np.array([c for _, c in out] + [q])

    def exit_point(self, p, d):
        """Where the ray p + s d (s > 0) leaves the band's rectangle."""
        w, h = self.W / 2, self.H
        best = np.inf
        for axis, bound in ((0, -w), (0, w), (1, 0.0), (1, h)):
            if abs(d[axis]) > 1e-12:
                s = (bound - p[axis]) / d[axis]
                if s > 1e-9:
                    best = min(best, s)
        e = p + best * d
        return np.array([np.clip(e[0], -w, w), np.clip(e[1], 0.0, h)])


# ---------------------------------------------------------------------------------------------
# Smooth modes. Each maps points P (n x 3) at time t to new points; all are the identity at
# t = 0 because their amplitudes are multiplied by time profiles that vanish there.


class Hourglass:
    """Stretch along y to `stretch` x H at the top with a waist: the lateral (x) and thickness
    (z) contraction is 1 - waist sin^2(pi eta) (eta = y / H; none at the held bottom and at the
    gripped top), and the axial stretch is distributed along y as 1 / contraction^2 so that the
    cross-section area times the axial stretch is the same everywhere: the volume ratio is
    J = stretch / mean(1 / c^2) at every point, above 1 for the drawn stretches (the band gains
    volume, unlike nearly incompressible tissue)."""

    def __init__(self, band, stretch, waist, profile):
        self.band, self.stretch, self.waist, self.profile = band, stretch, waist, profile

    def _tables(self, t):
        p = float(self.profile(t))
        eta = np.linspace(-0.5, 1.5, 4001)
        inside = (eta >= 0) & (eta <= 1)
        c = 1.0 - self.waist * p * np.where(inside, np.sin(math.pi * eta) ** 2, 0.0)
        dens = 1.0 / c**2
        cum = np.concatenate([[0.0], np.cumsum(0.5 * (dens[1:] + dens[:-1]) * np.diff(eta))])
        zero = np.interp(0.0, eta, cum)
        one = np.interp(1.0, eta, cum)
        lam = 1.0 + (self.stretch - 1.0) * p
        mapped = (cum - zero) / (one - zero) * lam
        return eta, c, mapped

    def __call__(self, P, t):
        eta_tab, c_tab, y_tab = self._tables(t)
        eta = P[:, 1] / self.band.H
        c = np.interp(eta, eta_tab, c_tab)
        y = np.interp(eta, eta_tab, y_tab) * self.band.H
        return np.stack([P[:, 0] * c, y, P[:, 2] * c], axis=1)


class LateralSpread:
    """The top part widens: x scaled by 1 + spread eta^power, thickness by its inverse square
    root (area kept), the height by `lift` eta."""

    def __init__(self, band, spread, power, lift, profile):
        self.band, self.spread, self.power, self.lift = band, spread, power, lift
        self.profile = profile

    def __call__(self, P, t):
        p = float(self.profile(t))
        eta = np.clip(P[:, 1] / self.band.H, 0.0, None)
        s = 1.0 + self.spread * p * eta**self.power
        return np.stack(
            [P[:, 0] * s, P[:, 1] * (1.0 + self.lift * p), P[:, 2] / np.sqrt(s)], axis=1
        )


class Bow:
    """Out-of-plane bowing of the band (mm towards the camera) and a sideways sway of the top."""

    def __init__(self, band, bow_mm, sway_mm, profile):
        self.band, self.bow, self.sway, self.profile = band, bow_mm, sway_mm, profile

    def __call__(self, P, t):
        p = float(self.profile(t))
        eta = np.clip(P[:, 1] / self.band.H, 0.0, 1.0)
        xi = P[:, 0] / (self.band.W / 2)
        Q = P.copy()
        Q[:, 2] += self.bow * p * np.sin(math.pi * eta) * (1.0 - 0.3 * xi**2)
        Q[:, 0] += self.sway * p * eta**2
        return Q


class Twist:
    """In-plane rotation by angle theta exp(-r^2 / rho^2) about a centre: every circle about
    the centre maps onto itself, so the map stays one-to-one at any angle; the shear strain
    peaks at r ~ rho / sqrt(2)."""

    def __init__(self, center, theta, rho, profile):
        self.c, self.theta, self.rho, self.profile = np.asarray(center), theta, rho, profile

    def __call__(self, P, t):
        p = float(self.profile(t))
        rel = P[:, :2] - self.c
        r2 = (rel**2).sum(axis=1)
        ang = self.theta * p * np.exp(-r2 / self.rho**2)
        Q = P.copy()
        Q[:, :2] = self.c + _rotate2(rel, ang)
        return Q


class Pinch:
    """Radial contraction towards a centre, r -> r (1 - kappa exp(-r^2/rho^2)) (one-to-one for
    kappa < 1), with the gathered tissue bulging towards the camera by `lift` mm."""

    def __init__(self, center, kappa, rho, lift, profile):
        self.c, self.kappa, self.rho, self.lift = np.asarray(center), kappa, rho, lift
        self.profile = profile

    def __call__(self, P, t):
        p = float(self.profile(t))
        rel = P[:, :2] - self.c
        g = np.exp(-(rel**2).sum(axis=1) / self.rho**2)
        Q = P.copy()
        Q[:, :2] = self.c + rel * (1.0 - self.kappa * p * g)[:, None]
        Q[:, 2] += self.lift * p * g
        return Q


class Bulge:
    """A Gaussian bump of height h (mm, towards the camera) and radius rho."""

    def __init__(self, center, height, rho, profile):
        self.c, self.h, self.rho, self.profile = np.asarray(center), height, rho, profile

    def __call__(self, P, t):
        p = float(self.profile(t))
        g = np.exp(-((P[:, :2] - self.c) ** 2).sum(axis=1) / self.rho**2)
        Q = P.copy()
        Q[:, 2] += self.h * p * g
        return Q


class Dent:
    """An instrument pressing on the band at a contact point moving along a straight rest path:
    the band is pushed away from the camera by depth(t) exp(-r^2/rho^2) and dragged along the
    motion by drag(t) times the same profile."""

    def __init__(self, start, end, depth, rho, drag, t_contact):
        self.start, self.end = np.asarray(start, float), np.asarray(end, float)
        self.depth, self.rho, self.drag = depth, rho, drag
        self.t0, self.t1 = t_contact

    def contact(self, t):
        u = float(np.clip((t - self.t0) / (self.t1 - self.t0), 0.0, 1.0))
        return self.start + u * (self.end - self.start)

    def pressure(self, t):
        """Fraction of the full dent at time t: it grows after touch-down, fades at lift-off."""
        return float(smoothstep(0.0, self.t0, t) * (1.0 - smoothstep(self.t1, 1.0, t)))

    def __call__(self, P, t):
        k = self.pressure(t)
        if k == 0.0:
            return P.copy()
        c = self.contact(t)
        direction = (self.end - self.start) / np.linalg.norm(self.end - self.start)
        g = np.exp(-((P[:, :2] - c) ** 2).sum(axis=1) / self.rho**2)
        Q = P.copy()
        Q[:, 2] -= self.depth * k * g
        Q[:, :2] += (self.drag * k * g)[:, None] * direction[None, :]
        return Q


class FlapOpening:
    """Opening of a cut: each side turns about the current cut front f(t) by
    +/- alpha(t) m(X) w(X) g(X) (counter-clockwise for the side left of the path seen from the
    front towards the mouth), where
      m = min(1, dist(X, uncut path + extension) / rho_tip)  vanishes ahead of the front,
      w = 1 - smoothstep(50 deg, 125 deg, |angle between X - f and the opened direction|)
          limits the turn to the flaps behind the front,
      g = smoothstep(0, hold_mm, y) keeps the held bottom edge in place.
    All three are continuous and the turn angle is zero wherever the side label jumps except
    across the opened path, so the map is continuous ahead of the front and the two copies of a
    cut point separate behind it. The lips also lift towards the camera by `curl_mm` near the
    opened path (the same for both sides, so it opens nothing by itself)."""

    def __init__(self, cut, alpha_left, alpha_right, profile, rho_tip=12.0, hold_mm=40.0,
                 curl_mm=2.0):
        self.cut = cut
        self.alpha_left, self.alpha_right = alpha_left, alpha_right
        self.profile, self.rho_tip, self.hold_mm, self.curl_mm = profile, rho_tip, hold_mm, curl_mm

    def turn_weight(self, xy, t):
        """m w g (n,) and the front (2,) at time t; zero everywhere before the cut starts."""
        f = self.cut.front(t)
        front = self.cut.point_at(f)
        if f <= 1e-9:
            return np.zeros(len(xy)), front, f
        back = self.cut.point_at(max(0.0, f - 20.0)) - front
        back /= max(np.linalg.norm(back), 1e-12)
        m = np.clip(polyline_distance(xy, self.cut.uncut_polyline(f)) / self.rho_tip, 0.0, 1.0)
        rel = xy - front
        cosang = (rel @ back) / np.maximum(np.linalg.norm(rel, axis=1), 1e-12)
        ang = np.degrees(np.arccos(np.clip(cosang, -1.0, 1.0)))
        w = 1.0 - smoothstep(50.0, 125.0, ang)
        g = smoothstep(0.0, self.hold_mm, xy[:, 1])
        return m * w * g, front, f

    def __call__(self, P, side, t):
        q = float(self.profile(t))
        if q == 0.0:
            return P.copy()
        weight, front, f = self.turn_weight(P[:, :2], t)
        alpha = np.where(side > 0, self.alpha_left, -self.alpha_right) * q * weight
        Q = P.copy()
        Q[:, :2] = front + _rotate2(P[:, :2] - front, alpha)
        opened = self.cut.opened_polyline(f)
        if opened is not None and self.curl_mm != 0.0:
            d = polyline_distance(P[:, :2], opened)
            Q[:, 2] += self.curl_mm * q * weight * np.exp(-((d / 12.0) ** 2))
        return Q


class Phantom:
    """A drawn scene: band, optional cut, the modes applied in order, optional instrument."""

    def __init__(self, name, seed, band, cut, opening, modes, dent, instrument, internal,
                 params):
        self.name, self.seed, self.band = name, seed, band
        self.cut, self.opening, self.modes, self.dent = cut, opening, modes, dent
        self.instrument = instrument  # dict or None, see instrument_pose
        self.internal = internal  # dict describing the internal structure
        self.params = params  # drawn values, written to gt/meta.json

    def sides(self, X):
        """Side label (+1 / -1) of rest points (n x 3) from the cut's partition; +1 without a
        cut. Vertices duplicated along the cut carry their own label instead."""
        if self.cut is None:
            return np.ones(len(X), dtype=int)
        return self.cut.side(X[:, :2])

    def deform(self, X, side, t):
        """World positions (n x 3) at normalised time t of rest points X (n x 3) with sides."""
        P = np.asarray(X, dtype=float)
        if self.opening is not None:
            P = self.opening(P, np.asarray(side), t)
        else:
            P = P.copy()
        for mode in self.modes:
            P = mode(P, t)
        if self.dent is not None:
            P = self.dent(P, t)
        return P


# ---------------------------------------------------------------------------------------------
# Scenario draws. Every random value comes from the seed; the ranges are documented in
# tools/phantoms/README.md.


def _ramp(t0, t1):
    return lambda t: smoothstep(t0, t1, t)


def _ramp_hold_release(t0, t1, t2, t3, keep):
    """Up over [t0, t1], held, then down to `keep` over [t2, t3]."""
    return lambda t: smoothstep(t0, t1, t) * (1.0 - (1.0 - keep) * smoothstep(t2, t3, t))


def _linear_progress(length, t0, t1):
    return lambda t: length * float(np.clip((t - t0) / (t1 - t0), 0.0, 1.0))


def _jerky_progress(length, t0, t1, rng, steps):
    """Advances in `steps` quick jumps of random size separated by pauses (a tear)."""
    sizes = rng.uniform(0.5, 1.5, steps)
    sizes = np.concatenate([[0.0], np.cumsum(sizes / sizes.sum())]) * length
    starts = np.linspace(t0, t1, steps + 1)[:-1]
    dur = (t1 - t0) / steps * rng.uniform(0.35, 0.6, steps)

    def progress(t):
        f = 0.0
        for k in range(steps):
            u = float(np.clip((t - starts[k]) / dur[k], 0.0, 1.0))
            f = sizes[k] + u * (sizes[k + 1] - sizes[k]) if t >= starts[k] else f
        return f

    return progress


def _resample(points, step):
    points = np.asarray(points, dtype=float)
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    n = max(2, int(math.ceil(s[-1] / step)) + 1)
    q = np.linspace(0.0, s[-1], n)
    return np.stack([np.interp(q, s, points[:, k]) for k in range(2)], axis=1)


def _straight_path(band, rng, edge, length, angle_deg):
    """A straight path of `length` mm entering from `edge` ('top', 'left', 'right') at a
    seed-drawn position, turned by angle_deg from the edge's inward normal."""
    w, h = band.W / 2, band.H
    if edge == "top":
        mouth = np.array([rng.uniform(-0.25, 0.25) * band.W, h])
        normal = np.array([0.0, -1.0])
    elif edge == "left":
        mouth = np.array([-w, rng.uniform(0.45, 0.65) * h])
        normal = np.array([1.0, 0.0])
    else:
        mouth = np.array([w, rng.uniform(0.45, 0.65) * h])
        normal = np.array([-1.0, 0.0])
    a = math.radians(angle_deg)
    d = np.array([math.cos(a) * normal[0] - math.sin(a) * normal[1],
                  math.sin(a) * normal[0] + math.cos(a) * normal[1]])
    return mouth, d, np.array([mouth, mouth + length * d])


def _flap_angles(alpha, edge):
    """Per-side turn angles: for a cut from a side edge the flap towards the held bottom edge
    turns less (it is anchored closer)."""
    if edge == "top":
        return alpha, alpha
    # Left of the path seen from the tip towards the mouth: below for a cut from the left.
    below_is_left = edge == "left"
    lower, upper = 0.45 * alpha, alpha
    return (lower, upper) if below_is_left else (upper, lower)


def _draw_internal(rng, band, kind=None):
    """A vessel (tube along a smooth curve) or a tumour (ellipsoid) in the band's mid-plane."""
    kind = kind or ("vessel" if rng.uniform() < 0.5 else "tumour")
    T = band.T
    if kind == "vessel":
        radius = min(0.22 * T, 2.0)
        y0 = rng.uniform(0.3, 0.7) * band.H
        y1 = rng.uniform(0.3, 0.7) * band.H
        wig = rng.uniform(4.0, 10.0) * rng.choice([-1, 1])
        xs = np.linspace(-band.W / 2 + 8, band.W / 2 - 8, 40)
        u = (xs - xs[0]) / (xs[-1] - xs[0])
        ys = y0 + (y1 - y0) * u + wig * np.sin(math.pi * u)
        zs = rng.uniform(-0.1, 0.1) * T * np.ones_like(xs)
        return {"kind": "vessel", "radius_mm": radius,
                "centerline": np.stack([xs, ys, zs], axis=1)}
    center = np.array([rng.uniform(-0.25, 0.25) * band.W, rng.uniform(0.3, 0.6) * band.H, 0.0])
    axes = np.array([rng.uniform(8.0, 14.0), rng.uniform(6.0, 10.0), 0.3 * T])
    return {"kind": "tumour", "center": center, "semi_axes_mm": axes,
            "angle_deg": rng.uniform(0.0, 180.0)}


def draw_phantom(name, seed):
    """The scene `name` drawn from `seed` (deterministic)."""
    if name not in SCENARIOS:
        raise ValueError(f"unknown scenario '{name}' (expected one of: {', '.join(SCENARIOS)})")
    rng = np.random.default_rng([int(seed), list(SCENARIOS).index(name)])
    band = Band(rng.uniform(90.0, 110.0), rng.uniform(90.0, 110.0), rng.uniform(6.0, 10.0))
    params = {"width_mm": band.W, "height_mm": band.H, "thickness_mm": band.T}
    cut = opening = dent = instrument = None
    modes = []
    bow = Bow(band, rng.uniform(-6.0, 6.0), rng.uniform(-12.0, 12.0), _ramp(0.0, 0.6))

    if name == "stretch":
        stretch = rng.uniform(1.7, 1.9)
        waist = rng.uniform(0.18, 0.3)
        release = rng.uniform() < 0.5
        profile = (_ramp_hold_release(0.0, 0.55, 0.7, 1.0, rng.uniform(0.3, 0.6)) if release
                   else _ramp(0.0, 0.6))
        modes = [Hourglass(band, stretch, waist, profile), Bow(band, bow.bow, bow.sway, profile)]
        params.update(stretch=stretch, waist=waist, release=release, bow_mm=bow.bow,
                      sway_mm=bow.sway)

    elif name == "strain":
        stretch = rng.uniform(1.2, 1.4)
        prof = _ramp(0.05, 0.7)
        W, H = band.W, band.H
        c_twist = np.array([rng.uniform(-0.2, 0.2) * W, rng.uniform(0.55, 0.75) * H])
        c_pinch = np.array([rng.uniform(-0.3, 0.3) * W, rng.uniform(0.25, 0.4) * H])
        c_bulge = np.array([-np.sign(c_pinch[0] + 1e-9) * rng.uniform(0.15, 0.3) * W,
                            rng.uniform(0.4, 0.6) * H])
        twist = math.radians(rng.uniform(35.0, 60.0)) * rng.choice([-1, 1])
        kappa = rng.uniform(0.35, 0.5)
        modes = [
            Twist(c_twist, twist, rng.uniform(10.0, 16.0), prof),
            Pinch(c_pinch, kappa, rng.uniform(9.0, 14.0), rng.uniform(3.0, 6.0), prof),
            Bulge(c_bulge, rng.uniform(5.0, 9.0), rng.uniform(10.0, 16.0), _ramp(0.2, 0.9)),
            Hourglass(band, stretch, rng.uniform(0.08, 0.15), prof),
            bow,
        ]
        params.update(stretch=stretch, twist_deg=math.degrees(twist), pinch_kappa=kappa,
                      twist_center=c_twist.tolist(), pinch_center=c_pinch.tolist(),
                      bulge_center=c_bulge.tolist())

    elif name == "instrument":
        W, H = band.W, band.H
        a = np.array([rng.uniform(-0.3, 0.3) * W, rng.uniform(0.2, 0.4) * H])
        b = np.array([rng.uniform(-0.3, 0.3) * W, rng.uniform(0.6, 0.8) * H])
        if rng.uniform() < 0.5:
            a, b = b, a
        t0, t1 = rng.uniform(0.1, 0.2), rng.uniform(0.8, 0.9)
        dent = Dent(a, b, rng.uniform(4.0, 8.0), rng.uniform(8.0, 14.0),
                    rng.uniform(2.0, 5.0), (t0, t1))
        modes = [Hourglass(band, rng.uniform(1.1, 1.25), 0.08, _ramp(0.0, 0.7)), bow]
        instrument = {"mode": "press", "kind": "grasper"}
        params.update(dent_depth_mm=dent.depth, dent_radius_mm=dent.rho, drag_mm=dent.drag,
                      contact_path=[a.tolist(), b.tolist()], contact_times=[t0, t1])

    else:
        # Cut scenes.
        if name == "precut":
            edge = rng.choice(["top", "left", "right"])
            length = float(rng.choice([25.0, 35.0, 45.0, 55.0]) if edge == "top"
                           else rng.choice([25.0, 35.0, 45.0]))
            _, _, pts = _straight_path(band, rng, edge, length, rng.uniform(-10.0, 10.0))
            progress = lambda t: float("inf")  # open from frame 0
            alpha = math.radians(rng.uniform(12.0, 20.0))
            prof = _ramp(0.05, 0.6)
            desc = f"slit of {{L:.0f}} mm from the {edge} edge, open from frame 0"
            precut = True
        else:
            t0, t1 = rng.uniform(0.15, 0.3), rng.uniform(0.6, 0.75)
            precut = False
            if name == "cut-straight":
                edge = rng.choice(["top", "left", "right"])
                length = rng.uniform(40.0, 65.0)
                _, _, pts = _straight_path(band, rng, edge, length, rng.uniform(-25.0, 25.0))
                alpha = math.radians(rng.uniform(10.0, 16.0))
                desc = f"straight cut of {{L:.0f}} mm from the {edge} edge"
            elif name == "cut-v":
                edge = "top"
                length = rng.uniform(50.0, 75.0)
                _, _, pts = _straight_path(band, rng, edge, length, rng.uniform(-5.0, 5.0))
                alpha = math.radians(rng.uniform(16.0, 24.0))
                desc = "vertical cut of {L:.0f} mm from the top edge, halves splay into a V"
            elif name == "cut-curved":
                edge = rng.choice(["top", "left", "right"])
                length = rng.uniform(45.0, 65.0)
                mouth, d, _ = _straight_path(band, rng, edge, length, rng.uniform(-15.0, 15.0))
                normal = np.array([-d[1], d[0]])
                u = np.linspace(0.0, 1.0, 60)
                if rng.uniform() < 0.5:
                    shape = "arc"
                    bend = rng.uniform(8.0, 14.0) * rng.choice([-1, 1])
                    off = bend * 4.0 * u * (1.0 - u) + bend * 0.6 * u**2
                else:
                    shape = "S"
                    off = rng.uniform(5.0, 9.0) * rng.choice([-1, 1]) * np.sin(2 * math.pi * u)
                pts = mouth + np.outer(u * length, d) + np.outer(off, normal)
                alpha = math.radians(rng.uniform(10.0, 16.0))
                desc = f"{shape}-shaped cut of {{L:.0f}} mm from the {edge} edge"
            else:  # tear
                edge = rng.choice(["top", "left", "right"])
                length = rng.uniform(45.0, 70.0)
                mouth, d, _ = _straight_path(band, rng, edge, length, rng.uniform(-15.0, 15.0))
                normal = np.array([-d[1], d[0]])
                n = int(length / 4.0)
                u = np.linspace(0.0, 1.0, n + 1)
                jag = rng.uniform(-2.5, 2.5, n + 1)
                jag[0] = 0.0
                wander = rng.uniform(3.0, 8.0) * rng.choice([-1, 1]) * np.sin(math.pi * u * 1.3)
                along = u * length + rng.uniform(-0.8, 0.8, n + 1) * (u > 0) * (u < 1)
                pts = mouth + np.outer(along, d) + np.outer(jag + wander, normal)
                alpha = math.radians(rng.uniform(10.0, 15.0))
                desc = f"jagged tear of {{L:.0f}} mm from the {edge} edge"
            pts = _resample(_clip_inside(band, pts), 1.0)
            # The tip stays in the upper 62 % of the band: the held bottom edge is not torn
            # towards.
            pts = pts[np.concatenate([[True], pts[1:, 1] >= 0.38 * band.H])]
            length = float(np.linalg.norm(np.diff(pts, axis=0), axis=1).sum())
            progress = (_jerky_progress(length, t0, t1, rng, int(rng.integers(3, 6)))
                        if name == "tear" else _linear_progress(length, t0, t1))
            prof = _ramp(t0, min(1.0, t1 + 0.15))
        pts = _resample(pts, 1.0)
        cut = CutPath(pts, band, progress, precut, desc)
        cut.description = desc.format(L=cut.length_mm)
        a_left, a_right = _flap_angles(alpha, edge)
        opening = FlapOpening(cut, a_left, a_right, prof, hold_mm=0.4 * band.H,
                              curl_mm=rng.uniform(1.0, 3.0))
        if edge == "top" or name == "cut-v":
            spread = rng.uniform(0.15, 0.3) if name != "cut-v" else rng.uniform(0.3, 0.45)
            modes = [LateralSpread(band, spread, 2.0, rng.uniform(0.05, 0.15), prof), bow]
        else:
            modes = [Hourglass(band, rng.uniform(1.15, 1.35), 0.08, prof), bow]
        params.update(cut_edge=str(edge), cut_length_mm=cut.length_mm,
                      turn_deg=math.degrees(alpha), precut=precut)
        # Seed-chosen instruments over the cut: scissors following the front, or a crossing.
        if rng.uniform() < 0.5:
            instrument = {"mode": "follow" if not precut else "cross", "kind": "scissors"}

    internal = _draw_internal(rng, band)
    if instrument is not None:
        instrument.update(_draw_instrument(rng, band))
    params["instrument"] = None if instrument is None else instrument["mode"]
    params["internal"] = internal["kind"]
    return Phantom(name, seed, band, cut, opening, modes, dent, instrument, internal, params)


def _clip_inside(band, pts):
    """Keeps a drawn path inside the band (2 mm from the other edges); the mouth stays."""
    w, h = band.W / 2, band.H
    q = pts.copy()
    q[1:, 0] = np.clip(q[1:, 0], -w + 2.0, w - 2.0)
    q[1:, 1] = np.clip(q[1:, 1], 2.0, h - 2.0)
    return q


def _draw_instrument(rng, band):
    """Shaft direction (elevation above the band plane and azimuth), crossing path, jaw cycle."""
    return {
        "elevation_deg": rng.uniform(35.0, 55.0),
        "azimuth_deg": rng.uniform(0.0, 360.0),
        "hover_mm": rng.uniform(2.0, 4.0),
        "cross_height_mm": rng.uniform(8.0, 16.0),
        "cross_from": [rng.uniform(-0.7, -0.5) * band.W, rng.uniform(0.2, 0.8) * band.H],
        "cross_to": [rng.uniform(0.5, 0.7) * band.W, rng.uniform(0.2, 0.8) * band.H],
        "jaw_period_s": rng.uniform(0.6, 1.2),
    }


def instrument_pose(phantom, t):
    """Tip position (3,), shaft direction from the tip outwards (3,), visible flag, for time t.
    'press': the jaws rest in the dent; 'follow': the tip hovers above the cut front (before
    the cut starts it waits above the mouth, afterwards it withdraws); 'cross': it sweeps over
    the band at a height."""
    inst = phantom.instrument
    el, az = math.radians(inst["elevation_deg"]), math.radians(inst["azimuth_deg"])
    axis = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
    T = phantom.band.T
    if inst["mode"] == "press":
        c = phantom.dent.contact(t)
        X = np.array([[c[0], c[1], T / 2]])
        tip = phantom.deform(X, np.ones(1), t)[0] + np.array([0.0, 0.0, 1.0])
        lift = (1.0 - smoothstep(0.0, phantom.dent.t0, t) + smoothstep(phantom.dent.t1, 1.0, t))
        return tip + axis * 25.0 * lift, axis
    if inst["mode"] == "follow":
        cut = phantom.cut
        f = cut.front(t)
        p = cut.point_at(f)
        # At the front both sides' copies coincide: either side label gives the point.
        tip = phantom.deform(np.array([[p[0], p[1], T / 2]]), np.ones(1), t)[0]
        tip = tip + np.array([0.0, 0.0, inst["hover_mm"]])
        done = smoothstep(0.0, 0.1, t - _done_time(phantom))
        return tip + axis * 60.0 * done, axis
    a = np.array(inst["cross_from"] + [T / 2 + inst["cross_height_mm"]])
    b = np.array(inst["cross_to"] + [T / 2 + inst["cross_height_mm"]])
    u = float(smoothstep(0.1, 0.9, t))
    return a + u * (b - a), axis


def _done_time(phantom):
    """First normalised time at which the cut front reaches its final length."""
    ts = np.linspace(0.0, 1.0, 1001)
    L = phantom.cut.length_mm
    for t in ts:
        if phantom.cut.front(t) >= L - 1e-9:
            return float(t)
    return 1.0
