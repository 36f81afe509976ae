"""Scenes built in Blender by script, for bench/blender/fidelity.py (run inside Blender 3.4):
  blender -b --factory-startup --python bench/blender/blender_scenes.py -- NAME OUT_DIR
      ADDON_PARENT [--spp 256] [--width 160] [--height 120] [--threads 2] [--max-bounces 8]
          [--env scenes/sky.hdr]

NAME is one of SCENES. Writes, in OUT_DIR: NAME.glb (exported by the add-on's own export
code, as "Render on farm" does), NAME.json (the settings the add-on sends, the frame, its
export notes) and NAME-cycles.exr (Cycles' render of the same .blend, with
bench/cycles/cycles_common.py's fair settings: box filter, no denoising, no clamping, the
same bounces). Every scene sits on a grey floor under a light (an emissive quad, a point
light, or the world), seen by one camera.
"""
import json
import math
import os
import sys

import bpy

argv = sys.argv[sys.argv.index("--") + 1:]
NAME, OUT, ADDON_PARENT = argv[0], os.path.abspath(argv[1]), os.path.abspath(argv[2])
opts = {"spp": 256, "width": 160, "height": 120, "threads": 2, "max_bounces": 8, "env": None, "seed": 0,
        "control": 0}
for i in range(3, len(argv), 2):
    k = argv[i].lstrip("-").replace("-", "_")
    opts[k] = type(opts[k])(argv[i + 1]) if opts[k] is not None else argv[i + 1]
sys.path.insert(0, ADDON_PARENT)
sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "cycles"))
import cycles_common  # noqa: E402
from tessera_blender import export  # noqa: E402


def clear():
    for o in list(bpy.data.objects):
        bpy.data.objects.remove(o)
    scene = bpy.context.scene
    scene.world = bpy.data.worlds.new("world")
    scene.world.use_nodes = True
    bg = scene.world.node_tree.nodes["Background"]
    bg.inputs["Color"].default_value = (0.02, 0.02, 0.02, 1)
    return scene


def principled(name, color=(0.8, 0.8, 0.8), metallic=0.0, roughness=0.5, transmission=0.0, emission=None):
    m = bpy.data.materials.new(name)
    m.use_nodes = True
    p = m.node_tree.nodes["Principled BSDF"]
    p.inputs["Base Color"].default_value = (*color, 1)
    p.inputs["Metallic"].default_value = metallic
    p.inputs["Roughness"].default_value = roughness
    p.inputs["Transmission"].default_value = transmission
    if emission:
        p.inputs["Emission"].default_value = (1, 1, 1, 1)
        p.inputs["Emission Strength"].default_value = emission
    return m


def add(kind, location, material, size=1.0, name=None):
    if kind == "sphere":
        bpy.ops.mesh.primitive_uv_sphere_add(segments=64, ring_count=32, radius=size, location=location)
        bpy.ops.object.shade_smooth()
    elif kind == "plane":
        bpy.ops.mesh.primitive_plane_add(size=size, location=location)
    else:
        bpy.ops.mesh.primitive_cube_add(size=size, location=location)
    o = bpy.context.active_object
    if name:
        o.name = name
    o.data.materials.append(material)
    return o


def camera(scene, location, target, lens=35.0):
    bpy.ops.object.camera_add(location=location)
    cam = bpy.context.active_object
    direction = (target[0] - location[0], target[1] - location[1], target[2] - location[2])
    from mathutils import Vector
    cam.rotation_euler = Vector(direction).to_track_quat("-Z", "Y").to_euler()
    cam.data.lens = lens
    scene.camera = cam
    return cam


def stage(scene, light="quad"):
    add("plane", (0, 0, 0), principled("floor", (0.5, 0.5, 0.5), roughness=1.0), size=12)
    if light == "quad":
        lamp = add("plane", (0, 0, 4), principled("lamp", (0, 0, 0), emission=8.0), size=2)
        lamp.rotation_euler = (math.pi, 0, 0)  # facing down
    elif light == "point":
        bpy.ops.object.light_add(type="POINT", location=(1.5, -1.5, 3))
        bpy.context.active_object.data.energy = 600
    camera(scene, (0, -6, 2.5), (0, 0, 0.8))


def diffuse_metal(scene):
    stage(scene)
    add("sphere", (-1.1, 0, 0.8), principled("red", (0.7, 0.1, 0.08), roughness=1.0), 0.8)
    add("sphere", (1.1, 0, 0.8), principled("gold", (1.0, 0.77, 0.34), metallic=1.0, roughness=0.3), 0.8)


def gltf_thickness(material, thickness):
    """The exporter's "glTF Material Output" group node with a Thickness: the material is a
    solid (KHR_materials_volume), as an author makes glass for glTF."""
    group = bpy.data.node_groups.get("glTF Material Output")
    if group is None:
        group = bpy.data.node_groups.new("glTF Material Output", "ShaderNodeTree")
        group.inputs.new("NodeSocketFloat", "Occlusion")
        group.inputs.new("NodeSocketFloat", "Thickness")
    node = material.node_tree.nodes.new("ShaderNodeGroup")
    node.node_tree = group
    node.inputs["Thickness"].default_value = thickness


def glass(scene):
    stage(scene)
    add("cube", (-1.5, 1.5, 1.0), principled("blue", (0.1, 0.2, 0.7), roughness=1.0), 2.0)
    m = principled("glass", (1, 1, 1), roughness=0.0, transmission=1.0)
    gltf_thickness(m, 1.6)
    add("sphere", (0, 0, 0.8), m, 0.8)


def emissive_point(scene):
    stage(scene, light="point")
    add("sphere", (-1.1, 0, 0.8), principled("white", (0.8, 0.8, 0.8), roughness=1.0), 0.8)
    add("cube", (1.1, 0, 0.6), principled("glow", (0.1, 0.1, 0.1), emission=2.0), 1.2)


def hdri(scene):
    add("plane", (0, 0, 0), principled("floor", (0.5, 0.5, 0.5), roughness=1.0), size=12)
    add("sphere", (-1.1, 0, 0.8), principled("white", (0.8, 0.8, 0.8), roughness=1.0), 0.8)
    add("sphere", (1.1, 0, 0.8), principled("chrome", (0.95, 0.95, 0.95), metallic=1.0, roughness=0.02), 0.8)
    camera(scene, (0, -6, 2.5), (0, 0, 0.8))
    nt = scene.world.node_tree
    tex = nt.nodes.new("ShaderNodeTexEnvironment")
    tex.image = bpy.data.images.load(os.path.abspath(opts["env"]))
    nt.links.new(tex.outputs["Color"], nt.nodes["Background"].inputs["Color"])


def animated(scene):
    stage(scene)
    cube = add("cube", (-1.5, 0, 0.5), principled("orange", (0.8, 0.35, 0.05), roughness=1.0), 1.0)
    cube.keyframe_insert("location", frame=1)
    cube.location = (1.5, 0, 0.5)
    cube.rotation_euler = (0, 0, math.radians(90))
    cube.keyframe_insert("location", frame=9)
    cube.keyframe_insert("rotation_euler", frame=9)
    scene.frame_start, scene.frame_end = 1, 9
    scene.frame_set(4)


def dof(scene):
    stage(scene)
    for i, c in enumerate([(0.7, 0.1, 0.1), (0.1, 0.6, 0.1), (0.1, 0.2, 0.7)]):
        add("sphere", (-1.2 + 1.2 * i, -1.5 + 2.0 * i, 0.5), principled(f"s{i}", c, roughness=1.0), 0.5)
    cam = scene.camera
    cam.data.dof.use_dof = True
    cam.data.dof.aperture_fstop = 0.8
    cam.data.dof.focus_distance = (cam.location - bpy.data.objects["Sphere.001"].location).length


SCENES = {"diffuse-metal": diffuse_metal, "glass": glass, "emissive-point": emissive_point, "hdri": hdri,
          "animated": animated, "dof": dof}

scene = clear()
SCENES[NAME](scene)
cycles_common.configure(scene, opts)
os.makedirs(OUT, exist_ok=True)


class Props:  # the add-on's panel settings, as bench/blender/fidelity.py asks
    samples = opts["spp"]
    max_bounces = opts["max_bounces"]
    tile_size = 32
    noise_target = 0.0


def lambert_control(scene, glb):
    """The control (--control 1): every rough dielectric Lambertian in both renderers,
    exactly: in Cycles a Diffuse BSDF (Oren-Nayar roughness 0) in place of the Principled
    BSDF, in the glTF KHR_materials_ior 1 (its Fresnel term is 0: glTF's dielectric is then
    Lambert(base colour)). Metals, glass and emitters stay as they are."""
    import struct
    names = []
    for m in bpy.data.materials:
        p = m.node_tree.nodes.get("Principled BSDF") if m.use_nodes else None
        if p is None or p.inputs["Metallic"].default_value > 0 or p.inputs["Transmission"].default_value > 0 \
                or (max(p.inputs["Emission"].default_value[:3]) > 0 and p.inputs["Emission Strength"].default_value > 0):
            continue
        d = m.node_tree.nodes.new("ShaderNodeBsdfDiffuse")
        d.inputs["Color"].default_value = p.inputs["Base Color"].default_value
        d.inputs["Roughness"].default_value = 0.0
        m.node_tree.links.new(d.outputs["BSDF"], m.node_tree.nodes["Material Output"].inputs["Surface"])
        names.append(m.name)
    with open(glb, "rb") as f:
        data = f.read()
    n = struct.unpack_from("<I", data, 12)[0]
    doc = json.loads(data[20:20 + n])
    for m in doc.get("materials", []):
        if m.get("name") in names:
            m.setdefault("extensions", {})["KHR_materials_ior"] = {"ior": 1.0}
    doc["extensionsUsed"] = sorted(set(doc.get("extensionsUsed", [])) | {"KHR_materials_ior"})
    js = json.dumps(doc).encode()
    js += b" " * (-len(js) % 4)
    rest = data[20 + n:]
    body = struct.pack("<I4s", len(js), b"JSON") + js + rest
    with open(glb, "wb") as f:
        f.write(struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body)
    return names


animation = NAME == "animated"
export.export_gltf(scene, os.path.join(OUT, NAME + ".glb"), animation)
if opts["control"]:
    print("Lambertian control:", lambert_control(scene, os.path.join(OUT, NAME + ".glb")))
settings = export.render_settings(scene, Props, OUT)
with open(os.path.join(OUT, NAME + ".json"), "w") as f:
    json.dump({"settings": settings, "frame": scene.frame_current, "notes": export.export_notes(scene)}, f, indent=1)
o = dict(opts, scene=NAME, out=os.path.join(OUT, NAME + "-cycles.exr"), stats=os.path.join(OUT, NAME + "-cycles.json"))
cycles_common.render(scene, o, "cycles")
