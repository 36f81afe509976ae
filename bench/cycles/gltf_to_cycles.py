"""Renders a glTF scene in Cycles as Blender itself imports it (the tool glTF files come from).

Run inside Blender 3.4 (Debian's):
  blender -b --factory-startup --python bench/cycles/gltf_to_cycles.py -- SCENE.gltf OUT.exr
      [--env MAP.hdr] [--env-strength 1] [--spp N] [--seed S] [--threads 2] [--max-bounces 16]
      [--width 480] [--height 360] [--stats F] [--png OUT.png]

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
    stays), so such a material gets Cycles' Diffuse BSDF (Lambert) with the same colour;
  - KHR_materials_volume's attenuation, which Blender 3.4's importer does not read, as a
    Volume Absorption of density 1 and colour 1 - sigma (Cycles' sigma_a = density (1 -
    colour)), sigma = -ln(attenuationColor) / attenuationDistance per channel;
  - Cycles as in cs184_to_cycles.py: Standard view, 1 px box filter, no denoising, no
    clamping, no adaptive sampling, caustics on, the same bounces, CPU, fixed threads.
"""
import json
import math
import sys
import time

import warnings

import bpy
import numpy

# Debian 12's Blender 3.4 glTF importer still says numpy.bool, which Debian's NumPy 1.24
# removed; it means the builtin. (Run Blender with Debian's python3 first on PATH: a
# pyenv one has no NumPy, compare_gltf.py takes care of it.)
with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    numpy.bool = bool


def args():
    argv = sys.argv[sys.argv.index("--") + 1:]
    o = {"scene": argv[0], "out": argv[1], "env": None, "env_strength": 1.0, "spp": 16, "seed": 0, "threads": 2,
         "max_bounces": 16, "width": 480, "height": 360, "stats": None, "png": None}
    i = 2
    while i < len(argv):
        k = argv[i].lstrip("-").replace("-", "_")
        o[k] = type(o[k])(argv[i + 1]) if o[k] is not None else argv[i + 1]
        i += 2
    return o


def blender_name(m, index):
    """The name Blender's importer gives glTF material `index`."""
    return m.get("name") or "Material_%d" % index


def lambertian(path):
    """Names of materials that glTF's model makes exactly Lambertian (ior 1 dielectrics)."""
    with open(path) as f:
        g = json.load(f)
    out = set()
    for i, m in enumerate(g.get("materials", [])):
        ext = m.get("extensions", {})
        pbr = m.get("pbrMetallicRoughness", {})
        if (ext.get("KHR_materials_ior", {}).get("ior") == 1 and pbr.get("metallicFactor", 1) == 0 and
                ext.get("KHR_materials_transmission", {}).get("transmissionFactor", 0) == 0 and
                not any(m.get("emissiveFactor", [0, 0, 0]))):
            out.add(blender_name(m, i))
    return out


def volumes(path):
    """Per material name: sigma_a (r, g, b) of its KHR_materials_volume, when it has one."""
    with open(path) as f:
        g = json.load(f)
    out = {}
    for i, m in enumerate(g.get("materials", [])):
        v = m.get("extensions", {}).get("KHR_materials_volume")
        if not v or v.get("thicknessFactor", 0) <= 0 or "attenuationDistance" not in v:
            continue
        c = v.get("attenuationColor", [1, 1, 1])
        out[blender_name(m, i)] = [-math.log(max(x, 1e-30)) / v["attenuationDistance"] for x in c]
    return out


def main():
    o = args()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.import_scene.gltf(filepath=o["scene"])
    scene = bpy.context.scene
    cams = [ob for ob in scene.objects if ob.type == "CAMERA"]
    if cams:
        scene.camera = cams[0]

    sigma = volumes(o["scene"])
    lambert = lambertian(o["scene"])
    for mat in bpy.data.materials:
        if not mat.use_nodes:
            continue
        nodes, links = mat.node_tree.nodes, mat.node_tree.links
        for n in list(nodes):
            if n.type != "BSDF_PRINCIPLED":
                continue
            n.distribution = "GGX"
            if mat.name in lambert:
                diffuse = nodes.new("ShaderNodeBsdfDiffuse")
                base = n.inputs["Base Color"]
                if base.is_linked:
                    links.new(base.links[0].from_socket, diffuse.inputs["Color"])
                else:
                    diffuse.inputs["Color"].default_value = base.default_value
                out = next(o for o in nodes if o.type == "OUTPUT_MATERIAL")
                links.new(diffuse.outputs["BSDF"], out.inputs["Surface"])
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
        if mat.name in sigma:
            out = next(n for n in nodes if n.type == "OUTPUT_MATERIAL")
            vol = nodes.new("ShaderNodeVolumeAbsorption")
            s = sigma[mat.name]
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

    scene.render.engine = "CYCLES"
    cy = scene.cycles
    cy.device = "CPU"
    cy.samples = o["spp"]
    cy.use_adaptive_sampling = False
    cy.use_denoising = False
    cy.seed = o["seed"]
    cy.max_bounces = cy.diffuse_bounces = cy.glossy_bounces = cy.transmission_bounces = o["max_bounces"]
    cy.volume_bounces = o["max_bounces"]
    cy.transparent_max_bounces = o["max_bounces"]
    cy.caustics_reflective = cy.caustics_refractive = True
    cy.sample_clamp_direct = cy.sample_clamp_indirect = 0
    cy.blur_glossy = 0
    cy.light_sampling_threshold = 0
    cy.pixel_filter_type = "BOX"
    cy.filter_width = 1.0
    scene.render.threads_mode = "FIXED"
    scene.render.threads = o["threads"]
    scene.render.resolution_x, scene.render.resolution_y = o["width"], o["height"]
    scene.render.resolution_percentage = 100
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"
    scene.render.image_settings.color_mode = "RGB"
    t0 = time.time()
    bpy.ops.render.render(write_still=False)
    seconds = time.time() - t0
    bpy.data.images["Render Result"].save_render(o["out"])
    if o["png"]:  # sRGB, clamped (Standard view), as Tessera's PNG
        scene.render.image_settings.file_format = "PNG"
        scene.render.image_settings.color_depth = "8"
        bpy.data.images["Render Result"].save_render(o["png"])
    if o["stats"]:
        with open(o["stats"], "w") as f:
            json.dump({"seconds": seconds, "spp": o["spp"]}, f)
    print("gltf_to_cycles: %s, %d spp in %.2f s -> %s" % (o["scene"], o["spp"], seconds, o["out"]))


main()
