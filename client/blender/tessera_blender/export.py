"""From the open Blender scene to what the farm renders: the glTF file (Blender's own
exporter), the settings that glTF cannot carry (resolution, frame range, fps, depth of
field, the world), where the frames go (Blender's output path and its #### convention), and
the list of what the exporter drops or changes, said before anything is sent."""
import math
import os

import bpy
from mathutils import Vector

# Shader nodes glTF (and so the farm) can express: Blender's exporter reads these.
EXPRESSIBLE = {
    "BSDF_PRINCIPLED", "OUTPUT_MATERIAL", "TEX_IMAGE", "NORMAL_MAP", "MAPPING", "TEX_COORD", "UVMAP",
    "SEPRGB", "SEPARATE_COLOR", "SEPXYZ", "SEPARATE_XYZ", "EMISSION", "BSDF_TRANSPARENT", "MIX_SHADER",
    "VERTEX_COLOR", "ATTRIBUTE", "REROUTE", "GROUP_INPUT", "GROUP_OUTPUT", "MIX_RGB", "MIX", "VALUE", "RGB",
    "CLAMP", "MATH", "BSDF_DIFFUSE", "BSDF_GLOSSY", "GROUP",
}
# Principled BSDF inputs the exporter drops (value, or a link), with what it means here.
DROPPED_INPUTS = {
    "Subsurface": "subsurface scattering (glTF has none): rendered as its base colour",
    "Anisotropic": "anisotropy (not exported by Blender 3.4): rendered isotropic",
    "Sheen": "sheen (not exported by Blender 3.4)",
    "Clearcoat": "clearcoat (KHR_materials_clearcoat: exported, rendered by the farm)",
}
# What the farm writes as it is. A PNG is the farm's EXR saved by Blender as the other
# formats are: the Python client's .png is the coordinator's preview, at most 1280 wide (a
# 1920-wide render came back 960 wide).
FORMATS = {"OPEN_EXR": ".exr", "OPEN_EXR_MULTILAYER": ".exr"}


def _input_used(node, name):
    sock = node.inputs.get(name)
    if sock is None:
        return False
    if sock.is_linked:
        return True
    v = sock.default_value
    return float(v) > 0 if isinstance(v, float) else False


def _has_volume(mat):
    """The exporter writes KHR_materials_volume from a "glTF Material Output" (or "glTF
    Settings") group node's Thickness input."""
    for n in mat.node_tree.nodes:
        if n.type == "GROUP" and n.node_tree and n.node_tree.name in ("glTF Material Output", "glTF Settings"):
            t = n.inputs.get("Thickness")
            if t is not None and (t.is_linked or t.default_value > 0):
                return True
    return False


def export_notes(scene):
    """What the export drops or changes, one line each, before anything is sent."""
    notes = []
    principled = False
    for mat in sorted({s.material for o in scene.objects if o.type == "MESH" for s in o.material_slots
                       if s.material}, key=lambda m: m.name):
        if not mat.use_nodes or not mat.node_tree:
            notes.append(f"material '{mat.name}' has no nodes: exported from its viewport colour")
            continue
        others = sorted({n.bl_idname.replace("ShaderNode", "") for n in mat.node_tree.nodes
                         if n.type not in EXPRESSIBLE and n.type != "FRAME"})
        if others:
            notes.append(f"material '{mat.name}': {', '.join(others)} cannot be expressed in glTF: the exporter "
                         "leaves them out")
        for node in mat.node_tree.nodes:
            if node.type == "BSDF_PRINCIPLED":
                principled = True
                if _input_used(node, "Transmission") and not _has_volume(mat):
                    notes.append(f"material '{mat.name}': transmission without a glTF Material Output's Thickness "
                                 "exports as a thin wall (KHR_materials_transmission alone): light passes without "
                                 "bending, unlike Cycles' solid glass")
                for name, what in DROPPED_INPUTS.items():
                    if name != "Clearcoat" and _input_used(node, name):
                        notes.append(f"material '{mat.name}': {what}")
            if node.type in ("BSDF_DIFFUSE", "BSDF_GLOSSY", "MIX_SHADER"):
                notes.append(f"material '{mat.name}': {node.bl_idname.replace('ShaderNode', '')} is approximated "
                             "by the exporter (glTF has one metallic-roughness material)")
    if principled:
        notes.append("Principled BSDF's diffuse (Disney) is rendered as glTF's Lambertian base: a little darker "
                     "at grazing angles on rough surfaces")
    cameras = [o for o in scene.objects if o.type == "CAMERA"]
    if len(cameras) > 1:
        notes.append(f"{len(cameras)} cameras: the farm frames with the scene camera only when it is the first the "
                     "exporter writes; hide or delete the others to be sure")
    if scene.camera is None:
        notes.append("no scene camera: the farm frames the whole scene from +Z")
    for o in scene.objects:
        if o.type == "LIGHT" and o.data.type == "AREA":
            notes.append(f"light '{o.name}': area lights are not in glTF (the exporter leaves them out); use an "
                         "emissive mesh")
    world = scene.world
    if world and world.use_nodes and world.node_tree:
        types = {n.type for n in world.node_tree.nodes}
        if types - {"BACKGROUND", "OUTPUT_WORLD", "TEX_ENVIRONMENT", "MAPPING", "TEX_COORD", "REROUTE"}:
            notes.append("the world's node setup is more than a colour or an environment texture with a strength: "
                         "only those are sent")
        if "MAPPING" in types:
            notes.append("the world's Mapping node is not sent: the environment keeps its default orientation")
    if scene.render.image_settings.file_format not in FORMATS and scene.render.image_settings.file_format != "PNG":
        notes.append(f"output format {scene.render.image_settings.file_format}: the farm writes OpenEXR, converted "
                     "by Blender to the scene's format")
    return notes


def write_rgbe(path, rgb):
    """A Radiance .hdr (RGBE, flat scanlines, top row first) of `rgb`, float (h, w, 3) rows
    bottom-up as Blender holds pixels. Written here because Blender's Image.save of a float
    image applies the view transform."""
    import numpy as np
    h, w, _ = rgb.shape
    rgb = np.maximum(rgb[::-1].astype(np.float64), 0)
    top = rgb.max(axis=2)
    mant, exp = np.frexp(top)
    scale = np.where(top > 1e-32, mant * 256.0 / np.where(top > 1e-32, top, 1), 0)
    out = np.zeros((h, w, 4), dtype=np.uint8)
    out[..., :3] = np.clip(rgb * scale[..., None], 0, 255).astype(np.uint8)
    out[..., 3] = np.where(top > 1e-32, exp + 128, 0).astype(np.uint8)
    with open(path, "wb") as f:
        f.write(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n" + f"-Y {h} +X {w}\n".encode())
        f.write(out.tobytes())
    return path


def mirrored_environment(image, path):
    """Writes `image` mirrored left to right as a Radiance .hdr at `path`. Cycles looks an
    equirectangular image up at u = 0.5 - atan2(y, x) / 2 pi (+Z up), Tessera at u = 0.5 +
    atan2(y, x) / 2 pi (CS184's convention, docs/gltf.md): the same image would render
    mirrored, its mirror image renders as Blender shows it."""
    import numpy as np
    w, h = image.size
    px = np.empty(w * h * 4, dtype=np.float32)
    image.pixels.foreach_get(px)  # scene-linear for a float image, rows bottom-up
    return write_rgbe(path, px.reshape(h, w, 4)[:, ::-1, :3])


def world_settings(scene, folder=None):
    """env / env_color / env_strength for the scene's world: an Environment Texture's image
    (an HDRI) as the farm's environment map (mirrored into `folder`, see
    mirrored_environment), a plain Background's colour as a uniform one."""
    world = scene.world
    if world is None:
        return {"no_default_env": True}
    if not world.use_nodes or not world.node_tree:
        return {"env_color": tuple(world.color)}
    out = next((n for n in world.node_tree.nodes if n.type == "OUTPUT_WORLD" and n.is_active_output), None)
    link = out.inputs["Surface"].links[0] if out and out.inputs["Surface"].is_linked else None
    bg = link.from_node if link and link.from_node.type == "BACKGROUND" else None
    if bg is None:
        return {"no_default_env": True}
    strength = float(bg.inputs["Strength"].default_value)
    color = bg.inputs["Color"]
    if color.is_linked and color.links[0].from_node.type == "TEX_ENVIRONMENT":
        image = color.links[0].from_node.image
        if image is not None and image.size[0] > 0:
            path = os.path.join(folder or bpy.app.tempdir, "environment.hdr")
            return {"env": mirrored_environment(image, path), "env_strength": strength}
    c = color.default_value
    return {"env_color": (c[0] * strength, c[1] * strength, c[2] * strength)}


def camera_settings(scene):
    """Depth of field (glTF cameras have none): lens radius and focus distance in metres."""
    cam = scene.camera
    if cam is None or cam.type != "CAMERA" or not cam.data.dof.use_dof:
        return {}
    dof = cam.data.dof
    if dof.focus_object is not None:
        # Along the optical axis, as Cycles measures it (blender_camera_focal_distance) and as
        # -d is: the straight-line distance put an object off the centre out of focus.
        view = cam.matrix_world.to_3x3() @ Vector((0.0, 0.0, -1.0))
        to = dof.focus_object.matrix_world.translation - cam.matrix_world.translation
        distance = abs(to.dot(view.normalized()))
    else:
        distance = dof.focus_distance
    radius = cam.data.lens / 1000.0 / (2.0 * dof.aperture_fstop)  # focal length / f-number = aperture diameter
    return {"lens_radius": radius, "focal_distance": max(distance, 1e-4)}


def frames(scene, animation):
    """The frames to render: the scene's range (with its step) or the current frame."""
    if not animation:
        return [scene.frame_current]
    return list(range(scene.frame_start, scene.frame_end + 1, max(1, scene.frame_step)))


def output_path(scene, frame):
    """Where Blender itself writes `frame` (render.frame_path: its #### convention, the
    file format's extension), and the format the farm is asked for (.exr or .png)."""
    path = scene.render.frame_path(frame=frame)
    return path, FORMATS.get(scene.render.image_settings.file_format, ".exr")


def resolution(scene):
    pct = scene.render.resolution_percentage / 100.0
    return (max(1, int(scene.render.resolution_x * pct)), max(1, int(scene.render.resolution_y * pct)))


def export_gltf(scene, path, animation):
    """Blender's glTF exporter on the whole scene, as a .glb at `path`."""
    wanted = dict(filepath=path, export_format="GLB", use_selection=False, use_visible=False, use_renderable=True,
                  use_active_scene=True, export_cameras=True, export_lights=True, export_apply=True,
                  export_animations=animation, export_frame_range=True, export_force_sampling=True,
                  export_yup=True, export_extras=False, will_save_settings=False)
    known = set(bpy.ops.export_scene.gltf.get_rna_type().properties.keys())
    bpy.ops.export_scene.gltf(**{k: v for k, v in wanted.items() if k in known})
    return path


def render_settings(scene, props, folder=None):
    """The Python client's keywords for this scene and the panel's settings (files made
    for them, the environment map, go into `folder`)."""
    s = dict(samples=props.samples, max_depth=props.max_bounces, tile=props.tile_size,
             noise_target=props.noise_target, resolution=resolution(scene), camera="file",
             fps=scene.render.fps / scene.render.fps_base)
    s.update(world_settings(scene, folder))
    if getattr(props, "aovs", False) and scene.render.image_settings.file_format in ("OPEN_EXR",
                                                                                     "OPEN_EXR_MULTILAYER"):
        s["aov"] = "all"  # layers the compositor reads (an EXR output only: PNG has no layers)
    if getattr(props, "denoise", False):
        s["denoise"] = True
    s.update(camera_settings(scene))
    if math.isclose(s.get("env_strength", 1.0), 1.0):
        s.pop("env_strength", None)
    return s


def blend_name():
    return os.path.basename(bpy.data.filepath) or "untitled.blend"
