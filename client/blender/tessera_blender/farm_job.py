"""One "Render on farm": submit the exported scene with the Python client, follow it, and
write each frame where Blender's output path says as soon as it is done. Runs in a thread
in the UI (the operator polls `state`) and inline in background mode; touches no bpy data,
so the thread never races Blender."""
import os
import threading
import time


class FarmJob:
    """submit -> watch -> fetch, reporting into `state` (a dict guarded by `lock`):
    status (the last tessera.JobStatus), written (paths), error (a message), done."""

    def __init__(self, tessera, farm_args, scene_path, frames, outputs, settings, name, on_status=None):
        self.tessera = tessera
        self.farm_args = farm_args
        self.scene_path = scene_path
        self.frames = frames  # [frame], one for a still
        self.outputs = outputs  # frame -> (path Blender wants, ".exr"/".png" asked of the farm)
        self.settings = settings
        self.name = name
        self.lock = threading.Lock()
        self.state = {"status": None, "written": [], "error": None, "done": False, "job": None}
        self.cancel_requested = False
        self.on_status = on_status  # called (in the thread) with each JobStatus

    def run(self):
        try:
            self._run()
        except self.tessera.TesseraError as e:
            self._set(error=e.message)
        except Exception as e:  # noqa: BLE001 (the UI must hear of anything)
            self._set(error=f"{type(e).__name__}: {e}")
        finally:
            self._set(done=True)

    def start(self):
        t = threading.Thread(target=self.run, name="tessera-farm-job", daemon=True)
        t.start()
        return t

    def snapshot(self):
        with self.lock:
            return dict(self.state, written=list(self.state["written"]))

    def _set(self, **kw):
        with self.lock:
            self.state.update(kw)

    def _run(self):
        with self.tessera.Farm(**self.farm_args) as farm:
            if len(self.frames) == 1:
                job = farm.submit(self.scene_path, frame=self.frames[0], name=self.name, **self.settings)
            else:
                job = farm.submit(self.scene_path, frames=self.frames, name=self.name, **self.settings)
            self._set(job=job.id)
            written = set()
            last = None
            for status in job.watch():
                last = status
                self._set(status=status)
                if self.on_status:
                    self.on_status(status)
                if self.cancel_requested:
                    job.cancel()
                    self.cancel_requested = False
                if status.frames_total:
                    for f in status.frames:
                        if f.state == "DONE" and f.frame not in written:
                            self._write(job, f.frame)
                            written.add(f.frame)
            if last is None or last.state != "DONE":
                reason = f": {last.error}" if last is not None and last.error else ""
                state = last.state.lower() if last is not None else "lost"
                raise self.tessera.TesseraError(f"job {job.id} {state}{reason}", "FAILED")
            if not last.frames_total:
                self._write(job, None)

    def _write(self, job, frame):
        key = frame if frame is not None else self.frames[0]
        path, ext = self.outputs[key]
        target = path if os.path.splitext(path)[1].lower() == ext else path + ".farm" + ext
        for attempt in range(3):
            got = job.fetch(target, frame=frame)[0]
            if got.final:
                break
            time.sleep(0.5)  # a coordinator restarted since the frame ended: fetch again
        with self.lock:
            self.state["written"].append((key, target, path))
