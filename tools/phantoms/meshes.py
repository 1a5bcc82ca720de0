"""Meshes of the phantom scenes and the files they are written to (numpy; the 2D constrained
Delaunay triangulation comes from Blender's mathutils).

- the band's render surface: a fine triangulation of the rest rectangle that contains the
  final cut path as constraint edges; the vertices on the path are duplicated (one copy per
  side, the tip excepted) and the outline of the split triangulation is extruded through the
  thickness, so the cut is real geometry with walls;
- the coarse tetrahedral model: its own triangulation (a triangular lattice), one prism layer
  through the thickness, each prism split into three tetrahedra; it never contains the cut;
- the internal structure (vessel tube or tumour ellipsoid) and the background sheet.
"""

import json
import math
import os
import struct
import zlib

import numpy as np


def _cdt(points, edges):
    """Constrained Delaunay triangulation of 2D points (n x 2) with constraint edges; returns
    the output points, the triangles (counter-clockwise) and for each output point the input
    point it came from (-1 for none)."""
    from mathutils import Vector
    from mathutils.geometry import delaunay_2d_cdt

    verts = [Vector((float(x), float(y))) for x, y in points]
    out_v, _, out_f, orig_v, _, _ = delaunay_2d_cdt(verts, [tuple(e) for e in edges], [], 0,
                                                     1e-5)
    origin = np.array([o[0] if len(o) else -1 for o in orig_v], dtype=np.int64)
    # mathutils works in single precision: take the input's double coordinates back.
    pts = np.array([[v.x, v.y] for v in out_v])
    pts[origin >= 0] = np.asarray(points, dtype=float)[origin[origin >= 0]]
    tris = np.array(out_f, dtype=np.int64)
    a, b, c = pts[tris[:, 0]], pts[tris[:, 1]], pts[tris[:, 2]]
    area2 = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    tris[area2 < 0] = tris[area2 < 0][:, [0, 2, 1]]
    return pts, tris, origin


def _lattice(band, spacing):
    """Triangular lattice of points strictly inside the band's rectangle (2D)."""
    w, h = band.W / 2, band.H
    dy = spacing * math.sqrt(3) / 2
    rows = []
    for j, y in enumerate(np.arange(dy / 2, h, dy)):
        off = 0.5 * spacing if j % 2 else 0.0
        xs = np.arange(-w + off + spacing / 2, w, spacing)
        rows.append(np.stack([xs, np.full_like(xs, y)], axis=1))
    return np.concatenate(rows)


def _rectangle_outline(band, spacing, extra=()):
    """Points along the rectangle's boundary (counter-clockwise from the bottom-left corner),
    spacing about `spacing`, including the given extra boundary points."""
    w, h = band.W / 2, band.H
    corners = [(-w, 0.0), (w, 0.0), (w, h), (-w, h)]
    pts = []
    for k in range(4):
        a, b = np.array(corners[k]), np.array(corners[(k + 1) % 4])
        n = max(1, int(round(np.linalg.norm(b - a) / spacing)))
        seg = [a + (b - a) * i / n for i in range(n)]
        for e in extra:
            e = np.asarray(e)
            d = b - a
            u = np.dot(e - a, d) / np.dot(d, d)
            if 0 < u < 1 and abs(np.cross(d, e - a)) < 1e-6 * np.linalg.norm(d):
                seg = [p for p in seg if np.linalg.norm(p - e) > 0.45 * spacing or
                       np.allclose(p, a)]
                seg.append(e)
        seg.sort(key=lambda p: np.dot(p - a, b - a))
        pts.extend(seg)
    return np.array(pts)


def _fan_sides(tris, v, path_neighbours, tri_side):
    """The triangles around vertex v split into the groups that the path's edges at v separate
    (two for a vertex of the path), each with its side: the majority of its triangles'
    centroid test, the two groups forced apart. Grouping by the fan's topology, not by each
    centroid, keeps thin triangles at a sharp bend of a jagged path on the right side."""
    around = np.nonzero((tris == v).any(axis=1))[0]
    parent = {int(k): int(k) for k in around}

    def find(k):
        while parent[k] != k:
            parent[k] = parent[parent[k]]
            k = parent[k]
        return k

    by_edge = {}
    for k in around:
        for q in tris[k]:
            q = int(q)
            if q != v and q not in path_neighbours:
                by_edge.setdefault(q, []).append(int(k))
    for ks in by_edge.values():
        for k in ks[1:]:
            parent[find(k)] = find(ks[0])
    groups = {}
    for k in around:
        groups.setdefault(find(int(k)), []).append(int(k))
    groups = sorted(groups.values(), key=len, reverse=True)
    votes = [int(np.sign(tri_side[g].sum())) or 1 for g in groups]
    if len(groups) == 2 and votes[0] == votes[1]:
        # Both groups vote alike: the clearer vote wins, the other group takes the other side.
        strength = [abs(tri_side[g].sum()) / len(g) for g in groups]
        weaker = int(np.argmin(strength))
        votes[weaker] = -votes[1 - weaker]
    return list(zip(groups, votes))


class BandSurface:
    """The band's closed render surface, split along the final cut path.

    vertices_rest (n x 3), sides (n,) side label of each vertex (for the deformation),
    faces (m x 3, outward), face_kind (m,) 0 front/back, 1 outer wall, 2 cut wall,
    twins (k x 2) vertex pairs that are the two copies of one cut point,
    front_twins the subset of twins on the front face."""

    def __init__(self, phantom, spacing):
        band, cut = phantom.band, phantom.cut
        lattice = _lattice(band, spacing)
        extra = [] if cut is None else [cut.points[0]]
        outline = _rectangle_outline(band, spacing, extra)
        pts = [outline]
        edges = [(i, (i + 1) % len(outline)) for i in range(len(outline))]
        keep = np.ones(len(lattice), dtype=bool)
        d_edge = np.minimum.reduce([lattice[:, 0] + band.W / 2, band.W / 2 - lattice[:, 0],
                                    lattice[:, 1], band.H - lattice[:, 1]])
        keep &= d_edge > 0.45 * spacing
        cut_index = None
        if cut is not None:
            from fields import _resample, polyline_distance

            path = _resample(cut.points, spacing)
            keep &= polyline_distance(lattice, path) > 0.45 * spacing
            # The mouth coincides with an outline point; the rest of the path is new.
            mouth = int(np.argmin(np.linalg.norm(outline - path[0], axis=1)))
            first = len(outline)
            cut_index = [mouth] + list(range(first, first + len(path) - 1))
            pts.append(path[1:])
            edges += [(cut_index[i], cut_index[i + 1]) for i in range(len(path) - 1)]
        pts.append(lattice[keep])
        pts = np.concatenate(pts)
        out_pts, tris, origin = _cdt(pts, edges)
        n2 = len(out_pts)
        sides2 = np.ones(n2, dtype=int)
        twins2 = []
        if cut is not None:
            inverse = {int(o): i for i, o in enumerate(origin) if o >= 0}
            cut_out = [inverse[i] for i in cut_index]
            sides2 = phantom.sides(np.c_[out_pts, np.zeros(n2)])
            tri_side = cut.side(out_pts[tris].mean(axis=1))
            # Every path vertex but the tip gets a copy for the triangles on side -1.
            copies = {}
            for v in cut_out[:-1]:
                copies[v] = n2 + len(copies)
            new_pts = [out_pts] + [out_pts[list(copies)]]
            for i, v in enumerate(cut_out[:-1]):
                neighbours = {cut_out[i + 1]} | ({cut_out[i - 1]} if i > 0 else set())
                for group, side in _fan_sides(tris, v, neighbours, tri_side):
                    if side < 0:
                        for k in group:
                            tris[k][tris[k] == v] = copies[v]
            out_pts = np.concatenate(new_pts)
            sides2 = np.concatenate([sides2, -np.ones(len(copies), dtype=int)])
            for v in copies:
                sides2[v] = 1
            twins2 = [(v, c) for v, c in copies.items()]
            self.tip2 = cut_out[-1]
        n2 = len(out_pts)
        self.points2 = out_pts
        self.tris2 = tris
        T = band.T
        front = np.c_[out_pts, np.full(n2, T / 2)]
        back = np.c_[out_pts, np.full(n2, -T / 2)]
        self.vertices_rest = np.concatenate([front, back])
        self.sides = np.concatenate([sides2, sides2])
        faces = [tris, tris[:, [0, 2, 1]] + n2]
        kinds = [np.zeros(len(tris), int), np.zeros(len(tris), int)]
        # Outline of the split triangulation: edges used by one triangle, oriented as in it.
        e = np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
        key = np.sort(e, axis=1)
        _, inv, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
        border = e[counts[inv] == 1]
        twin_set = set()
        for v, c in twins2:
            twin_set.update((v, c))
        if cut is not None:
            twin_set.add(self.tip2)
        walls = []
        wall_kind = []
        for a, b in border:
            # Outward wall: front a -> b runs counter-clockwise around the interior.
            walls.append((b, a, a + n2))
            walls.append((b, a + n2, b + n2))
            kind = 2 if (a in twin_set and b in twin_set) else 1
            wall_kind += [kind, kind]
        faces.append(np.array(walls, dtype=np.int64))
        kinds.append(np.array(wall_kind, dtype=int))
        self.faces = np.concatenate(faces)
        self.face_kind = np.concatenate(kinds)
        tw = np.array(twins2, dtype=np.int64).reshape(-1, 2)
        self.front_twins = tw
        self.twins = np.concatenate([tw, tw + n2])

    def deformed(self, phantom, t):
        return phantom.deform(self.vertices_rest, self.sides, t)

    def opening_mm(self, x):
        """Largest distance between the two copies of a cut point on the front face."""
        if len(self.front_twins) == 0:
            return 0.0
        d = np.linalg.norm(x[self.front_twins[:, 0]] - x[self.front_twins[:, 1]], axis=1)
        return float(d.max())

    def surface_faces(self, x):
        """Faces of the true surface at positions x: cut walls whose copies still coincide
        (the unopened part, inside the tissue) are left out."""
        keep = self.face_kind != 2
        if (~keep).any():
            partner = np.arange(len(x))
            partner[self.twins[:, 0]] = self.twins[:, 1]
            partner[self.twins[:, 1]] = self.twins[:, 0]
            f = self.faces[~keep]
            sep = np.linalg.norm(x[f] - x[partner[f]], axis=2).max(axis=1)
            keep[np.nonzero(~keep)[0][sep > 1e-6]] = True
        return self.faces[keep]


def model_tets(band, spacing):
    """Coarse tetrahedral model of the rest band: triangular lattice triangulated in the plane,
    one prism layer, each prism split into 3 tetrahedra by the vertex-order rule (a quad face
    is split on the diagonal from its lowest-numbered bottom vertex), which makes shared quad
    faces agree. Returns vertices (n x 3) and positively oriented tetrahedra (m x 4)."""
    outline = _rectangle_outline(band, spacing)
    lat = _lattice(band, spacing)
    d_edge = np.minimum.reduce([lat[:, 0] + band.W / 2, band.W / 2 - lat[:, 0], lat[:, 1],
                                band.H - lat[:, 1]])
    pts = np.concatenate([outline, lat[d_edge > 0.45 * spacing]])
    edges = [(i, (i + 1) % len(outline)) for i in range(len(outline))]
    p2, tris, _ = _cdt(pts, edges)
    n = len(p2)
    T = band.T
    verts = np.concatenate([np.c_[p2, np.full(n, -T / 2)], np.c_[p2, np.full(n, T / 2)]])
    tets = []
    for tri in tris:
        i, j, k = sorted(int(v) for v in tri)
        I, J, K = i + n, j + n, k + n
        tets += [(i, j, k, K), (i, j, J, K), (i, I, J, K)]
    tets = np.array(tets, dtype=np.int64)
    a, b, c, d = (verts[tets[:, q]] for q in range(4))
    vol = np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a)
    tets[vol < 0] = tets[vol < 0][:, [0, 2, 1, 3]]
    return verts, tets


def internal_mesh(phantom):
    """Closed surface (vertices, faces) of the internal structure at rest."""
    spec = phantom.internal
    if spec["kind"] == "vessel":
        line = spec["centerline"]
        r = spec["radius_mm"]
        ring = 16
        tang = np.gradient(line, axis=0)
        tang /= np.linalg.norm(tang, axis=1)[:, None]
        zaxis = np.array([0.0, 0.0, 1.0])
        verts = []
        for p, tv in zip(line, tang):
            n1 = zaxis - tv * np.dot(zaxis, tv)
            n1 /= np.linalg.norm(n1)
            n2 = np.cross(tv, n1)
            for k in range(ring):
                a = 2 * math.pi * k / ring
                verts.append(p + r * (math.cos(a) * n1 + math.sin(a) * n2))
        m = len(line)
        faces = []
        for i in range(m - 1):
            for k in range(ring):
                a, b = i * ring + k, i * ring + (k + 1) % ring
                c, d = a + ring, b + ring
                faces += [(a, c, b), (b, c, d)]
        verts.append(line[0])
        verts.append(line[-1])
        s0, s1 = len(verts) - 2, len(verts) - 1
        for k in range(ring):
            faces.append((s0, (k + 1) % ring, k))
            faces.append((s1, (m - 1) * ring + k, (m - 1) * ring + (k + 1) % ring))
        verts, faces = np.array(verts), np.array(faces, dtype=np.int64)
    else:
        nu, nv = 24, 12
        verts = [(0.0, 0.0, -1.0)]
        for j in range(1, nv):
            th = math.pi * j / nv - math.pi / 2
            for i in range(nu):
                ph = 2 * math.pi * i / nu
                verts.append((math.cos(th) * math.cos(ph), math.cos(th) * math.sin(ph),
                              math.sin(th)))
        verts.append((0.0, 0.0, 1.0))
        faces = []
        for i in range(nu):
            faces.append((0, 1 + (i + 1) % nu, 1 + i))
        for j in range(nv - 2):
            for i in range(nu):
                a = 1 + j * nu + i
                b = 1 + j * nu + (i + 1) % nu
                faces += [(a, b, a + nu), (b, b + nu, a + nu)]
        top = len(verts) - 1
        base = 1 + (nv - 2) * nu
        for i in range(nu):
            faces.append((top, base + i, base + (i + 1) % nu))
        verts = np.array(verts) * spec["semi_axes_mm"]
        ang = math.radians(spec["angle_deg"])
        rot = np.array([[math.cos(ang), -math.sin(ang), 0], [math.sin(ang), math.cos(ang), 0],
                        [0, 0, 1]])
        verts = verts @ rot.T + spec["center"]
        faces = np.array(faces, dtype=np.int64)
    # Outward orientation (positive enclosed volume) whatever the parametrisation's handedness.
    a, b, c = verts[faces[:, 0]], verts[faces[:, 1]], verts[faces[:, 2]]
    if np.einsum("ij,ij->i", a, np.cross(b, c)).sum() < 0:
        faces = faces[:, [0, 2, 1]]
    return verts, faces


def internal_faces_at(phantom, verts_rest, faces, t):
    """Faces of the internal structure kept at time t: a triangle whose edge crosses the
    opened part of the cut path is torn apart and dropped (its corners move with different
    flaps)."""
    cut = phantom.cut
    if cut is None:
        return faces
    side = phantom.sides(verts_rest)
    mixed = np.nonzero((side[faces] != side[faces[:, :1]]).any(axis=1))[0]
    f = cut.front(t)
    drop = []
    for k in mixed:
        for a, b in ((0, 1), (1, 2), (2, 0)):
            s = cut.crossing_arclength(verts_rest[faces[k, a], :2], verts_rest[faces[k, b], :2])
            if s is not None and s < f:
                drop.append(k)
                break
    keep = np.ones(len(faces), dtype=bool)
    keep[drop] = False
    return faces[keep]


# ---------------------------------------------------------------------------------------------
# Camera projection and the silhouette mask (pixel centres, OpenCV convention).


def project(K, R, tvec, x):
    """Pixels (n x 2) and depths (n,) of world points x (n x 3); K = (fx, fy, cx, cy)."""
    pc = x @ R.T + tvec
    z = pc[:, 2]
    return np.stack([K[0] * pc[:, 0] / z + K[2], K[1] * pc[:, 1] / z + K[3]], axis=1), z


def rasterize_mask(K, R, tvec, x, faces, width, height):
    """Binary mask (height x width, uint8 0/255) of the union of the projected triangles,
    sampled at pixel centres (a pixel is inside when its centre is inside or on an edge of a
    triangle). Every vertex must be in front of the camera."""
    uv, z = project(K, R, tvec, x)
    if (z <= 0).any():
        raise ValueError("a surface point is behind the camera")
    mask = np.zeros((height, width), dtype=bool)
    tri = uv[faces]  # (m, 3, 2)
    lo = np.floor(tri.min(axis=1)).astype(np.int64)
    hi = np.ceil(tri.max(axis=1)).astype(np.int64)
    lo = np.maximum(lo, 0)
    hi[:, 0] = np.minimum(hi[:, 0], width - 1)
    hi[:, 1] = np.minimum(hi[:, 1], height - 1)
    ok = (hi >= lo).all(axis=1)
    tri, lo, hi = tri[ok], lo[ok], hi[ok]
    size = (hi - lo + 1).max(axis=1)
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    area = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    sgn = np.where(area < 0, -1.0, 1.0)
    nondeg = np.abs(area) > 1e-12
    # Group by bounding-box size so that one vectorised pass covers a window per triangle.
    bucket = np.ceil(np.log2(np.maximum(size, 1))).astype(int)
    for bexp in np.unique(bucket):
        sel = np.nonzero((bucket == bexp) & nondeg)[0]
        win = 1 << int(bexp)
        for dy in range(win):
            for dx in range(win):
                px = lo[sel, 0] + dx
                py = lo[sel, 1] + dy
                inb = (px <= hi[sel, 0]) & (py <= hi[sel, 1])
                if not inb.any():
                    continue
                s = sel[inb]
                qx, qy = px[inb].astype(float), py[inb].astype(float)
                e0 = ((b[s, 0] - a[s, 0]) * (qy - a[s, 1]) - (b[s, 1] - a[s, 1]) * (qx - a[s, 0]))
                e1 = ((c[s, 0] - b[s, 0]) * (qy - b[s, 1]) - (c[s, 1] - b[s, 1]) * (qx - b[s, 0]))
                e2 = ((a[s, 0] - c[s, 0]) * (qy - c[s, 1]) - (a[s, 1] - c[s, 1]) * (qx - c[s, 0]))
                g = sgn[s]
                inside = (e0 * g >= 0) & (e1 * g >= 0) & (e2 * g >= 0)
                mask[py[inb][inside], px[inb][inside]] = True
    return (mask * 255).astype(np.uint8)


# ---------------------------------------------------------------------------------------------
# Writers (the caller writes into a temporary folder that is renamed when complete).


def write_obj(path, verts, faces, header=None):
    used = np.unique(faces)
    remap = -np.ones(len(verts), dtype=np.int64)
    remap[used] = np.arange(len(used))
    lines = [] if header is None else [f"# {header}"]
    lines += [f"v {p[0]:.6f} {p[1]:.6f} {p[2]:.6f}" for p in verts[used]]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in remap[faces]]
    with open(path, "w") as f:
        f.write("\n".join(lines) + "\n")


def write_vtk_tets(path, verts, tets, title):
    lines = ["# vtk DataFile Version 3.0", title, "ASCII", "DATASET UNSTRUCTURED_GRID",
             f"POINTS {len(verts)} double"]
    lines += [f"{p[0]:.9g} {p[1]:.9g} {p[2]:.9g}" for p in verts]
    lines.append(f"CELLS {len(tets)} {5 * len(tets)}")
    lines += [f"4 {a} {b} {c} {d}" for a, b, c, d in tets]
    lines.append(f"CELL_TYPES {len(tets)}")
    lines += ["10"] * len(tets)
    with open(path, "w") as f:
        f.write("\n".join(lines) + "\n")


def write_png(path, image):
    """8-bit PNG: greyscale (height x width) or RGB (height x width x 3) uint8."""
    h, w = image.shape[:2]
    ctype = 0 if image.ndim == 2 else 2
    raw = b"".join(b"\x00" + image[r].tobytes() for r in range(h))

    def chunk(tag, data):
        return (struct.pack(">I", len(data)) + tag + data +
                struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF))

    png = (b"\x89PNG\r\n\x1a\n" +
           chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, ctype, 0, 0, 0)) +
           chunk(b"IDAT", zlib.compress(raw, 6)) + chunk(b"IEND", b""))
    with open(path, "wb") as f:
        f.write(png)


def read_png_gray(path):
    """Reads back a greyscale image written by write_png (8-bit, unfiltered rows only)."""
    with open(path, "rb") as f:
        data = f.read()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        raise ValueError(f"{path}: not a PNG file")
    pos, idat, w, h = 8, b"", 0, 0
    while pos < len(data):
        n = struct.unpack(">I", data[pos : pos + 4])[0]
        tag = data[pos + 4 : pos + 8]
        body = data[pos + 8 : pos + 8 + n]
        if tag == b"IHDR":
            w, h, depth, ctype = struct.unpack(">IIBB", body[:10])
            if depth != 8 or ctype != 0:
                raise ValueError(f"{path}: expected 8-bit greyscale")
        elif tag == b"IDAT":
            idat += body
        pos += 12 + n
    raw = np.frombuffer(zlib.decompress(idat), dtype=np.uint8).reshape(h, w + 1)
    if (raw[:, 0] != 0).any():
        raise ValueError(f"{path}: filtered rows are not supported")
    return raw[:, 1:].copy()


def write_json(path, value):
    with open(path, "w") as f:
        json.dump(value, f, indent=2)
        f.write("\n")


def frame_name(frame, ext):
    return f"{frame:06d}.{ext}"


def ensure_dir(path):
    os.makedirs(path, exist_ok=True)
