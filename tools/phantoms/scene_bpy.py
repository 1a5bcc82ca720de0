"""The Blender side of a phantom scene: objects, procedural materials, laparoscope camera and
light, Cycles settings, and the per-frame update. Units: 1 Blender unit = 1 mm."""

import math

import bpy
import numpy as np


def reset_scene():
    for obj in list(bpy.data.objects):
        bpy.data.objects.remove(obj, do_unlink=True)
    for coll in (bpy.data.meshes, bpy.data.materials, bpy.data.lights, bpy.data.cameras):
        for item in list(coll):
            coll.remove(item)
    return bpy.context.scene


def configure_render(scene, width, height, samples, seed):
    scene.render.engine = "CYCLES"
    c = scene.cycles
    c.device = "CPU"
    c.samples = samples
    c.use_adaptive_sampling = True
    c.adaptive_threshold = 0.03
    # Debian's Blender is built without OpenImageDenoise: no denoiser, the remaining path-tracing
    # noise adds to the sensor noise.
    c.use_denoising = False
    c.max_bounces = 2
    c.diffuse_bounces = 1
    c.glossy_bounces = 1
    c.transmission_bounces = 0
    c.volume_bounces = 0
    c.transparent_max_bounces = 2
    c.caustics_reflective = False
    c.caustics_refractive = False
    c.sample_clamp_indirect = 4.0
    c.seed = seed
    c.use_animated_seed = False
    scene.render.resolution_x = width
    scene.render.resolution_y = height
    scene.render.resolution_percentage = 100
    scene.render.use_persistent_data = True
    scene.render.image_settings.file_format = "PNG"
    scene.render.image_settings.color_mode = "RGB"
    scene.render.image_settings.color_depth = "8"
    scene.view_settings.view_transform = "Filmic"
    scene.view_settings.look = "Medium High Contrast"
    scene.view_settings.exposure = 0.0
    world = bpy.data.worlds.new("cavity") if scene.world is None else scene.world
    scene.world = world
    world.use_nodes = True
    bg = world.node_tree.nodes.get("Background")
    # A dim, warm surround: what the metal reflects where no tissue is.
    bg.inputs["Color"].default_value = (0.35, 0.22, 0.2, 1.0)
    bg.inputs["Strength"].default_value = 0.15


# ---------------------------------------------------------------------------------------------
# Materials: everything procedural from Blender's own nodes.


def _nodes(mat):
    mat.use_nodes = True
    nt = mat.node_tree
    for n in list(nt.nodes):
        nt.nodes.remove(n)
    return nt, nt.nodes, nt.links


def _ramp(nodes, stops):
    r = nodes.new("ShaderNodeValToRGB")
    els = r.color_ramp.elements
    while len(els) > len(stops):
        els.remove(els[-1])
    while len(els) < len(stops):
        els.new(0.5)
    for el, (pos, col) in zip(els, stops):
        el.position = pos
        el.color = (*col, 1.0)
    return r


def _veins(nodes, links, vec, scale, width, detail=2.0):
    """Thin meandering lines where a noise field crosses its mid level (|noise - 0.5| small):
    a vessel-like network that needs no Voronoi evaluation. Returns a 0 (line) .. 1 factor."""
    noise = nodes.new("ShaderNodeTexNoise")
    noise.inputs["Scale"].default_value = scale
    noise.inputs["Detail"].default_value = detail
    noise.inputs["Distortion"].default_value = 0.6
    links.new(vec, noise.inputs["Vector"])
    sub = nodes.new("ShaderNodeMath")
    sub.operation = "SUBTRACT"
    sub.inputs[1].default_value = 0.5
    links.new(noise.outputs["Fac"], sub.inputs[0])
    ab = nodes.new("ShaderNodeMath")
    ab.operation = "ABSOLUTE"
    links.new(sub.outputs[0], ab.inputs[0])
    ramp = _ramp(nodes, [(0.0, (0, 0, 0)), (width, (1, 1, 1))])
    links.new(ab.outputs[0], ramp.inputs["Fac"])
    return ramp.outputs["Color"]


def _mix(nodes, links, fac, color1, color2, blend="MIX"):
    mix = nodes.new("ShaderNodeMixRGB")
    mix.blend_type = blend
    for sock, val in (("Fac", fac), ("Color1", color1), ("Color2", color2)):
        if isinstance(val, tuple):
            mix.inputs[sock].default_value = val if len(val) == 4 else (*val, 1.0)
        elif isinstance(val, float):
            mix.inputs[sock].default_value = val
        else:
            links.new(val, mix.inputs[sock])
    return mix.outputs["Color"]


def tissue_material(name, seed, inner=False):
    """Tissue shaded from its rest coordinates (attribute `rest`), so the pattern moves with it:
    low-frequency mottling (noise), a network of vessels and finer capillaries (lines where a
    noise field crosses its mid level), small pale speckles (Voronoi sites), over a wet
    Principled BSDF (clearcoat for the specular highlights of the moist surface, a bump from a
    fine noise grain)."""
    mat = bpy.data.materials.new(name)
    nt, nodes, links = _nodes(mat)
    rng = np.random.default_rng([seed, 7 if inner else 3])
    attr = nodes.new("ShaderNodeAttribute")
    attr.attribute_name = "rest"
    mapping = nodes.new("ShaderNodeMapping")
    mapping.inputs["Location"].default_value = tuple(rng.uniform(-500, 500, 3))
    links.new(attr.outputs["Vector"], mapping.inputs["Vector"])
    vec = mapping.outputs["Vector"]

    mottle = nodes.new("ShaderNodeTexNoise")
    mottle.inputs["Scale"].default_value = rng.uniform(0.04, 0.07)
    mottle.inputs["Detail"].default_value = 3.0
    mottle.inputs["Roughness"].default_value = 0.6
    links.new(vec, mottle.inputs["Vector"])
    if inner:
        stops = [(0.3, (0.30, 0.03, 0.03)), (0.7, (0.50, 0.08, 0.06))]
    else:
        stops = [(0.3, (0.50, 0.10, 0.08)), (0.55, (0.68, 0.22, 0.17)),
                 (0.8, (0.78, 0.38, 0.30))]
    base = _ramp(nodes, stops)
    links.new(mottle.outputs["Fac"], base.inputs["Fac"])
    color = base.outputs["Color"]

    spots = nodes.new("ShaderNodeTexVoronoi")
    spots.feature = "F1"
    spots.inputs["Scale"].default_value = rng.uniform(0.18, 0.28)
    links.new(vec, spots.inputs["Vector"])
    speck = _ramp(nodes, [(0.0, (1, 1, 1)), (0.1, (1, 1, 1)), (0.16, (0, 0, 0))])
    links.new(spots.outputs["Distance"], speck.inputs["Fac"])
    sel = nodes.new("ShaderNodeMath")  # only a part of the sites shows a speckle
    sel.operation = "MULTIPLY"
    links.new(speck.outputs["Color"], sel.inputs[0])
    gate = _ramp(nodes, [(0.45, (0, 0, 0)), (0.55, (1, 1, 1))])
    links.new(spots.outputs["Color"], gate.inputs["Fac"])
    links.new(gate.outputs["Color"], sel.inputs[1])
    pale = (0.85, 0.55, 0.45) if not inner else (0.55, 0.18, 0.14)
    color = _mix(nodes, links, sel.outputs[0], color, pale)

    if not inner:
        vessels = _veins(nodes, links, vec, rng.uniform(0.012, 0.02), 0.018)
        color = _mix(nodes, links, vessels, (0.30, 0.02, 0.06), color)
        capill = _veins(nodes, links, vec, rng.uniform(0.06, 0.09), 0.012)
        faint = _mix(nodes, links, 0.55, capill, (1.0, 1.0, 1.0))
        color = _mix(nodes, links, 1.0, color, faint, blend="MULTIPLY")

    bsdf = nodes.new("ShaderNodeBsdfPrincipled")
    links.new(color, bsdf.inputs["Base Color"])
    bsdf.inputs["Specular"].default_value = 0.5
    bsdf.inputs["Roughness"].default_value = 0.45 if not inner else 0.6
    bsdf.inputs["Clearcoat"].default_value = 0.7 if not inner else 0.3
    bsdf.inputs["Clearcoat Roughness"].default_value = 0.08
    grain = nodes.new("ShaderNodeTexNoise")
    grain.inputs["Scale"].default_value = rng.uniform(0.6, 0.9)
    grain.inputs["Detail"].default_value = 1.0
    links.new(vec, grain.inputs["Vector"])
    bump = nodes.new("ShaderNodeBump")
    bump.inputs["Strength"].default_value = 0.3
    bump.inputs["Distance"].default_value = 0.3
    links.new(grain.outputs["Fac"], bump.inputs["Height"])
    links.new(bump.outputs["Normal"], bsdf.inputs["Normal"])
    out = nodes.new("ShaderNodeOutputMaterial")
    links.new(bsdf.outputs["BSDF"], out.inputs["Surface"])
    return mat


def background_material(seed):
    """Other tissue behind the band: yellowish fat lobules (Voronoi cells, each its own shade)
    between patches of darker, vascular tissue."""
    mat = bpy.data.materials.new("background")
    nt, nodes, links = _nodes(mat)
    rng = np.random.default_rng([seed, 11])
    coord = nodes.new("ShaderNodeTexCoord")
    vec = coord.outputs["Object"]
    lob = nodes.new("ShaderNodeTexVoronoi")
    lob.inputs["Scale"].default_value = rng.uniform(0.035, 0.055)
    links.new(vec, lob.inputs["Vector"])
    fat = _ramp(nodes, [(0.0, (0.62, 0.42, 0.16)), (1.0, (0.85, 0.66, 0.32))])
    links.new(lob.outputs["Color"], fat.inputs["Fac"])
    rim = _ramp(nodes, [(0.3, (1, 1, 1)), (0.8, (0.8, 0.65, 0.6))])
    links.new(lob.outputs["Distance"], rim.inputs["Fac"])
    fat_c = _mix(nodes, links, 1.0, fat.outputs["Color"], rim.outputs["Color"], "MULTIPLY")
    noise = nodes.new("ShaderNodeTexNoise")
    noise.inputs["Scale"].default_value = rng.uniform(0.012, 0.02)
    noise.inputs["Detail"].default_value = 3.0
    links.new(vec, noise.inputs["Vector"])
    red = _ramp(nodes, [(0.3, (0.28, 0.05, 0.04)), (0.7, (0.5, 0.12, 0.09))])
    links.new(noise.outputs["Fac"], red.inputs["Fac"])
    sel = _ramp(nodes, [(0.42, (0, 0, 0)), (0.58, (1, 1, 1))])
    links.new(noise.outputs["Fac"], sel.inputs["Fac"])
    color = _mix(nodes, links, sel.outputs["Color"], red.outputs["Color"], fat_c)
    vessels = _veins(nodes, links, vec, rng.uniform(0.008, 0.012), 0.015)
    color = _mix(nodes, links, vessels, (0.25, 0.02, 0.05), color)
    bsdf = nodes.new("ShaderNodeBsdfPrincipled")
    links.new(color, bsdf.inputs["Base Color"])
    bsdf.inputs["Roughness"].default_value = 0.5
    bsdf.inputs["Clearcoat"].default_value = 0.5
    bsdf.inputs["Clearcoat Roughness"].default_value = 0.1
    out = nodes.new("ShaderNodeOutputMaterial")
    links.new(bsdf.outputs["BSDF"], out.inputs["Surface"])
    return mat


def metal_material():
    """Brushed stainless steel of the instrument."""
    mat = bpy.data.materials.new("steel")
    nt, nodes, links = _nodes(mat)
    bsdf = nodes.new("ShaderNodeBsdfPrincipled")
    bsdf.inputs["Base Color"].default_value = (0.72, 0.72, 0.74, 1.0)
    bsdf.inputs["Metallic"].default_value = 0.85
    bsdf.inputs["Roughness"].default_value = 0.3
    out = nodes.new("ShaderNodeOutputMaterial")
    links.new(bsdf.outputs["BSDF"], out.inputs["Surface"])
    return mat


# ---------------------------------------------------------------------------------------------
# Objects.


def mesh_object(name, verts, faces, material_slots=(), face_material=None, smooth=True,
                rest=None):
    me = bpy.data.meshes.new(name)
    me.from_pydata([tuple(v) for v in verts], [], [tuple(int(i) for i in f) for f in faces])
    me.update()
    for m in material_slots:
        me.materials.append(m)
    if face_material is not None:
        me.polygons.foreach_set("material_index", np.asarray(face_material, dtype=np.int32))
    me.polygons.foreach_set("use_smooth", np.full(len(me.polygons), smooth, dtype=bool))
    # Sharp edges between the faces and the walls, smooth across the deformed faces.
    me.use_auto_smooth = True
    me.auto_smooth_angle = math.radians(50.0)
    if rest is not None:
        attr = me.attributes.new("rest", "FLOAT_VECTOR", "POINT")
        attr.data.foreach_set("vector", np.asarray(rest, dtype=np.float32).ravel())
    obj = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def set_vertices(obj, x):
    obj.data.vertices.foreach_set("co", np.asarray(x, dtype=np.float32).ravel())
    obj.data.update()


def background_sheet(band, seed, depth_mm):
    """A large wavy sheet of other tissue behind the band (static but for a slow breathing)."""
    rng = np.random.default_rng([seed, 13])
    n, size = 140, 1600.0
    xs = np.linspace(-size / 2, size / 2, n)
    ys = np.linspace(-size / 2, size / 2, n) + band.H / 2
    X, Y = np.meshgrid(xs, ys)
    Z = np.zeros_like(X)
    for _ in range(6):
        k = rng.uniform(0.01, 0.04)
        a = rng.uniform(0, 2 * math.pi)
        Z += rng.uniform(1.0, 4.0) * np.sin(k * (math.cos(a) * X + math.sin(a) * Y) +
                                            rng.uniform(0, 6.3))
    Z -= depth_mm
    verts = np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1)
    faces = []
    for j in range(n - 1):
        for i in range(n - 1):
            a = j * n + i
            faces.append((a, a + 1, a + n + 1, a + n))
    obj = mesh_object("background", verts, faces, [background_material(seed)])
    obj.data.use_auto_smooth = False
    return obj


def instrument(metal):
    """A 5 mm laparoscopic instrument: shaft and two jaws hinged at its end. The root empty's
    local frame: origin at the jaw tips' meeting point, +z along the shaft away from the tip."""
    root = bpy.data.objects.new("instrument", None)
    bpy.context.scene.collection.objects.link(root)

    def add(name, verts, faces, parent):
        obj = mesh_object(name, verts, faces, [metal])
        obj.data.auto_smooth_angle = math.radians(35.0)
        obj.parent = parent
        return obj

    ring, r, L = 24, 2.5, 260.0
    verts, faces = [], []
    for z in (14.0, 14.0 + L):
        for k in range(ring):
            a = 2 * math.pi * k / ring
            verts.append((r * math.cos(a), r * math.sin(a), z))
    for k in range(ring):
        a, b = k, (k + 1) % ring
        faces.append((a, b, b + ring, a + ring))
    faces.append(tuple(range(ring - 1, -1, -1)))
    add("shaft", verts, faces, root)
    jaws = []
    for sign in (1, -1):
        hinge = bpy.data.objects.new(f"hinge{sign}", None)
        bpy.context.scene.collection.objects.link(hinge)
        hinge.parent = root
        hinge.location = (0.0, 0.0, 14.0)
        # A tapered jaw from the hinge (z = 0) to its tip (z = -14), half of the shaft's section.
        jv = [(-2.2, 0.0, 0.0), (2.2, 0.0, 0.0), (2.2, sign * 2.2, 0.0), (-2.2, sign * 2.2, 0.0),
              (-0.6, 0.0, -14.0), (0.6, 0.0, -14.0), (0.6, sign * 0.9, -14.0),
              (-0.6, sign * 0.9, -14.0)]
        jf = [(0, 1, 2, 3), (4, 7, 6, 5), (0, 4, 5, 1), (1, 5, 6, 2), (2, 6, 7, 3), (3, 7, 4, 0)]
        if sign < 0:
            jf = [tuple(reversed(f)) for f in jf]
        add(f"jaw{sign}", jv, jf, hinge)
        jaws.append((hinge, sign))
    return root, jaws


def pose_instrument(root, jaws, tip, axis, jaw_open_deg):
    """Places the instrument with its tip at `tip` and its shaft along `axis` (unit, outwards)."""
    from mathutils import Matrix, Vector

    z = Vector(axis).normalized()
    helper = Vector((0.0, 0.0, 1.0)) if abs(z.z) < 0.9 else Vector((1.0, 0.0, 0.0))
    x = helper.cross(z).normalized()
    y = z.cross(x)
    m = Matrix(((x.x, y.x, z.x, tip[0]), (x.y, y.y, z.y, tip[1]), (x.z, y.z, z.z, tip[2]),
                (0, 0, 0, 1)))
    root.matrix_world = m
    for hinge, sign in jaws:
        hinge.rotation_euler = (sign * math.radians(jaw_open_deg) / 2, 0.0, 0.0)


def camera_and_light(K, R, tvec, width, power_w, spot_deg):
    """Blender camera matching the OpenCV pinhole (fx = fy, principal point at the image
    centre), and the laparoscope's light: a spot a few mm beside the lens, along its axis."""
    from mathutils import Matrix

    cam_data = bpy.data.cameras.new("laparoscope")
    cam_data.sensor_fit = "HORIZONTAL"
    cam_data.sensor_width = 36.0
    cam_data.lens = K[0] * 36.0 / width
    cam_data.clip_start = 1.0
    cam_data.clip_end = 5000.0
    cam = bpy.data.objects.new("laparoscope", cam_data)
    bpy.context.scene.collection.objects.link(cam)
    # Blender's camera looks down its -z with y up; OpenCV's along +z with y down.
    Rw = R.T @ np.diag([1.0, -1.0, -1.0])
    C = -R.T @ tvec
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = Rw, C
    cam.matrix_world = Matrix(m.tolist())
    bpy.context.scene.camera = cam
    light_data = bpy.data.lights.new("scope-light", type="SPOT")
    light_data.energy = power_w
    light_data.spot_size = math.radians(spot_deg)
    light_data.spot_blend = 0.8
    light_data.shadow_soft_size = 2.5
    light = bpy.data.objects.new("scope-light", light_data)
    bpy.context.scene.collection.objects.link(light)
    ml = m.copy()
    ml[:3, 3] = C + Rw @ np.array([4.0, -3.0, 0.0])
    light.matrix_world = Matrix(ml.tolist())
    return cam, light


def render_frame(scene, path):
    scene.render.filepath = path
    bpy.ops.render.render(write_still=True)


def read_png_rgb(path):
    """The rendered 8-bit frame as (height x width x 3) float in [0, 255], top row first."""
    img = bpy.data.images.load(path)
    try:
        w, h = img.size
        px = np.empty(w * h * 4, dtype=np.float32)
        img.pixels.foreach_get(px)
    finally:
        bpy.data.images.remove(img)
    return px.reshape(h, w, 4)[::-1, :, :3] * 255.0
