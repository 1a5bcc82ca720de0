"""Phantom scene generator: a tissue band deformed by analytic fields, rendered by Blender's
Cycles, written with ground truth in the layout of `arreg synth` (tools/phantoms/README.md).

Run by Blender:  blender -b --factory-startup -noaudio -P tools/phantoms/phantom.py -- ARGS
(tools/phantoms/make-scene does this).
"""

import argparse
import math
import os
import shutil
import subprocess
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import numpy as np  # noqa: E402

import fields  # noqa: E402
import meshes  # noqa: E402

VERSION = 1
PROG = "make-scene"


class UsageError(Exception):
    pass


_progress_line_open = False  # a "\r" progress line waits for its newline


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        raise UsageError(message)


def parse_args(argv):
    p = _Parser(prog=PROG, add_help=False)
    p.add_argument("--scenario")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--out")
    p.add_argument("--frames", type=int, default=80)
    p.add_argument("--size", default="640x512")
    p.add_argument("--samples", type=int, default=8)
    p.add_argument("--fps", type=float, default=24.0)
    p.add_argument("--gt-every", type=int, default=5)
    p.add_argument("--mesh-mm", type=float, default=1.5)
    p.add_argument("--model-mm", type=float, default=9.0)
    p.add_argument("--keep-frames", action="store_true")
    p.add_argument("--force", action="store_true")
    p.add_argument("--list", action="store_true")
    p.add_argument("--quiet", action="store_true")
    a = p.parse_args(argv)
    if a.list:
        return a
    if not a.scenario:
        raise UsageError("--scenario is required (--list shows the scenarios)")
    if a.scenario not in fields.SCENARIOS:
        raise UsageError(f"--scenario: unknown '{a.scenario}' (expected one of: "
                         f"{', '.join(fields.SCENARIOS)})")
    if not a.out:
        raise UsageError("--out is required")
    if a.seed < 0:
        raise UsageError(f"--seed: must be >= 0, got {a.seed}")
    if a.frames < 2:
        raise UsageError(f"--frames: must be >= 2, got {a.frames}")
    try:
        w, h = (int(v) for v in a.size.lower().split("x"))
    except ValueError:
        raise UsageError(f"--size: expected WxH, got '{a.size}'")
    if w < 16 or h < 16 or w % 2 or h % 2:
        raise UsageError(f"--size: width and height must be even and >= 16, got '{a.size}'")
    a.width, a.height = w, h
    if a.samples < 1:
        raise UsageError(f"--samples: must be >= 1, got {a.samples}")
    if not a.fps > 0:
        raise UsageError(f"--fps: must be > 0, got {a.fps}")
    if a.gt_every < 1:
        raise UsageError(f"--gt-every: must be >= 1, got {a.gt_every}")
    if not 0.3 <= a.mesh_mm <= 5.0:
        raise UsageError(f"--mesh-mm: must be in [0.3, 5], got {a.mesh_mm}")
    if not 3.0 <= a.model_mm <= 30.0:
        raise UsageError(f"--model-mm: must be in [3, 30], got {a.model_mm}")
    return a


# ---------------------------------------------------------------------------------------------
# Camera: oblique view, distance fitted to the tissue's extent over the whole sequence.


def look_at(center, tilt_deg, azimuth_deg, roll_deg, distance):
    """camera_from_world (R, t) of a camera `distance` mm from `center`, its axis `tilt_deg`
    off the band's normal (+z) towards azimuth `azimuth_deg`, the band's +y up in the image
    turned by `roll_deg`."""
    tl, az = math.radians(tilt_deg), math.radians(azimuth_deg)
    offset = np.array([math.sin(tl) * math.cos(az), math.sin(tl) * math.sin(az), math.cos(tl)])
    C = center + distance * offset
    fwd = -offset
    up = np.array([0.0, 1.0, 0.0])
    right = np.cross(fwd, up)
    if np.linalg.norm(right) < 1e-6:
        right = np.array([1.0, 0.0, 0.0])
    right /= np.linalg.norm(right)
    down = np.cross(fwd, right)
    r = math.radians(roll_deg)
    x = math.cos(r) * right + math.sin(r) * down
    y = -math.sin(r) * right + math.cos(r) * down
    R = np.stack([x, y, fwd])
    return R, -R @ C


def fit_camera(points, rng, width, height):
    """Draws the view (field of view 62-78 deg, tilt 20-40 deg, any azimuth, roll +-15 deg)
    and the distance: the smallest at which every point lies 4 % inside the image, times
    1.0-1.15."""
    hfov = rng.uniform(62.0, 78.0)
    fx = (width / 2) / math.tan(math.radians(hfov) / 2)
    K = (fx, fx, width / 2 - 0.5, height / 2 - 0.5)
    tilt, az, roll = rng.uniform(20.0, 40.0), rng.uniform(0.0, 360.0), rng.uniform(-15.0, 15.0)
    lo, hi = points.min(axis=0), points.max(axis=0)
    center = 0.5 * (lo + hi)

    def fits(d):
        R, t = look_at(center, tilt, az, roll, d)
        uv, z = meshes.project(K, R, t, points)
        mx, my = 0.04 * width, 0.04 * height
        return ((z > 1.0).all() and (uv[:, 0] >= mx).all() and (uv[:, 0] <= width - mx).all()
                and (uv[:, 1] >= my).all() and (uv[:, 1] <= height - my).all())

    a, b = 10.0, 5000.0
    for _ in range(60):
        m = 0.5 * (a + b)
        a, b = (a, m) if fits(m) else (m, b)
    distance = b * rng.uniform(1.0, 1.15)
    R, t = look_at(center, tilt, az, roll, distance)
    view = {"hfov_deg": hfov, "tilt_deg": tilt, "azimuth_deg": az, "roll_deg": roll,
            "distance_mm": distance}
    return K, R, t, view


# ---------------------------------------------------------------------------------------------


def log(args, msg):
    if not args.quiet:
        print(f"{PROG}: {msg}", file=sys.stderr, flush=True)


def generate(args):
    start = time.time()
    out = os.path.abspath(args.out)
    parent = os.path.dirname(out)
    if not os.path.isdir(parent):
        raise RuntimeError(f"--out: parent folder {parent} does not exist")
    if os.path.exists(out) and not os.path.isdir(out):
        raise RuntimeError(f"--out: {out} exists and is not a folder")
    if os.path.isdir(out) and os.listdir(out) and not args.force:
        raise RuntimeError(f"--out: {out} exists and is not empty (remove it or pass --force)")
    if shutil.which("ffmpeg") is None:
        raise RuntimeError("ffmpeg: not found on PATH (Debian package ffmpeg)")
    tmp = out + ".tmp"
    shutil.rmtree(tmp, ignore_errors=True)
    os.makedirs(tmp)
    try:
        summary = _generate_into(args, tmp, start)
        if os.path.isdir(out):
            shutil.rmtree(out)
        os.rename(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    log(args, f"{out}: {args.frames} frames in {time.time() - start:.1f} s "
        f"({summary})")


def _generate_into(args, tmp, start):
    global _progress_line_open
    import scene_bpy

    W, H, n = args.width, args.height, args.frames
    ph = fields.draw_phantom(args.scenario, args.seed)
    # Every random stream depends on the scenario too: one seed gives unrelated scenes.
    key = args.seed * len(fields.SCENARIOS) + list(fields.SCENARIOS).index(args.scenario)
    rng = np.random.default_rng([key, 101])
    surface = meshes.BandSurface(ph, args.mesh_mm)
    model_v, model_t = meshes.model_tets(ph.band, args.model_mm)
    inner_v, inner_f = meshes.internal_mesh(ph)
    inner_side = ph.sides(inner_v)
    times = [f / (n - 1) for f in range(n)]

    # Camera from the tissue's extent over the sequence.
    sample = surface.vertices_rest[:: max(1, len(surface.vertices_rest) // 3000)]
    sample_side = surface.sides[:: max(1, len(surface.vertices_rest) // 3000)]
    extent = np.concatenate([ph.deform(sample, sample_side, t)
                             for t in np.linspace(0.0, 1.0, 21)])
    K, R, tvec, view = fit_camera(extent, rng, W, H)
    C = -R.T @ tvec
    if ph.instrument is not None:
        # The shaft leaves the view away from the lens, not towards it.
        tip, axis = fields.instrument_pose(ph, 0.5)
        to_cam = (C - tip) / np.linalg.norm(C - tip)
        if np.dot(axis, to_cam) > math.cos(math.radians(40.0)):
            ph.instrument["azimuth_deg"] = (ph.instrument["azimuth_deg"] + 180.0) % 360.0
    noise_gain = rng.uniform(0.3, 0.9)  # shot noise variance per grey level
    noise_read = rng.uniform(1.0, 2.5)  # read noise (8-bit grey levels)
    crf = int(rng.integers(18, 26))
    light_scale = rng.uniform(0.9, 1.3)
    bg_depth = ph.band.T / 2 + rng.uniform(15.0, 30.0)

    # Blender scene.
    scene = scene_bpy.reset_scene()
    scene_bpy.configure_render(scene, W, H, args.samples, key)
    mats = [scene_bpy.tissue_material("tissue", key),
            scene_bpy.tissue_material("tissue-inner", key, inner=True)]
    band_obj = scene_bpy.mesh_object("band", surface.vertices_rest, surface.faces, mats,
                                     face_material=(surface.face_kind > 0).astype(np.int32),
                                     rest=surface.vertices_rest)
    bg = scene_bpy.background_sheet(ph.band, key, bg_depth)
    inst = None
    if ph.instrument is not None:
        inst = scene_bpy.instrument(scene_bpy.metal_material())
    dist = view["distance_mm"]
    scene_bpy.camera_and_light(K, R, tvec, W, 4.0 * math.pi * dist**2 * light_scale,
                               rng.uniform(70.0, 90.0))

    render_dir = os.path.join(tmp, "render")
    gt = os.path.join(tmp, "gt")
    for d in (render_dir, gt + "/masks", gt + "/surface", gt + "/internal"):
        os.makedirs(d)
    if args.keep_frames:
        os.makedirs(os.path.join(tmp, "frames"))
    video = os.path.join(tmp, "video.mp4")
    enc = subprocess.Popen(
        ["ffmpeg", "-hide_banner", "-loglevel", "error", "-y", "-f", "rawvideo", "-pix_fmt",
         "rgb24", "-s", f"{W}x{H}", "-r", f"{args.fps:g}", "-i", "-", "-c:v", "libx264",
         "-preset", "medium", "-crf", str(crf), "-pix_fmt", "yuv420p", video],
        stdin=subprocess.PIPE)
    opening, fronts, mask_area = [], [], []
    render_s = 0.0
    try:
        for frame, t in enumerate(times):
            x = surface.deformed(ph, t)
            scene_bpy.set_vertices(band_obj, x)
            bg.location = (0.0, 0.0, 1.5 * math.sin(2 * math.pi * frame / args.fps / 4.0))
            if inst is not None:
                tip, axis = fields.instrument_pose(ph, t)
                jaw = 0.0
                if ph.instrument["kind"] == "scissors":
                    phase = 2 * math.pi * frame / args.fps / ph.instrument["jaw_period_s"]
                    jaw = 12.0 + 12.0 * math.sin(phase)
                else:
                    jaw = 10.0
                scene_bpy.pose_instrument(inst[0], inst[1], tip, axis, jaw)
            scene.frame_set(frame)
            # A new path-tracing noise pattern every frame (no fixed pattern to track).
            scene.cycles.seed = (key * 7919 + frame) % 2**31
            png = os.path.join(render_dir, meshes.frame_name(frame, "png"))
            t0 = time.time()
            scene_bpy.render_frame(scene, png)
            render_s += time.time() - t0
            img = scene_bpy.read_png_rgb(png)
            os.remove(png)
            # Sensor noise: shot noise growing with the signal plus read noise.
            nrng = np.random.default_rng([key, 202, frame])
            sigma = np.sqrt(noise_gain * img + noise_read**2)
            img = np.clip(np.rint(img + sigma * nrng.standard_normal(img.shape)), 0, 255)
            img = img.astype(np.uint8)
            enc.stdin.write(img.tobytes())
            if args.keep_frames:
                meshes.write_png(os.path.join(tmp, "frames", meshes.frame_name(frame, "png")),
                               img)
            faces = surface.surface_faces(x)
            mask = meshes.rasterize_mask(K, R, tvec, x, faces, W, H)
            meshes.write_png(os.path.join(gt, "masks", meshes.frame_name(frame, "png")),
                                  mask)
            mask_area.append(int((mask > 0).sum()))
            if frame % args.gt_every == 0 or frame == n - 1:
                meshes.write_obj(os.path.join(gt, "surface", meshes.frame_name(frame, "obj")),
                                 x, faces)
                xi = ph.deform(inner_v, inner_side, t)
                meshes.write_obj(os.path.join(gt, "internal", meshes.frame_name(frame, "obj")),
                                 xi, meshes.internal_faces_at(ph, inner_v, inner_f, t))
            if ph.cut is not None:
                opening.append(surface.opening_mm(x))
                fronts.append(ph.cut.front(t))
            if not args.quiet:
                el = time.time() - start
                print(f"\r{PROG}: frame {frame + 1}/{n}  {el:.0f} s", end="", file=sys.stderr,
                      flush=True)
                _progress_line_open = True
        if _progress_line_open:
            print("", file=sys.stderr)
            _progress_line_open = False
    finally:
        enc.stdin.close()
        rc = enc.wait()
    if rc != 0:
        raise RuntimeError(f"ffmpeg: encoding {video} failed (exit {rc})")
    shutil.rmtree(render_dir)

    # Cut ground truth.
    cut_json = {"cut": None}
    if ph.cut is not None:
        cut = ph.cut
        path = cut.points
        T = ph.band.T
        cv = np.concatenate([np.c_[path, np.full(len(path), T / 2)],
                             np.c_[path, np.full(len(path), -T / 2)]])
        m = len(path)
        cf = []
        for i in range(m - 1):
            cf += [(i, i + 1, i + m), (i + 1, i + 1 + m, i + m)]
        meshes.write_obj(os.path.join(gt, "cut_surface.obj"), cv, np.array(cf),
                         header="cut surface, rest frame = world frame at frame 0 (mm)")
        opened = [f for f in range(n) if fronts[f] > 1e-9]
        done = [f for f in range(n) if fronts[f] >= cut.length_mm - 1e-9]
        first = opened[0] if opened else -1
        last = done[0] if done else (n - 1)
        cut_json = {"cut": {
            "surface": "cut_surface.obj",
            "open_frames": [first, last],
            "description": cut.description,
            "precut": bool(cut.precut),
            "length_mm": cut.length_mm,
            "coordinates": "rest pose = world frame at frame 0 (model frame of scene.json)",
            "opening_mm": [round(v, 4) for v in opening],
            "front_mm": [round(v, 4) for v in fronts],
            "path_rest_mm": [[round(p[0], 4), round(p[1], 4)] for p in path],
        }}
    meshes.write_json(os.path.join(gt, "cut.json"), cut_json)

    meshes.write_vtk_tets(os.path.join(tmp, "model.vtk"), model_v, model_t,
                          f"phantom {args.scenario} seed {args.seed}: coarse model, rest pose")
    meshes.write_obj(os.path.join(tmp, "internal.obj"), inner_v, inner_f,
                     header=f"internal structure ({ph.internal['kind']}), rest pose (mm)")
    params = {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in ph.params.items()}
    meshes.write_json(os.path.join(gt, "meta.json"), {
        "units": "mm",
        "frames": n,
        "surface_every_k": args.gt_every,
        "width": W,
        "height": H,
        "fps": args.fps,
        "seed": args.seed,
        "scenario": args.scenario,
        "description": fields.SCENARIOS[args.scenario],
        "version": VERSION,
        "generator": {
            "source": "phantom",
            "renderer": f"Blender {_blender_version()} Cycles (CPU), {args.samples} samples, "
                        "no denoiser",
            "samples": args.samples,
            "mesh_mm": args.mesh_mm,
            "model_mm": args.model_mm,
            "noise_gain": noise_gain,
            "noise_read_sigma": noise_read,
            "crf": crf,
            "view": view,
        },
        "truth": {
            "deformation": "analytic displacement fields of the rest coordinates and time "
                           "(tools/phantoms/fields.py), no finite elements",
            "params": params,
            "surface_vertices": int(len(surface.vertices_rest)),
            "surface_triangles": int(len(surface.faces)),
            "mask_area_px": mask_area,
        },
        "model": {"tetrahedra": int(len(model_t)), "vertices": int(len(model_v))},
        "mask": "organ silhouette of gt/surface rasterised with the scene camera at pixel "
                "centres; instruments are not part of it",
        "seconds": round(time.time() - start, 1),
        "render_seconds": round(render_s, 1),
    })
    scene_json = {
        "units": "mm",
        "description": f"phantom {args.scenario} seed {args.seed}: "
                       f"{fields.SCENARIOS[args.scenario]}",
        "model": {"mesh": "model.vtk"},
        "internal_structures": [{"name": "internal", "mesh": "internal.obj",
                                 "color": [1.0, 0.85, 0.1]}],
        "camera": {"width": W, "height": H, "fx": K[0], "fy": K[1], "cx": K[2], "cy": K[3],
                   "camera_from_world": {"rotation": R.tolist(),
                                         "translation_mm": tvec.tolist()}},
        "video": "video.mp4",
        "ground_truth": "gt",
        # The registration's material prior: the same as `arreg synth` gives its bands, so
        # that both scene sources are registered with one parameter set.
        "material": {"youngs_modulus_pa": 100000.0, "poisson_ratio": 0.45},
    }
    # Written last: a scene file means the folder is complete.
    meshes.write_json(os.path.join(tmp, "scene.json"), scene_json)
    return f"render {render_s:.1f} s"


def _blender_version():
    try:
        import bpy

        return bpy.app.version_string
    except ImportError:
        return "?"


def main(argv):
    try:
        args = parse_args(argv)
    except UsageError as e:
        print(f"{PROG}: error: {e}", file=sys.stderr)
        return 2
    if args.list:
        for name, desc in fields.SCENARIOS.items():
            print(f"{name:13s} {desc}")
        return 0
    try:
        generate(args)
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=sys.stderr)
        return 130
    except (RuntimeError, OSError, ValueError) as e:
        print(("\n" if _progress_line_open else "") + f"{PROG}: error: {e}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    argv = sys.argv[sys.argv.index("--") + 1 :] if "--" in sys.argv else []
    sys.exit(main(argv))
