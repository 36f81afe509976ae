"""Renders a glTF scene in Cycles as Blender itself imports it (the tool glTF files come from).

Run inside Blender 3.4 (Debian's):
  blender -b --factory-startup --python bench/cycles/gltf_to_cycles.py -- SCENE.gltf OUT.exr
      [--env MAP.hdr] [--env-strength 1] [--spp N] [--seed S] [--threads 2] [--max-bounces 16]
      [--width 480] [--height 360] [--stats F] [--png OUT.png] [--rest-pose 1] [--coverage COV.exr]

Blender's own glTF importer makes the materials (Principled BSDF), lights and camera. On
top of it, so that the two renderers are given the same problem:
  - the environment map as the world, with Tessera's lat-long convention (CS184's -e):
    Cycles' equirectangular u is 0.5 - atan2(Y, X) / 2 pi in its +Z-up world, ours 0.5 +
    atan2(-z, x) / 2 pi in glTF's +Y-up one, where Blender's Y = -z: the direction's Y is
    mirrored before the lookup (docs/gltf.md);
  - every Principled BSDF uses single-scattering GGX (the specification's model; Blender's
    "Multiscatter GGX" would add the energy GGX loses);
  - one-sided emission: glTF's emitters without doubleSided emit from the front only, as
    Tessera renders them; Cycles' emission is two-sided, so the strength is multiplied by
    1 - Backfacing (the importer marks such materials with backface culling);
  - a dielectric of KHR_materials_ior 1 (no metal, no transmission) is exactly Lambertian
    in glTF's model (its Fresnel term is 0); Principled v1 cannot say so (Disney diffuse
    stays), so such a material gets Cycles' Diffuse BSDF (Lambert) with the same colour
    (normal map and alpha kept);
  - an image that is both a colour texture (base colour, emission) and a data one
    (metallic-roughness...) is one datablock in the importer's hands, read raw (non-colour)
    everywhere; colour uses get an sRGB copy;
  - alphaMode MASK: Cycles ignores the importer's alpha clip (an EEVEE setting) and would
    blend; the alpha goes through alpha >= alphaCutoff;
  - KHR_materials_volume's attenuation, which Blender 3.4's importer does not read, as a
    Volume Absorption of density 1 and colour 1 - sigma (Cycles' sigma_a = density (1 -
    colour)), sigma = -ln(attenuationColor) / attenuationDistance per channel;
  - the camera as Tessera chooses it: the first camera in the scene's node order (depth
    first from the scene's roots), an orthographic one 2 ymag high (the importer makes the
    larger of xmag, ymag fill the image's wider side); a file without a camera is framed
    as Tessera frames it (core/scene/gltf/gltf_lights_cameras.cc, frame_gltf_scene): the
    world bounds of the imported meshes' faces as posed, from 45 degrees round from +Z to
    +X and 30 up, 40 degrees vertically, r / sin(20 deg) x 1.05 from the centre (r: half
    the bounds' diagonal); glTF's (x, y, z) is Blender's (x, -z, y);
  - a primitive without a material gets glTF's default one (white metal of roughness 1);
    the importer leaves it without, and Cycles would render its grey diffuse default;
  - --rest-pose 1: no animation is imported (the importer would pose the file at its
    first animation's first key); nodes, bones and shape keys keep the file's own
    transforms and weights, the still Tessera renders;
  - --coverage F: after the render, 16 more samples per pixel with a transparent film,
    the alpha (the model's coverage of each pixel) written to F (EXR, RGBA);
  - Cycles set as for every comparison (cycles_common.py).
"""
import math
import os
import sys
import warnings

import bpy
import numpy
from mathutils import Vector

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import cycles_common  # noqa: E402
from compare_gltf import gltf_json  # noqa: E402

# Debian 12's Blender 3.4 glTF importer still says numpy.bool, which Debian's NumPy 1.24
# removed; it means the builtin. (Run Blender with Debian's python3 first on PATH: a
# pyenv one has no NumPy, compare_gltf.py takes care of it.)
with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    numpy.bool = bool


def lambertian(g):
    """Indices of materials that glTF's model makes exactly Lambertian (ior 1 dielectrics)."""
    out = set()
    for i, m in enumerate(g.get("materials", [])):
        ext = m.get("extensions", {})
        pbr = m.get("pbrMetallicRoughness", {})
        if (ext.get("KHR_materials_ior", {}).get("ior") == 1 and pbr.get("metallicFactor", 1) == 0 and
                ext.get("KHR_materials_transmission", {}).get("transmissionFactor", 0) == 0 and
                not any(m.get("emissiveFactor", [0, 0, 0]))):
            out.add(i)
    return out


def volumes(g):
    """Per material index: sigma_a (r, g, b) of its KHR_materials_volume, when it has one."""
    out = {}
    for i, m in enumerate(g.get("materials", [])):
        v = m.get("extensions", {}).get("KHR_materials_volume")
        if not v or v.get("thicknessFactor", 0) <= 0 or "attenuationDistance" not in v:
            continue
        c = v.get("attenuationColor", [1, 1, 1])
        out[i] = [-math.log(max(x, 1e-30)) / v["attenuationDistance"] for x in c]
    return out


def node_order(data):
    """glTF node indices in Tessera's walk order: depth first from the default scene's roots
    (scene 0; with no scenes, every node that is nobody's child)."""
    nodes = data.nodes or []
    if data.scenes:
        roots = list(data.scenes[data.scene if data.scene is not None else 0].nodes or [])
    else:
        child = {c for n in nodes for c in (n.children or [])}
        roots = [i for i in range(len(nodes)) if i not in child]
    order, stack = [], roots[::-1]
    while stack:
        i = stack.pop()
        order.append(i)
        stack.extend((nodes[i].children or [])[::-1])
    return order


def import_gltf(path, rest_pose):
    """Blender's importer; returns {glTF node index: camera datablock}, the node order and
    {Blender material name: glTF material index} (the importer renames repeated names)."""
    from io_scene_gltf2.blender.imp.gltf2_blender_camera import BlenderCamera
    from io_scene_gltf2.blender.imp.gltf2_blender_scene import BlenderScene
    cameras, order, materials = {}, [], {}
    create, animations = BlenderCamera.create, BlenderScene.create_animations

    def record(gltf, vnode, camera_id):
        cam = create(gltf, vnode, camera_id)
        cameras[vnode.camera_node_idx] = cam
        if gltf.data.cameras[camera_id].type == "orthographic":  # Tessera: ymag is half the height
            cam.sensor_fit = "VERTICAL"
            cam.ortho_scale = 2 * abs(gltf.data.cameras[camera_id].orthographic.ymag)
        return cam

    def after_nodes(gltf):  # every material and camera exists by now
        order[:] = node_order(gltf.data)
        for i, m in enumerate(gltf.data.materials or []):
            materials.update({name: i for name in getattr(m, "blender_material", {}).values()})
        if not rest_pose:
            animations(gltf)
    BlenderCamera.create = staticmethod(record)
    BlenderScene.create_animations = staticmethod(after_nodes)
    try:
        bpy.ops.import_scene.gltf(filepath=path)
    finally:
        BlenderCamera.create, BlenderScene.create_animations = staticmethod(create), staticmethod(animations)
    return cameras, order, materials


def frame_like_tessera(scene):
    """A camera framing the posed meshes' bounds as Tessera frames a file without one."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    lo, hi = numpy.full(3, numpy.inf), numpy.full(3, -numpy.inf)
    for ob in scene.objects:
        if ob.type != "MESH":
            continue
        ev = ob.evaluated_get(depsgraph)
        me = ev.to_mesh()
        co = numpy.empty(len(me.vertices) * 3)
        me.vertices.foreach_get("co", co)
        used = numpy.empty(len(me.loops), dtype=numpy.int64)
        me.loops.foreach_get("vertex_index", used)
        m = numpy.array(ev.matrix_world)
        if len(used):  # faces' vertices only (Tessera skips points and lines)
            p = co.reshape(-1, 3)[numpy.unique(used)] @ m[:3, :3].T + m[:3, 3]
            lo, hi = numpy.minimum(lo, p.min(axis=0)), numpy.maximum(hi, p.max(axis=0))
        ev.to_mesh_clear()
    to_gltf = lambda v: numpy.array([v[0], v[2], -v[1]])  # noqa: E731  Blender (X, Y, Z) -> glTF
    lo, hi = numpy.minimum(to_gltf(lo), to_gltf(hi)), numpy.maximum(to_gltf(lo), to_gltf(hi))
    c, r = (lo + hi) / 2, 0.5 * numpy.linalg.norm(hi - lo)
    el, az = math.radians(30), math.radians(45)
    d = numpy.array([math.cos(el) * math.sin(az), math.sin(el), math.cos(el) * math.cos(az)])
    eye = c + d * (r / math.sin(math.radians(20)) * 1.05)
    cam = bpy.data.cameras.new("tessera-framing")
    cam.sensor_fit = "VERTICAL"
    cam.angle_y = math.radians(40)
    cam.clip_start, cam.clip_end = 1e-3, 1e12  # Tessera's znear; no far plane
    ob = bpy.data.objects.new("tessera-framing", cam)
    scene.collection.objects.link(ob)
    ob.location = (eye[0], -eye[2], eye[1])
    ob.rotation_euler = Vector((-d[0], d[2], -d[1])).to_track_quat("-Z", "Y").to_euler()
    print("gltf_to_cycles: no camera: framed like Tessera, bounds %s - %s (glTF axes), eye %s" % (lo, hi, eye))
    return ob


def give_default_material():
    """glTF's default material where the importer left a primitive without one."""
    default = None
    for me in {ob.data for ob in bpy.context.scene.objects if ob.type == "MESH"}:
        if all(me.materials) and len(me.materials):
            continue
        if default is None:
            default = bpy.data.materials.new("glTF default")
            default.use_nodes = True
            n = default.node_tree.nodes["Principled BSDF"]
            n.inputs["Base Color"].default_value = (1, 1, 1, 1)
            n.inputs["Metallic"].default_value = 1
            n.inputs["Roughness"].default_value = 1
        if not len(me.materials):
            me.materials.append(default)
        for i, m in enumerate(me.materials):
            if m is None:
                me.materials[i] = default


def write_coverage(scene, o):
    """The model's coverage of each pixel (alpha with a transparent film), 16 spp, as an EXR."""
    scene.render.film_transparent = True
    scene.cycles.samples = 16
    scene.cycles.max_bounces = 0
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"
    scene.render.image_settings.color_mode = "RGBA"
    bpy.ops.render.render(write_still=False)
    bpy.data.images["Render Result"].save_render(o["coverage"])


COLOUR_TEXTURES = ("BASE COLOR", "EMISSIVE", "SHEEN COLOR", "SPECULAR COLOR")  # the importer's node labels


def srgb_colour_textures(nodes, copies):
    """The importer gives an image one colour space for all its uses: one that is also a
    metallic-roughness (or other data) texture is read raw as base colour too. Colour uses
    get an sRGB copy of such an image."""
    for n in nodes:
        if n.type == "TEX_IMAGE" and n.label in COLOUR_TEXTURES and n.image and n.image.colorspace_settings.is_data:
            if n.image.name not in copies:
                copies[n.image.name] = n.image.copy()
                copies[n.image.name].colorspace_settings.is_data = False
                copies[n.image.name].colorspace_settings.name = "sRGB"
            n.image = copies[n.image.name]


def alpha_mask(mat, n, links):
    """alphaMode MASK: Cycles ignores the importer's alpha clip; coverage is alpha >= cutoff."""
    alpha = n.inputs["Alpha"]
    if mat.blend_method != "CLIP":
        return
    if alpha.is_linked:
        step = mat.node_tree.nodes.new("ShaderNodeMath")
        step.operation = "GREATER_THAN"
        step.inputs[1].default_value = mat.alpha_threshold - 1e-6
        links.new(alpha.links[0].from_socket, step.inputs[0])
        links.new(step.outputs["Value"], alpha)
    else:
        alpha.default_value = 1.0 if alpha.default_value >= mat.alpha_threshold else 0.0


def lambert(n, nodes, links):
    """Cycles' Diffuse BSDF (Lambert) in place of a Principled BSDF, with its colour and alpha."""
    diffuse = nodes.new("ShaderNodeBsdfDiffuse")
    for src, dst in ((n.inputs["Base Color"], diffuse.inputs["Color"]), (n.inputs["Normal"], diffuse.inputs["Normal"])):
        if src.is_linked:
            links.new(src.links[0].from_socket, dst)
        elif dst.name == "Color":
            dst.default_value = src.default_value
    shader, alpha = diffuse.outputs["BSDF"], n.inputs["Alpha"]
    if alpha.is_linked or alpha.default_value < 1:
        mix = nodes.new("ShaderNodeMixShader")  # fac 0: transparent, 1: the surface
        links.new(nodes.new("ShaderNodeBsdfTransparent").outputs["BSDF"], mix.inputs[1])
        links.new(shader, mix.inputs[2])
        if alpha.is_linked:
            links.new(alpha.links[0].from_socket, mix.inputs["Fac"])
        else:
            mix.inputs["Fac"].default_value = alpha.default_value
        shader = mix.outputs["Shader"]
    out = next(o for o in nodes if o.type == "OUTPUT_MATERIAL")
    links.new(shader, out.inputs["Surface"])


def main():
    o = cycles_common.parse_args(dict(cycles_common.DEFAULTS, env=None, env_strength=1.0, png=None,
                                      rest_pose=0, coverage=None))
    bpy.ops.wm.read_factory_settings(use_empty=True)
    cameras, order, index = import_gltf(o["scene"], o["rest_pose"])
    scene = bpy.context.scene
    first = next((cameras[i] for i in order if i in cameras), None)
    if first is not None:
        scene.camera = next(ob for ob in scene.objects if ob.data == first)
    else:
        scene.camera = frame_like_tessera(scene)
    give_default_material()

    g = gltf_json(o["scene"])
    sigma, lambert_ones, copies = volumes(g), lambertian(g), {}
    for mat in list(bpy.data.materials):
        if not mat.use_nodes:
            continue
        nodes, links = mat.node_tree.nodes, mat.node_tree.links
        srgb_colour_textures(nodes, copies)
        for n in list(nodes):
            if n.type != "BSDF_PRINCIPLED":
                continue
            n.distribution = "GGX"
            alpha_mask(mat, n, links)
            if index.get(mat.name) in lambert_ones:
                lambert(n, nodes, links)
                continue
            strength = n.inputs["Emission Strength"]
            if mat.use_backface_culling and not strength.is_linked and strength.default_value > 0:
                geometry = nodes.new("ShaderNodeNewGeometry")
                front = nodes.new("ShaderNodeMath")
                front.operation = "MULTIPLY_ADD"  # backfacing x (-strength) + strength
                front.inputs[1].default_value = -strength.default_value
                front.inputs[2].default_value = strength.default_value
                links.new(geometry.outputs["Backfacing"], front.inputs[0])
                links.new(front.outputs["Value"], strength)
        if index.get(mat.name) in sigma:
            out = next(n for n in nodes if n.type == "OUTPUT_MATERIAL")
            vol = nodes.new("ShaderNodeVolumeAbsorption")
            s = sigma[index[mat.name]]
            if max(s) > 1:  # colour must stay in [0, 1]: scale the density instead
                k = max(s)
                vol.inputs["Density"].default_value = k
                vol.inputs["Color"].default_value = (1 - s[0] / k, 1 - s[1] / k, 1 - s[2] / k, 1)
            else:
                vol.inputs["Density"].default_value = 1
                vol.inputs["Color"].default_value = (1 - s[0], 1 - s[1], 1 - s[2], 1)
            links.new(vol.outputs["Volume"], out.inputs["Volume"])

    world = bpy.data.worlds.new("env")
    world.use_nodes = True
    nt = world.node_tree
    bg = nt.nodes["Background"]
    if o["env"]:
        coord = nt.nodes.new("ShaderNodeTexCoord")
        mapping = nt.nodes.new("ShaderNodeMapping")
        mapping.vector_type = "VECTOR"
        mapping.inputs["Scale"].default_value = (1, -1, 1)
        tex = nt.nodes.new("ShaderNodeTexEnvironment")
        tex.image = bpy.data.images.load(o["env"])
        tex.interpolation = "Linear"
        nt.links.new(coord.outputs["Generated"], mapping.inputs["Vector"])
        nt.links.new(mapping.outputs["Vector"], tex.inputs["Vector"])
        nt.links.new(tex.outputs["Color"], bg.inputs["Color"])
        bg.inputs["Strength"].default_value = o["env_strength"]
    else:
        bg.inputs["Strength"].default_value = 0
    scene.world = world

    cycles_common.configure(scene, o)
    cycles_common.render(scene, o, "gltf_to_cycles")
    if o["coverage"]:
        write_coverage(scene, o)


main()
