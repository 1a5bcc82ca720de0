"""Tests of the phantom scene source (tools/phantoms), run inside Blender's Python by
tests/tools/run-phantoms-test:

  blender -b --factory-startup -noaudio --python-exit-code 1 -P tests/tools/test_phantoms.py \
      -- [--arreg PATH]

The analytic fields' invariants, the render surface and the coarse model, then a tiny render
(96x80, 3 frames, 4 samples) end to end: layout, masks against Cycles' own rendering of the
ground-truth surface, and `arreg run` + `arreg eval` on it when --arreg is given.
"""

import json
import os
import shutil
import subprocess
import sys
import tempfile
import unittest

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
TOOL = os.path.join(ROOT, "tools", "phantoms")
sys.path.insert(0, TOOL)

import numpy as np  # noqa: E402

import fields  # noqa: E402
import meshes  # noqa: E402

ARREG = None
SEEDS = (1, 2, 3, 4)


def _rest_grid(band, n=41, z=None):
    xs = np.linspace(-band.W / 2, band.W / 2, n)
    ys = np.linspace(0.0, band.H, n)
    zz = band.T / 2 if z is None else z
    return np.array([[x, y, zz] for y in ys for x in xs])


class FieldTest(unittest.TestCase):
    def test_identity_at_time_zero(self):
        for name in fields.SCENARIOS:
            for seed in SEEDS:
                ph = fields.draw_phantom(name, seed)
                X = np.concatenate([_rest_grid(ph.band), _rest_grid(ph.band, z=-ph.band.T / 2)])
                for side in (1, -1):
                    x = ph.deform(X, np.full(len(X), side), 0.0)
                    self.assertLess(np.abs(x - X).max(), 1e-9, f"{name} seed {seed}")

    def test_draw_is_deterministic(self):
        a = fields.draw_phantom("tear", 5)
        b = fields.draw_phantom("tear", 5)
        self.assertTrue(np.array_equal(a.cut.points, b.cut.points))
        X = _rest_grid(a.band)
        np.testing.assert_array_equal(a.deform(X, a.sides(X), 0.7), b.deform(X, b.sides(X), 0.7))

    def test_cut_continuous_ahead_of_front_and_open_behind(self):
        for name in fields.CUT_SCENARIOS:
            for seed in SEEDS:
                ph = fields.draw_phantom(name, seed)
                cut = ph.cut
                P = np.c_[cut.points, np.full(len(cut.points), ph.band.T / 2)]
                ones = np.ones(len(P))
                opened_late = 0.0
                for t in np.linspace(0.0, 1.0, 11):
                    f = cut.front(t)
                    jump = np.linalg.norm(ph.deform(P, ones, t) - ph.deform(P, -ones, t), axis=1)
                    ahead = cut.arclength > f + 1e-9
                    if ahead.any():
                        self.assertLess(jump[ahead].max(), 1e-9, f"{name} {seed} t={t}")
                    if t >= 0.9:
                        opened_late = max(opened_late, jump.max())
                # The cut is open at the end: a few mm at least where it is widest.
                self.assertGreater(opened_late, 5.0, f"{name} seed {seed}")

    def test_continuous_off_the_cut(self):
        """Pairs of points 0.01 mm apart that do not straddle the opened cut move together: the
        side label jumps across the cut's extension too, where the turn must vanish."""
        rng = np.random.default_rng(0)
        for name in fields.SCENARIOS:
            for seed in SEEDS[:2]:
                ph = fields.draw_phantom(name, seed)
                b = ph.band
                X = np.c_[rng.uniform(-b.W / 2, b.W / 2, 4000), rng.uniform(0, b.H, 4000),
                          np.full(4000, b.T / 2)]
                d = rng.normal(size=(4000, 2))
                d = 0.01 * d / np.linalg.norm(d, axis=1)[:, None]
                Y = X.copy()
                Y[:, :2] += d
                for t in (0.5, 1.0):
                    keep = np.ones(len(X), dtype=bool)
                    if ph.cut is not None:
                        f = ph.cut.front(t)
                        for k in range(len(X)):
                            s = ph.cut.crossing_arclength(X[k, :2], Y[k, :2])
                            if s is not None and s < f:
                                keep[k] = False
                    dx = ph.deform(X, ph.sides(X), t) - ph.deform(Y, ph.sides(Y), t)
                    step = np.linalg.norm(dx, axis=1)[keep]
                    # Strains stay below 300 %: 0.01 mm becomes at most 0.04 mm.
                    self.assertLess(step.max(), 0.04, f"{name} seed {seed} t={t}")

    def test_stretch_reaches_its_ratio_with_a_waist(self):
        for seed in SEEDS:
            ph = fields.draw_phantom("stretch", seed)
            b = ph.band
            s = ph.params["stretch"]
            self.assertTrue(1.7 <= s <= 1.9)
            top = np.array([[0.0, b.H, 0.0], [b.W / 2, b.H, 0.0]])
            x = ph.deform(top, np.ones(2), 0.6)
            self.assertAlmostEqual(x[0, 1] / b.H, s, places=6)
            # Grips keep the width at the ends; the waist is narrower than both.
            for eta_mid in (0.5,):
                row = np.array([[-b.W / 2, eta_mid * b.H, 0.0], [b.W / 2, eta_mid * b.H, 0.0]])
                xm = ph.deform(row, np.ones(2), 0.6)
                width_mid = xm[1, 0] - xm[0, 0]
                self.assertLess(width_mid, 0.85 * b.W)
            bottom = np.array([[-b.W / 2, 0.0, 0.0], [b.W / 2, 0.0, 0.0]])
            np.testing.assert_allclose(ph.deform(bottom, np.ones(2), 0.6), bottom, atol=1e-9)

    def test_no_fold_over(self):
        """The front face stays one-to-one: no triangle of the render surface flips in the
        band's plane at any time (the maps are diffeomorphisms away from the cut)."""
        for name in fields.SCENARIOS:
            ph = fields.draw_phantom(name, 1)
            surf = meshes.BandSurface(ph, 3.0)
            front = surf.tris2
            for t in (0.25, 0.5, 0.75, 1.0):
                x = surf.deformed(ph, t)[: len(surf.points2)]
                a, b, c = x[front[:, 0], :2], x[front[:, 1], :2], x[front[:, 2], :2]
                area = ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) -
                        (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))
                self.assertGreater(area.min(), 0.0, f"{name} t={t}")


def _closed_volume(verts, faces):
    a, b, c = verts[faces[:, 0]], verts[faces[:, 1]], verts[faces[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


class MeshTest(unittest.TestCase):
    def test_band_surface_closed_with_cut_walls(self):
        for name, seed in [("stretch", 1)] + [(n, s) for n in fields.CUT_SCENARIOS
                                              for s in (1, 2, 3)]:
            ph = fields.draw_phantom(name, seed)
            s = meshes.BandSurface(ph, 2.0)
            f = s.faces
            e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
            # Closed and consistently oriented: every directed edge once, its reverse once.
            directed = {tuple(x) for x in e}
            self.assertEqual(len(directed), len(e), name)
            self.assertTrue(all((b, a) in directed for a, b in directed), name)
            b = ph.band
            self.assertAlmostEqual(_closed_volume(s.vertices_rest, f), b.W * b.H * b.T,
                                   delta=1e-6 * b.W * b.H * b.T)
            if ph.cut is not None:
                # One copy per path vertex but the tip, on each face; copies coincide at rest.
                self.assertEqual(len(s.front_twins), len(fields._resample(ph.cut.points, 2.0)) - 1)
                self.assertGreater((s.face_kind == 2).sum(), 0)
                tw = s.twins
                np.testing.assert_array_equal(s.vertices_rest[tw[:, 0]],
                                              s.vertices_rest[tw[:, 1]])
                self.assertTrue((s.sides[tw[:, 0]] == 1).all())
                self.assertTrue((s.sides[tw[:, 1]] == -1).all())
                # At rest the cut walls coincide and are left out of the true surface.
                self.assertEqual(len(s.surface_faces(s.vertices_rest)),
                                 (s.face_kind != 2).sum())

    def test_model_is_a_valid_uncut_band(self):
        for seed in SEEDS:
            ph = fields.draw_phantom("precut", seed)
            b = ph.band
            v, t = meshes.model_tets(b, 9.0)
            a, bb, c, d = (v[t[:, q]] for q in range(4))
            vol = np.einsum("ij,ij->i", np.cross(bb - a, c - a), d - a) / 6.0
            self.assertGreater(vol.min(), 1e-3)
            self.assertAlmostEqual(vol.sum(), b.W * b.H * b.T, delta=1e-6 * b.W * b.H * b.T)
            # Conforming: every interior face is shared by exactly two tetrahedra, and the
            # faces used once (the boundary) enclose the whole band.
            faces = np.concatenate([t[:, [1, 2, 3]], t[:, [0, 3, 2]], t[:, [0, 1, 3]],
                                    t[:, [0, 2, 1]]])
            _, counts = np.unique(np.sort(faces, axis=1), axis=0, return_counts=True)
            self.assertLessEqual(counts.max(), 2)
            bfaces = faces[np.isin(np.arange(len(faces)),
                                   _once(faces))]
            self.assertAlmostEqual(_closed_volume(v, bfaces), b.W * b.H * b.T,
                                   delta=1e-6 * b.W * b.H * b.T)
            # The model spans exactly the rendered band.
            np.testing.assert_allclose(v.min(axis=0), [-b.W / 2, 0, -b.T / 2], atol=1e-9)
            np.testing.assert_allclose(v.max(axis=0), [b.W / 2, b.H, b.T / 2], atol=1e-9)

    def test_internal_structure_inside_the_band(self):
        for seed in SEEDS:
            for name in ("stretch", "cut-v"):
                ph = fields.draw_phantom(name, seed)
                v, f = meshes.internal_mesh(ph)
                b = ph.band
                self.assertTrue((np.abs(v[:, 0]) < b.W / 2).all())
                self.assertTrue(((v[:, 1] > 0) & (v[:, 1] < b.H)).all())
                self.assertTrue((np.abs(v[:, 2]) < b.T / 2).all())
                self.assertGreater(_closed_volume(v, f), 0.0)

    def test_internal_structure_torn_only_across_the_opened_cut(self):
        """A vessel crossing the cut loses triangles across the opened part (they would span
        the gap) and keeps none stretched beyond the tissue's own strain."""
        crossed = 0
        for seed in range(1, 30):
            ph = fields.draw_phantom("cut-v", seed)
            if ph.internal["kind"] != "vessel":
                continue
            v, f = meshes.internal_mesh(ph)
            side = ph.sides(v)
            x = ph.deform(v, side, 1.0)
            kept = meshes.internal_faces_at(ph, v, f, 1.0)
            self.assertEqual(len(meshes.internal_faces_at(ph, v, f, 0.0)), len(f))
            if len(kept) == len(f):
                continue
            crossed += 1
            e = np.concatenate([kept[:, [0, 1]], kept[:, [1, 2]], kept[:, [2, 0]]])
            ratio = (np.linalg.norm(x[e[:, 0]] - x[e[:, 1]], axis=1) /
                     np.linalg.norm(v[e[:, 0]] - v[e[:, 1]], axis=1))
            self.assertLess(ratio.max(), 3.0, f"seed {seed}")
            # What is dropped straddles the cut: its corners lie on both sides.
            dropped = [k for k in range(len(f)) if not (kept == f[k]).all(axis=1).any()]
            self.assertTrue(all(len(set(side[f[k]])) == 2 for k in dropped), f"seed {seed}")
            if crossed >= 3:
                break
        self.assertGreater(crossed, 0)

    def test_mask_rasteriser_against_analytic_square(self):
        # A square 20 px wide centred on the image, seen fronto-parallel at 100 mm.
        K = (100.0, 100.0, 31.5, 31.5)
        R, tv = np.eye(3), np.array([0.0, 0.0, 100.0])
        s = 10.0  # mm -> 10 px half width at fx / z = 1 px per mm
        verts = np.array([[-s, -s, 0], [s, -s, 0], [s, s, 0], [-s, s, 0]], dtype=float)
        faces = np.array([[0, 1, 2], [0, 2, 3]])
        m = meshes.rasterize_mask(K, R, tv, verts, faces, 64, 64)
        # Pixel centres u in [21.5, 41.5] -> 22..41 inclusive: 20 x 20 pixels.
        self.assertEqual(int((m > 0).sum()), 400)
        self.assertTrue((m[22:42, 22:42] == 255).all())


def _once(faces):
    key = np.sort(faces, axis=1)
    _, inv, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    return np.nonzero(counts[inv] == 1)[0]


def _load_json(path):
    with open(path) as fh:
        return json.load(fh)


def _scene_camera(scene_dir):
    """(fx, fy, cx, cy), camera_from_world rotation and translation of a scene's camera."""
    cam = _load_json(os.path.join(scene_dir, "scene.json"))["camera"]
    K = (cam["fx"], cam["fy"], cam["cx"], cam["cy"])
    pose = cam["camera_from_world"]
    return K, np.array(pose["rotation"]), np.array(pose["translation_mm"])


def _read_obj(path):
    v, f = [], []
    with open(path) as fh:
        for line in fh:
            if line.startswith("v "):
                v.append([float(x) for x in line.split()[1:4]])
            elif line.startswith("f "):
                f.append([int(x.split("/")[0]) - 1 for x in line.split()[1:4]])
    return np.array(v), np.array(f, dtype=np.int64)


class RenderTest(unittest.TestCase):
    """One tiny scene of each kind, rendered once for all the checks below."""

    @classmethod
    def setUpClass(cls):
        cls.tmp = tempfile.mkdtemp(prefix="phantoms-test-")
        cls.scenes = {}
        for name, seed in (("cut-v", 1), ("instrument", 1)):
            out = os.path.join(cls.tmp, name)
            r = subprocess.run(
                [os.path.join(TOOL, "make-scene"), "--scenario", name, "--seed", str(seed),
                 "--out", out, "--frames", "3", "--size", "96x80", "--samples", "4",
                 "--gt-every", "2", "--quiet"], capture_output=True, text=True)
            if r.returncode != 0:
                raise RuntimeError(f"make-scene {name} failed: {r.stderr.strip()}")
            cls.scenes[name] = out

    @classmethod
    def tearDownClass(cls):
        shutil.rmtree(cls.tmp, ignore_errors=True)

    def test_layout(self):
        for name, d in self.scenes.items():
            for rel in ("video.mp4", "scene.json", "model.vtk", "internal.obj", "gt/meta.json",
                        "gt/cut.json", "gt/surface/000000.obj", "gt/surface/000002.obj",
                        "gt/internal/000000.obj", "gt/internal/000002.obj"):
                self.assertTrue(os.path.isfile(os.path.join(d, rel)), f"{name}: {rel}")
            self.assertEqual(sorted(os.listdir(os.path.join(d, "gt", "masks"))),
                             ["000000.png", "000001.png", "000002.png"])
            self.assertFalse(os.path.exists(d + ".tmp"))
            self.assertFalse(os.path.exists(os.path.join(d, "render")))
            scene = _load_json(os.path.join(d, "scene.json"))
            self.assertEqual(set(scene), {"units", "description", "model",
                                          "internal_structures", "camera", "video",
                                          "ground_truth", "material"})
            cam = scene["camera"]
            self.assertEqual((cam["width"], cam["height"]), (96, 80))
            R = np.array(cam["camera_from_world"]["rotation"])
            np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-9)
            self.assertAlmostEqual(np.linalg.det(R), 1.0, places=9)
            meta = _load_json(os.path.join(d, "gt", "meta.json"))
            self.assertEqual((meta["frames"], meta["width"], meta["height"]), (3, 96, 80))
            self.assertEqual(meta["surface_every_k"], 2)
            cut = _load_json(os.path.join(d, "gt", "cut.json"))["cut"]
            if name == "cut-v":
                self.assertEqual(len(cut["opening_mm"]), 3)
                self.assertEqual(cut["opening_mm"][0], 0.0)
                self.assertGreater(cut["opening_mm"][2], 5.0)
                self.assertFalse(cut["precut"])
                v, f = _read_obj(os.path.join(d, "gt", "cut_surface.obj"))
                self.assertGreater(len(f), 10)
            else:
                self.assertIsNone(cut)

    def test_frame_zero_is_the_rest_pose(self):
        """The model's frame-0 pose is the world frame: the GT surface at frame 0 spans the
        same box as model.vtk."""
        for name, d in self.scenes.items():
            v, _ = _read_obj(os.path.join(d, "gt", "surface", "000000.obj"))
            with open(os.path.join(d, "model.vtk")) as fh:
                lines = fh.read().split("\n")
            n = int(lines[4].split()[1])
            mv = np.array([[float(x) for x in ln.split()] for ln in lines[5 : 5 + n]])
            np.testing.assert_allclose(v.min(axis=0), mv.min(axis=0), atol=1e-4)
            np.testing.assert_allclose(v.max(axis=0), mv.max(axis=0), atol=1e-4)

    def test_masks_match_cycles_rendering_of_gt_surface(self):
        """Cycles renders the GT surface (white emission, black world, one sample at each
        pixel's centre) with the scene camera; its silhouette equals the mask but for pixels
        whose centre lies within a fraction of a pixel of the outline."""
        import bpy

        import scene_bpy

        for name, d in self.scenes.items():
            K, R, tv = _scene_camera(d)
            for frame in (0, 2):
                v, f = _read_obj(os.path.join(d, "gt", "surface", f"{frame:06d}.obj"))
                scene = scene_bpy.reset_scene()
                scene_bpy.configure_render(scene, 96, 80, 1, 0)
                scene.cycles.use_adaptive_sampling = False
                scene.cycles.filter_width = 0.01
                scene.view_settings.view_transform = "Standard"
                scene.view_settings.look = "None"
                scene.world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0
                mat = bpy.data.materials.new("white")
                mat.use_nodes = True
                nodes = mat.node_tree.nodes
                nodes.remove(nodes["Principled BSDF"])
                em = nodes.new("ShaderNodeEmission")
                mat.node_tree.links.new(em.outputs[0], nodes["Material Output"].inputs[0])
                scene_bpy.mesh_object("gt", v, f, [mat])
                scene_bpy.camera_and_light(K, R, tv, 96, 0.0, 60.0)
                png = os.path.join(self.tmp, "check.png")
                scene_bpy.render_frame(scene, png)
                cycles = scene_bpy.read_png_rgb(png)[:, :, 0] > 127
                mask = meshes.read_png_gray(
                    os.path.join(d, "gt", "masks", f"{frame:06d}.png")) > 0
                differ = cycles != mask
                self.assertGreater(mask.sum(), 300, f"{name} frame {frame}")
                self.assertLess(differ.sum(), 0.02 * mask.sum(), f"{name} frame {frame}")
                # Every differing pixel touches the outline of the mask.
                grown = mask.copy()
                shrunk = mask.copy()
                for ax in (0, 1):
                    for sh in (1, -1):
                        grown |= np.roll(mask, sh, axis=ax)
                        shrunk &= np.roll(mask, sh, axis=ax)
                self.assertFalse((differ & ~(grown & ~shrunk)).any(), f"{name} frame {frame}")

    def test_mask_area_against_projected_surface(self):
        """Mask area against the projected GT surface: a line of sight meets the band's
        surface once on its way in, so the silhouette's area is the sum of the projected areas
        of the triangles that face the camera (to within the pixels on the outline)."""
        for name, d in self.scenes.items():
            K, R, tv = _scene_camera(d)
            for frame in (0, 2):
                v, f = _read_obj(os.path.join(d, "gt", "surface", f"{frame:06d}.obj"))
                uv, _ = meshes.project(K, R, tv, v)
                a, b, c = uv[f[:, 0]], uv[f[:, 1]], uv[f[:, 2]]
                area = 0.5 * ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) -
                              (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))
                # Outward faces turn clockwise in the image (its y axis points down).
                facing = -area[area < 0].sum()
                m = meshes.read_png_gray(os.path.join(d, "gt", "masks", f"{frame:06d}.png")) > 0
                inner = m.copy()
                for ax in (0, 1):
                    for sh in (1, -1):
                        inner &= np.roll(m, sh, axis=ax)
                outline = int((m & ~inner).sum())
                self.assertLess(abs(m.sum() - facing), 0.6 * outline + 0.01 * facing,
                                f"{name} frame {frame}: mask {m.sum()} px, projected "
                                f"{facing:.1f} px, outline {outline} px")

    def test_arreg_reads_the_scene(self):
        if ARREG is None:
            self.skipTest("no --arreg binary given")
        d = self.scenes["cut-v"]
        run = os.path.join(self.tmp, "run")
        rep = os.path.join(self.tmp, "report")
        r = subprocess.run([ARREG, "run", "--scene", os.path.join(d, "scene.json"), "--out", run],
                           capture_output=True, text=True)
        self.assertEqual(r.returncode, 0, r.stderr[-2000:])
        r = subprocess.run([ARREG, "eval", "--run", run, "--gt", os.path.join(d, "gt"), "--out",
                            rep], capture_output=True, text=True)
        self.assertEqual(r.returncode, 0, r.stderr[-2000:])
        self.assertTrue(os.listdir(rep))


class CliTest(unittest.TestCase):
    def run_tool(self, *args):
        return subprocess.run([os.path.join(TOOL, "make-scene"), *args], capture_output=True,
                              text=True)

    def test_bad_usage_is_one_line_exit_2(self):
        for args in (["--scenario", "nope", "--out", "/tmp/x"], ["--scenario", "stretch"],
                     ["--scenario", "stretch", "--out", "/tmp/x", "--size", "97x80"],
                     ["--scenario", "stretch", "--out", "/tmp/x", "--frames", "1"]):
            r = self.run_tool(*args)
            self.assertEqual(r.returncode, 2, args)
            lines = r.stderr.strip().splitlines()
            self.assertEqual(len(lines), 1, r.stderr)
            self.assertTrue(lines[0].startswith("make-scene: error: "), lines[0])

    def test_non_empty_out_is_refused_without_partial_output(self):
        with tempfile.TemporaryDirectory() as tmp:
            out = os.path.join(tmp, "scene")
            os.makedirs(out)
            open(os.path.join(out, "keep.txt"), "w").close()
            r = self.run_tool("--scenario", "stretch", "--out", out, "--frames", "2")
            self.assertEqual(r.returncode, 1)
            self.assertIn("not empty", r.stderr)
            self.assertEqual(os.listdir(out), ["keep.txt"])
            self.assertFalse(os.path.exists(out + ".tmp"))

    def test_list_and_help(self):
        r = self.run_tool("--list")
        self.assertEqual(r.returncode, 0)
        names = [ln.split()[0] for ln in r.stdout.strip().splitlines()]
        self.assertEqual(names, list(fields.SCENARIOS))
        r = self.run_tool("--help")
        self.assertEqual(r.returncode, 0)
        self.assertIn("--scenario", r.stdout)


if __name__ == "__main__":
    argv = sys.argv[sys.argv.index("--") + 1 :] if "--" in sys.argv else []
    if "--arreg" in argv:
        k = argv.index("--arreg")
        ARREG = argv[k + 1]
        del argv[k : k + 2]
    result = unittest.main(argv=["test_phantoms"] + argv, exit=False, verbosity=2)
    sys.exit(0 if result.result.wasSuccessful() else 1)
