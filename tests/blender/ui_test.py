"""The add-on in Blender's interface (run by ui-test.sh under Xvfb: blender --factory-startup
--python ui_test.py -- BIN BUILD SRC RESULT.json). "Render on farm" is invoked as the panel's
button does, in a window, against a loopback farm; while the job runs, Blender keeps
handling its timers (the interface is not frozen) and the status bar and panel show the
job's progress; at the end the frame is on disk and in the Image Editor. Writes RESULT.json
({"failures": [...], "log": [...]}) and quits: the shell script judges."""
import json
import os
import sys
import time

import bpy

argv = sys.argv[sys.argv.index("--") + 1:]
BIN, BUILD, SRC, RESULT = (os.path.abspath(a) for a in argv[:4])
sys.path.insert(0, os.path.join(SRC, "tests", "python"))
from local_farm import LocalFarm  # noqa: E402

log, failures = [], []
state = {"ticks": 0, "ticks_running": 0, "texts": set(), "started": None}


def check(ok, what):
    log.append(("ok    " if ok else "FAIL  ") + what)
    if not ok:
        failures.append(what)


def finish():
    with open(RESULT, "w") as f:
        json.dump({"failures": failures, "log": log}, f)
    farm.stop()
    bpy.ops.wm.quit_blender()


bpy.ops.preferences.addon_install(filepath=os.path.join(BUILD, "blender", "tessera_blender.zip"))
bpy.ops.preferences.addon_enable(module="tessera_blender")
farm = LocalFarm(BIN, workers=1, threads=1)
scene = bpy.context.scene
scene.tessera.coordinator = farm.address
scene.tessera.samples, scene.tessera.tile_size = 2048, 16
scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 80, 60, 100
scene.render.image_settings.file_format = "PNG"
scene.render.filepath = os.path.join(farm.dir, "ui", "still_####")


def start():
    window = bpy.context.window_manager.windows[0]
    screen = window.screen
    areas = sorted(screen.areas, key=lambda a: a.width * a.height)
    image_area = areas[0]
    image_area.type = "IMAGE_EDITOR"  # the smallest area shows the result
    props_area = next(a for a in screen.areas if a.type == "PROPERTIES")
    with bpy.context.temp_override(window=window, screen=screen, area=props_area):
        result = bpy.ops.tessera.render_on_farm("INVOKE_DEFAULT")
    check("RUNNING_MODAL" in result, f"the operator runs modal in the interface ({result})")
    state["started"] = time.time()
    state["image_area"] = image_area
    bpy.app.timers.register(poll, first_interval=0.05)
    return None


def poll():
    state["ticks"] += 1
    state.setdefault("times", []).append(round(time.time() - state["started"], 2))
    status = scene.tessera.last_status
    if status:
        state["texts"].add(status)
    if status.startswith("job") and "running" in status:
        state["ticks_running"] += 1
    if status.startswith("done") or status.startswith("failed") or time.time() - state["started"] > 120:
        check(status.startswith("done"), f"the job ends done ({status})")
        check(state["ticks_running"] >= 3, f"Blender ran its timers {state['ticks_running']} times while the job "
              f"rendered ({state['ticks']} in {time.time() - state['started']:.1f} s in all): the interface is not "
              "frozen")
        check(any("%" in t for t in state["texts"]), f"progress was shown ({sorted(state['texts'])[:3]})")
        path = scene.render.frame_path(frame=scene.frame_current)
        check(os.path.isfile(path), f"the frame is written at {path}")
        image = state["image_area"].spaces.active.image
        check(image is not None and os.path.abspath(bpy.path.abspath(image.filepath)) == path,
              f"the Image Editor shows it ({image.filepath if image else None})")
        log.append("      tick times (s): " + " ".join(str(t) for t in state["times"][:40]))
        finish()
        return None
    return 0.05


bpy.app.timers.register(start, first_interval=1.0)
