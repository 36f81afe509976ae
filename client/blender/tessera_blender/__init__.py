"""Tessera render farm: send the open scene to a Tessera farm from Render Properties.

The scene goes as glTF (Blender's own exporter) with what glTF cannot carry (resolution,
frame range, fps, depth of field, the world colour or HDRI) as the farm's settings; frames
come back where the output path says (its #### convention), a still into the Image Editor.
For scripts: bpy.context.scene.tessera (coordinator, token_file, tls_ca, samples,
max_bounces, tile_size, noise_target, animation, aovs, denoise) and bpy.ops.tessera.render_on_farm(),
which in background mode (blender -b) waits for the job and writes the frames before it
returns. docs/blender.md has the details."""
import os
import sys
import tempfile

import bpy

bl_info = {
    "name": "Tessera render farm",
    "author": "Tessera",
    "version": (0, 1, 0),
    "blender": (3, 4, 0),
    "location": "Properties > Render > Tessera render farm",
    "description": "Render the scene on a Tessera farm and get its frames back",
    "category": "Render",
}

_HERE = os.path.dirname(os.path.abspath(__file__))


def client():
    """The Python client: the copy this add-on carries (lib/), else one on sys.path."""
    lib = os.path.join(_HERE, "lib")
    if os.path.isdir(lib) and lib not in sys.path:
        sys.path.insert(0, lib)
    import tessera
    return tessera


from . import export  # noqa: E402
from .farm_job import FarmJob  # noqa: E402


def _describe(s):
    text = f"job {s.id} {s.state.lower()} {100 * s.progress:.0f}%"
    if s.frames_total:
        text += f", frames {s.frames_done}/{s.frames_total}"
    return text + f", {s.active_workers} workers, ETA {s.eta_seconds:.0f} s"


def _print_status(s, last=[None]):  # background mode: a line when the words change
    text = _describe(s)
    if text != last[0]:
        print("Tessera: " + text, flush=True)
        last[0] = text


class TesseraSettings(bpy.types.PropertyGroup):
    coordinator: bpy.props.StringProperty(name="Coordinator", default="127.0.0.1:7878",
                                          description="The coordinator's gRPC address, HOST:PORT")
    token_file: bpy.props.StringProperty(name="Token file", subtype="FILE_PATH",
                                         description="File holding your access token (empty: none, or "
                                                     "$TESSERA_TOKEN_FILE)")
    tls_ca: bpy.props.StringProperty(name="TLS CA", subtype="FILE_PATH",
                                     description="The coordinator's certificate authority (PEM): connect over TLS")
    samples: bpy.props.IntProperty(name="Samples", default=64, min=1, max=1 << 24,
                                   description="Camera samples per pixel (a maximum with a noise target)")
    max_bounces: bpy.props.IntProperty(name="Max bounces", default=16, min=0, max=1 << 16,
                                       description="Scattering events per path (0: emitters only)")
    tile_size: bpy.props.IntProperty(name="Tile size", default=32, min=8, max=4096,
                                     description="Tile size in pixels (the unit of work a worker gets)")
    noise_target: bpy.props.FloatProperty(name="Noise target", default=0.0, min=0.0, max=1e9, precision=4,
                                          description="Stop refining a tile once its estimated relative error is "
                                                      "below this (0: off)")
    animation: bpy.props.BoolProperty(name="Animation", default=False,
                                      description="Render the scene's frame range, not just the current frame")
    aovs: bpy.props.BoolProperty(name="AOV layers", default=False,
                                 description="Alpha, albedo, normal, depth and material index layers in OpenEXR "
                                             "outputs, for the compositor (docs/aov.md)")
    denoise: bpy.props.BoolProperty(name="Denoise", default=False,
                                    description="The coordinator denoises the final image (as Cycles' denoiser "
                                                "does; the noisy one stays in an EXR as noisy.R/G/B: docs/denoise.md)")
    # What the last render did (shown in the panel; read by scripts).
    last_job: bpy.props.StringProperty(name="Last job")
    last_status: bpy.props.StringProperty(name="Last status")
    last_export: bpy.props.StringProperty(name="Last export", subtype="FILE_PATH")


class TESSERA_OT_render_on_farm(bpy.types.Operator):
    """Export the scene as glTF, render it on the Tessera farm, and write its frames where the
    output path says"""
    bl_idname = "tessera.render_on_farm"
    bl_label = "Render on farm"

    _timer = None
    _job = None
    _thread = None

    def _prepare(self, context):
        scene = context.scene
        props = scene.tessera
        tessera = client()
        for note in export.export_notes(scene):
            self.report({"WARNING"}, "Tessera: " + note)
        frames = export.frames(scene, props.animation)
        outputs = {f: export.output_path(scene, f) for f in frames}
        folder = tempfile.mkdtemp(prefix="tessera-blender-")
        path = export.export_gltf(scene, os.path.join(folder, "scene.glb"), props.animation)
        props.last_export = path
        farm_args = {"address": props.coordinator}
        if props.token_file:
            farm_args["token_file"] = bpy.path.abspath(props.token_file)
        if props.tls_ca:
            farm_args["tls_ca"] = bpy.path.abspath(props.tls_ca)
        printer = _print_status if bpy.app.background else None
        return FarmJob(tessera, farm_args, path, frames, outputs, export.render_settings(scene, props, folder),
                       export.blend_name(), on_status=printer)

    def _finish(self, context, state):
        scene = context.scene
        props = scene.tessera
        props.last_job = state["job"] or ""
        for frame, got, wanted in state["written"]:
            if got != wanted:  # a format the farm does not write: Blender converts the EXR
                image = bpy.data.images.load(got)
                image.save_render(wanted, scene=scene)
                bpy.data.images.remove(image)
                os.unlink(got)
        if state["error"]:
            props.last_status = "failed: " + state["error"]
            self.report({"ERROR"}, "Tessera: " + state["error"])
            return {"CANCELLED"}
        paths = [w for _, _, w in state["written"]]
        props.last_status = f"done: {len(paths)} frame{'s' if len(paths) != 1 else ''} written"
        self.report({"INFO"}, f"Tessera: job {props.last_job} done, {', '.join(paths[:3])}"
                              f"{' ...' if len(paths) > 3 else ''}")
        if len(paths) == 1 and not bpy.app.background:
            image = bpy.data.images.load(paths[0], check_existing=True)
            image.reload()
            for area in context.screen.areas if context.screen else ():
                if area.type == "IMAGE_EDITOR":
                    area.spaces.active.image = image
                    break
        return {"FINISHED"}

    def execute(self, context):
        try:
            job = self._prepare(context)
        except Exception as e:  # noqa: BLE001 (an export or settings error, as a report)
            self.report({"ERROR"}, f"Tessera: {e}")
            return {"CANCELLED"}
        if bpy.app.background:  # scripts: wait here, printing progress
            job.start().join()
            return self._finish(context, job.snapshot())
        self._job = job
        self._thread = job.start()
        wm = context.window_manager
        self._timer = wm.event_timer_add(0.25, window=context.window)
        wm.progress_begin(0, 1000)
        wm.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        if event.type == "ESC":
            self._job.cancel_requested = True
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        state = self._job.snapshot()
        s = state["status"]
        if s is not None:
            context.workspace.status_text_set("Tessera: " + _describe(s) + " (Esc cancels)")
            context.window_manager.progress_update(int(1000 * s.progress))
            context.scene.tessera.last_status = _describe(s)
        if not state["done"]:
            return {"PASS_THROUGH"}
        context.window_manager.event_timer_remove(self._timer)
        context.window_manager.progress_end()
        context.workspace.status_text_set(None)
        return self._finish(context, state)


class TESSERA_PT_farm(bpy.types.Panel):
    bl_label = "Tessera render farm"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "render"

    def draw(self, context):
        props = context.scene.tessera
        col = self.layout.column()
        for name in ("coordinator", "token_file", "tls_ca", "samples", "max_bounces", "tile_size", "noise_target",
                     "animation", "aovs", "denoise"):
            col.prop(props, name)
        col.operator(TESSERA_OT_render_on_farm.bl_idname, icon="RENDER_STILL")
        if props.last_status:
            col.label(text=props.last_status)


_CLASSES = (TesseraSettings, TESSERA_OT_render_on_farm, TESSERA_PT_farm)


def register():
    for c in _CLASSES:
        bpy.utils.register_class(c)
    bpy.types.Scene.tessera = bpy.props.PointerProperty(type=TesseraSettings)


def unregister():
    del bpy.types.Scene.tessera
    for c in reversed(_CLASSES):
        bpy.utils.unregister_class(c)
