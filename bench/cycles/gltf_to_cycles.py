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
  - Cycles set as for every comparison (cycles_common.py).
"""
import json
import math
import os
import sys
import warnings

import bpy
import numpy

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import cycles_common  # noqa: E402

# Debian 12's Blender 3.4 glTF importer still says numpy.bool, which Debian's NumPy 1.24
# removed; it means the builtin. (Run Blender with Debian's python3 first on PATH: a
# pyenv one has no NumPy, compare_gltf.py takes care of it.)
with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    numpy.bool = bool


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
    o = cycles_common.parse_args(dict(cycles_common.DEFAULTS, env=None, env_strength=1.0, png=None))
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

    cycles_common.configure(scene, o)
    cycles_common.render(scene, o, "gltf_to_cycles")


main()
