"""Tessera's Python client: drive a render farm from a pipeline.

    import tessera

    farm = tessera.Farm("render-head:7878", token_file="~/.tessera/token", tls_ca="ca.pem")
    job = farm.submit("shot.glb", frames="1-240", samples=256, resolution=(1920, 1080))
    for s in job.watch():
        print(f"{s.state} {100 * s.progress:.0f}% frames {s.frames_done}/{s.frames_total}")
    job.fetch("out/shot.####.exr")   # every finished frame
    print(job.status().ended_at)     # a datetime

Farm(address, token=, token_file=, tls_ca=): address, token and CA as the CLI takes them
(else $TESSERA_COORDINATOR, $TESSERA_TOKEN_FILE / $TESSERA_TOKEN, $TESSERA_TLS_CA).
submit(scene, frames=None, name=None, priority=0, **settings) -> Job; the settings are
`tessera submit`'s flags by name (tessera.settings), so the farm's image is the one
`tessera render` makes with the same flags, bit for bit. jobs(), job(id or prefix),
events(). Job: status(), watch(), wait(), fetch(path, frame=None), cancel(), requeue(),
set_priority(n), delete(), events(). Errors raise TesseraError with the coordinator's
message and its gRPC code; Job.wait() raises JobFailed for a FAILED or CANCELLED job.
"""
import os as _os

if _os.path.realpath(_os.path.dirname(__file__)).endswith(_os.path.join("client", "python", "tessera")):
    raise ImportError("this is tessera's source folder: import the built package (PYTHONPATH=build/python), "
                      "which has the generated gRPC stubs")

from tessera._build import VERSION as __version__  # noqa: E402
from tessera.farm import Farm, Job, frame_path  # noqa: E402
from tessera.settings import DEFAULTS, parse_frames  # noqa: E402
from tessera.types import Event, Fetched, FrameStatus, JobFailed, JobStatus, TesseraError  # noqa: E402

__all__ = ["Farm", "Job", "JobStatus", "FrameStatus", "Event", "Fetched", "TesseraError", "JobFailed", "DEFAULTS",
           "parse_frames", "frame_path", "__version__"]
