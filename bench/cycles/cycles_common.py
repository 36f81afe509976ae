"""What every Tessera-vs-Cycles script sets the same way (run inside Blender): the Cycles
settings that make the comparison fair, and rendering to an EXR with its time.

Cycles: CPU with a fixed thread count, no adaptive sampling, no denoising, no clamping,
caustics on, no glossy blur, no light threshold, a 1 px box filter, the same max bounces
for every kind, Standard view transform (the EXR is linear either way), 32-bit RGB EXR.
"""
import json
import sys
import time

import bpy


def parse_args(defaults):
    """Blender passes the script's own arguments after "--": SCENE OUT then --key value."""
    argv = sys.argv[sys.argv.index("--") + 1:]
    o = dict(defaults, scene=argv[0], out=argv[1])
    i = 2
    while i < len(argv):
        k = argv[i].lstrip("-").replace("-", "_")
        o[k] = type(o[k])(argv[i + 1]) if o[k] is not None else argv[i + 1]
        i += 2
    return o


DEFAULTS = {"spp": 16, "seed": 0, "threads": 2, "max_bounces": 16, "width": 480, "height": 360, "stats": None}


def configure(scene, o):
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


def render(scene, o, tag):
    """Renders, writes o["out"] (and o["png"] when asked: sRGB, clamped) and o["stats"]."""
    t0 = time.time()
    bpy.ops.render.render(write_still=False)
    seconds = time.time() - t0
    result = bpy.data.images["Render Result"]
    result.save_render(o["out"])
    if o.get("png"):
        scene.render.image_settings.file_format = "PNG"
        scene.render.image_settings.color_depth = "8"
        result.save_render(o["png"])
    if o["stats"]:
        with open(o["stats"], "w") as f:
            json.dump({"seconds": seconds, "spp": o["spp"]}, f)
    print("%s: %s, %d spp in %.2f s -> %s" % (tag, o["scene"], o["spp"], seconds, o["out"]))
