"""The Blender add-on driven headless against a farm on loopback (run by addon-test.sh:
blender -b --factory-startup --python-exit-code 1 --python addon_test.py -- BIN BUILD SRC).

  1. Installed from build/blender/tessera_blender.zip and enabled, as a user would.
  2. A still (the factory scene, resolution and samples shrunk, OpenEXR output with ####):
     written where render.frame_path says, and bit-identical to `tessera render` of the
     exported file with the settings the add-on sent.
  3. An animation (frames 2-3 of a moving cube, step 1): each frame at its frame_path, the
     second equal to `tessera render --frame 3`; the exported keyframe times are frame / fps
     (keys at frames 1 and 4), so the farm's frame N is Blender's frame N.
  4. PNG output, and a JPEG output that Blender converts from the farm's EXR.
  5. What the exporter drops (subsurface, a node glTF cannot express, an area light) is
     listed before submitting; an unreachable coordinator is an error report that names it.
"""
import json
import os
import struct
import subprocess
import sys
import tempfile

import bpy

argv = sys.argv[sys.argv.index("--") + 1:]
BIN, BUILD, SRC = (os.path.abspath(a) for a in argv[:3])
sys.path.insert(0, os.path.join(SRC, "tests", "python"))
from local_farm import LocalFarm, identical, render_local  # noqa: E402

failures = []


def check(ok, what):
    print(("ok    " if ok else "FAIL  ") + what, flush=True)
    if not ok:
        failures.append(what)


def cli_flags(settings, frame):
    """`tessera render` flags for the add-on's settings (the Python client's keywords)."""
    import tessera.settings  # the add-on's copy (its lib/ is on sys.path once it ran)
    return tessera.settings.cli_flags(frame=frame, **settings)


tmp = tempfile.mkdtemp(prefix="tessera-blender-test-")
bpy.ops.preferences.addon_install(filepath=os.path.join(BUILD, "blender", "tessera_blender.zip"))
bpy.ops.preferences.addon_enable(module="tessera_blender")
from tessera_blender import export  # noqa: E402

check(hasattr(bpy.context.scene, "tessera"), "the add-on is installed from its zip and enabled")
farm = LocalFarm(BIN, workers=1, threads=2)
try:
    scene = bpy.context.scene
    props = scene.tessera
    props.coordinator = farm.address
    props.samples, props.max_bounces, props.tile_size = 4, 3, 16
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 64, 48, 50
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.filepath = os.path.join(tmp, "still", "shot_####")
    scene.frame_set(1)

    # 2. A still.
    bpy.ops.tessera.render_on_farm()
    want = scene.render.frame_path(frame=1)
    check(want.endswith("shot_0001.exr") and os.path.isfile(want), f"the still is written to {want}")
    check(len(props.last_job) == 16 and props.last_status.startswith("done"),
          f"the job and its end are on scene.tessera ({props.last_job}, {props.last_status})")
    settings = export.render_settings(scene, props)
    check(settings["resolution"] == (32, 24) and settings["max_depth"] == 3, "resolution (with %) and bounces sent")
    render_local(BIN, props.last_export, os.path.join(tmp, "local.exr"), *cli_flags(settings, 1))
    check(identical(BIN, want, os.path.join(tmp, "local.exr")), "the farm's still is tessera render's, bit for bit")
    # With AOV layers: the compositor's passes in the same EXR.
    props.aovs = True
    bpy.ops.tessera.render_on_farm()
    image = bpy.data.images.load(want, check_existing=False)
    scene.use_nodes = True
    node = scene.node_tree.nodes.new("CompositorNodeImage")
    node.image = image
    outputs = [o.name for o in node.outputs]
    check(all(n in outputs for n in ("albedo", "normal", "depth", "id", "Alpha")),
          f"AOV layers reach Blender's compositor ({outputs})")
    props.aovs = False

    # 3. An animation.
    cube = bpy.data.objects["Cube"]
    cube.location = (0, 0, 0)
    cube.keyframe_insert("location", frame=1)
    cube.location = (1, 0, 0)
    cube.keyframe_insert("location", frame=4)
    scene.frame_start, scene.frame_end = 2, 3
    scene.render.filepath = os.path.join(tmp, "anim", "f_")
    props.animation = True
    bpy.ops.tessera.render_on_farm()
    paths = [scene.render.frame_path(frame=f) for f in (2, 3)]
    check(all(os.path.isfile(p) for p in paths), f"each frame at its frame_path: {paths}")
    with open(props.last_export, "rb") as f:
        data = f.read()
    doc = json.loads(data[20:20 + struct.unpack_from("<I", data, 12)[0]])
    times = doc["accessors"][doc["animations"][0]["samplers"][0]["input"]]
    # The keys (frames 1 and 4) at frame / fps: the farm's frame N is Blender's frame N.
    check(abs(times["min"][0] - 1 / 24) < 1e-6 and abs(times["max"][0] - 4 / 24) < 1e-6,
          f"exported keyframe times are frame / fps ({times['min']} .. {times['max']})")
    render_local(BIN, props.last_export, os.path.join(tmp, "local3.exr"), *cli_flags(settings, 3))
    check(identical(BIN, paths[1], os.path.join(tmp, "local3.exr")), "frame 3 is tessera render --frame 3's")
    props.animation = False

    # 4. PNG, and a format the farm does not write.
    scene.render.image_settings.file_format = "PNG"
    scene.render.filepath = os.path.join(tmp, "png", "p_####")
    size = (scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage)
    # Wider than the coordinator's 1280-pixel preview, which it was (a 1920-wide render came
    # back 960 wide).
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 1300, 4, 100
    bpy.ops.tessera.render_on_farm()
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = size
    png = scene.render.frame_path(frame=scene.frame_current)
    with open(png, "rb") as f:
        head = f.read(24)
    check(head[:8] == b"\x89PNG\r\n\x1a\n", f"PNG output at {png}")
    check(struct.unpack(">II", head[16:24]) == (1300, 4), f"the PNG at full size ({struct.unpack('>II', head[16:24])})")
    check(not os.path.exists(png + ".farm.exr"), "the EXR it was made from is gone")
    scene.render.image_settings.file_format = "JPEG"
    scene.render.filepath = os.path.join(tmp, "jpg", "j_####")
    bpy.ops.tessera.render_on_farm()
    jpg = scene.render.frame_path(frame=scene.frame_current)
    with open(jpg, "rb") as f:
        check(f.read(3) == b"\xff\xd8\xff", f"JPEG output converted by Blender at {jpg}")
    check(not os.path.exists(jpg + ".farm.exr"), "the EXR it was made from is gone")

    # Depth of field on a focus object off the centre: its distance along the optical axis,
    # as Cycles measures it (the straight line put it out of focus).
    from mathutils import Vector
    cam = scene.camera
    focus = bpy.data.objects.new("Focus", None)
    scene.collection.objects.link(focus)
    focus.location = cam.matrix_world @ Vector((1.5, 0.0, -4.0))
    cam.data.dof.use_dof, cam.data.dof.focus_object = True, focus
    bpy.context.view_layer.update()
    got = export.camera_settings(scene)["focal_distance"]
    check(abs(got - 4.0) < 1e-4, f"a focus object's distance along the optical axis ({got}, 4 wanted)")
    cam.data.dof.use_dof, cam.data.dof.focus_object = False, None

    # 5. Notes and errors.
    mat = bpy.data.materials.new("Skin")
    mat.use_nodes = True
    mat.node_tree.nodes["Principled BSDF"].inputs["Subsurface"].default_value = 0.3
    mat.node_tree.nodes.new("ShaderNodeTexVoronoi")
    cube.data.materials.clear()
    cube.data.materials.append(mat)
    bpy.ops.object.light_add(type="AREA")
    notes = export.export_notes(scene)
    print("\n".join("      note: " + n for n in notes))
    check(any("Skin" in n and "subsurface" in n for n in notes), "subsurface is listed")
    check(any("TexVoronoi" in n for n in notes), "a node glTF cannot express is listed")
    check(any("area lights" in n for n in notes), "an area light is listed")
    check(any("Disney" in n for n in notes), "Principled's diffuse model is listed")
    props.coordinator = "127.0.0.1:1"
    try:
        bpy.ops.tessera.render_on_farm()
        check(False, "an unreachable coordinator is an error")
    except RuntimeError as e:
        check("Tessera:" in str(e) and ("UNAVAILABLE" in str(e) or "connect" in str(e).lower()),
              f"an unreachable coordinator is an error report: {str(e)[:160]}")
finally:
    farm.stop()
    subprocess.run(["rm", "-rf", tmp])

print("FAILED" if failures else "OK", flush=True)
sys.exit(1 if failures else 0)
