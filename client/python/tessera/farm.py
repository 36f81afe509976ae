"""A coordinator, seen from Python: Farm (connection, submit, jobs, events) and Job (status,
watch, wait, fetch, cancel, requeue, priority, delete), over the same gRPC service the
`tessera` CLI uses (proto/tessera.proto)."""
import os
import re
import tempfile
import time

import grpc
import xxhash

from tessera import settings as _settings
from tessera._pb import tessera_pb2 as pb
from tessera._pb import tessera_pb2_grpc as pb_grpc
from tessera.bundle import Bundle, SceneError
from tessera.types import Event, Fetched, JobFailed, JobStatus, TesseraError, rpc_error

from tessera._build import MAX_JOB_NAME_BYTES, PROTOCOL_VERSION  # proto/wire.h, at build time
DEFAULT_COORDINATOR = "127.0.0.1:7878"
_LIST_PAGE = 1000
_ID_DIGITS = 16  # a job id: 64 random bits in hex


def frame_path(pattern, frame):
    """`pattern` with its last run of '#' replaced by the frame number, zero-padded to the
    run's length ("shot.####.exr", 7 -> "shot.0007.exr"), as the CLI writes frames."""
    runs = list(re.finditer(r"#+", pattern))
    if not runs:
        return pattern
    m = runs[-1]
    n = len(m.group(0))
    digits = f"-{abs(frame):0{n - 1}d}" if frame < 0 else f"{frame:0{n}d}"
    return pattern[:m.start()] + digits + pattern[m.end():]


def _default_name(scene):
    """A job's name where none is given: the scene's path, or its file name where the path
    is longer than the coordinator takes (MAX_JOB_NAME_BYTES), cut on a character boundary."""
    name = os.fspath(scene)
    if len(name.encode("utf-8", "surrogateescape")) <= MAX_JOB_NAME_BYTES:
        return name
    cut = os.path.basename(name).encode("utf-8", "surrogateescape")[:MAX_JOB_NAME_BYTES]
    return cut.decode("utf-8", "ignore")


def _read_token(path):
    path = os.path.expanduser(path)  # (the package's own example: token_file="~/.tessera/token")
    try:
        with open(path) as f:
            token = f.read().strip()
    except OSError as e:
        raise TesseraError(f"{path}: {e.strerror}") from None
    if not token or any(c.isspace() for c in token):
        raise TesseraError(f"{path}: holds no token (one token, surrounding white space ignored)")
    return token


def _kept_errors(stream, raised):
    """`stream`'s items; an exception it raises is kept in `raised` (gRPC swallows those of a
    request iterator and fails the call with "Exception iterating requests!")."""
    try:
        yield from stream
    except Exception as e:  # noqa: BLE001 (re-raised by the caller, named)
        raised.append(e)
        raise


class Farm:
    """A coordinator. `address` defaults to $TESSERA_COORDINATOR, else 127.0.0.1:7878; the
    token is `token`, else read from `token_file`, $TESSERA_TOKEN_FILE, or $TESSERA_TOKEN;
    `tls_ca` (else $TESSERA_TLS_CA) is the PEM file of the authority that signed the
    coordinator's certificate: with it the connection is TLS. `timeout` bounds each call
    but watch streams; `reconnect_seconds` is how long watch() rides out a coordinator that
    went away (as the CLI's --reconnect-seconds)."""

    def __init__(self, address=None, token=None, token_file=None, tls_ca=None, timeout=60.0,
                 reconnect_seconds=300.0):
        self.address = address or os.environ.get("TESSERA_COORDINATOR") or DEFAULT_COORDINATOR
        if token is None:
            token_file = token_file or os.environ.get("TESSERA_TOKEN_FILE")
            token = _read_token(token_file) if token_file else os.environ.get("TESSERA_TOKEN", "").strip()
        token = token.strip() if token else token  # (as $TESSERA_TOKEN and a file's: "abc\n" was refused by gRPC)
        self._metadata = (("authorization", "Bearer " + token),) if token else ()
        tls_ca = tls_ca or os.environ.get("TESSERA_TLS_CA")
        self.tls = bool(tls_ca)
        options = [("grpc.max_receive_message_length", 1 << 30), ("grpc.max_send_message_length", 64 << 20)]
        if tls_ca:
            try:
                with open(tls_ca, "rb") as f:
                    ca = f.read()
            except OSError as e:
                raise TesseraError(f"{tls_ca}: {e.strerror}") from None
            self._channel = grpc.secure_channel(self.address, grpc.ssl_channel_credentials(ca), options)
        else:
            self._channel = grpc.insecure_channel(self.address, options)
        self._stub = pb_grpc.TesseraStub(self._channel)
        self.timeout = timeout
        self.reconnect_seconds = reconnect_seconds

    def close(self):
        self._channel.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __repr__(self):
        return f"Farm({self.address!r}{', tls' if self.tls else ''})"

    # ---- calls ----------------------------------------------------------------------------

    def _call(self, method, request, timeout=None):
        try:
            return getattr(self._stub, method)(request, timeout=timeout or self.timeout, metadata=self._metadata)
        except grpc.RpcError as e:
            raise rpc_error(e, self.tls) from None

    def _stream(self, method, request, timeout=None):
        return getattr(self._stub, method)(request, timeout=timeout, metadata=self._metadata)

    # ---- jobs -----------------------------------------------------------------------------

    def submit(self, scene, frames=None, name=None, priority=0, **settings):
        """Sends `scene` (.dae, .gltf, .glb: its buffers and images go with it) and returns
        its Job. `frames` makes a sequence ("1-240", "1-240x2", "1,5,9", or a list of
        ints); the render settings are tessera.settings' keywords (samples=, max_depth=,
        resolution=(w, h), ...), with `tessera submit`'s defaults."""
        frame_list = _settings.parse_frames(frames) if frames is not None else []
        if frame_list and settings.get("frame") is not None:
            raise TesseraError("frame= and frames= do not go together (a sequence renders each of its frames)")
        proto_settings, env = _settings.to_proto(scene, frame_list, **settings)
        try:
            bundle = Bundle(scene, env)
        except SceneError as e:
            raise TesseraError(str(e)) from None
        if env:  # workers find it in the bundle, relative to the main file
            proto_settings.environment_map = bundle.files[-1][0]
        raised = []
        try:
            # As the CLI allows: 120 s and a second a MiB (600 s flat failed a 1 GiB scene on a
            # link under 1.7 MiB/s).
            deadline = max(self.timeout, 120 + sum(bundle.sizes) / (1 << 20))
            upload = self._stub.UploadScene(_kept_errors(bundle.chunks(), raised), timeout=deadline,
                                            metadata=self._metadata)
        except SceneError as e:
            raise TesseraError(str(e)) from None
        except grpc.RpcError as e:
            if raised:  # the stream's own error, which gRPC reports as "Exception iterating requests!"
                raise TesseraError(str(raised[0])) from None
            raise rpc_error(e, self.tls) from None
        req = pb.SubmitJobRequest(version=PROTOCOL_VERSION, settings=proto_settings, priority=int(priority),
                                  name=name if name is not None else _default_name(scene), upload_id=upload.upload_id,
                                  frames=frame_list)
        return Job(self, self._call("SubmitJob", req, timeout=max(self.timeout, 120)).id)

    def job(self, id):
        """The job with this id, or the only one whose id starts with it (as git takes
        commits; an ambiguous or unknown prefix raises TesseraError naming it)."""
        if not id or len(id) >= _ID_DIGITS or not re.fullmatch(r"[0-9a-f]+", id):
            return Job(self, id)  # a whole id, a frame's ("ID-fN"): the coordinator says
        matches = [s.id for s in self._list_pages() if s.id.startswith(id)]
        if len(matches) == 1:
            return Job(self, matches[0])
        if not matches:
            raise TesseraError(f"no job id starts with '{id}'", "NOT_FOUND")
        raise TesseraError(f"job id prefix '{id}' is ambiguous: {len(matches)} jobs start with it "
                           f"({', '.join(matches[:3])}{', ...' if len(matches) > 3 else ''}); give more of it")

    def _list_pages(self):
        req = pb.ListJobsRequest(page_size=_LIST_PAGE)
        while True:
            page = self._call("ListJobs", req)
            yield from page.jobs
            if not page.next_page_token:
                return
            req.page_token = page.next_page_token

    def jobs(self):
        """Every job the coordinator keeps, in submission order, as JobStatus. A sequence's
        frames are counted (frames_done, frames_total), not listed: job(id).status() lists them."""
        return [JobStatus.from_proto(s) for s in self._list_pages()]

    def events(self, job=None, after=0, limit=100, oldest=False):
        """The farm's events (oldest first): the last `limit` (at most 1000) after event id
        `after`, or the first `limit` with oldest=True; only `job`'s if given."""
        job_id = job.id if isinstance(job, Job) else (job or "")
        got = self._call("ListEvents", pb.ListEventsRequest(job_id=job_id, after=after, limit=limit, oldest=oldest))
        return [Event.from_proto(e) for e in got.events]


class Job:
    """A job on a farm, by id."""

    def __init__(self, farm, id):
        self.farm = farm
        self.id = id

    def __repr__(self):
        return f"Job({self.id!r})"

    def status(self):
        """The job's JobStatus now (a sequence's with every frame)."""
        return JobStatus.from_proto(self.farm._call("GetJob", pb.JobId(id=self.id)))

    def watch(self):
        """Progress until the job ends: a JobStatus at each change (about four a second
        while it renders), the last one ended. A coordinator that goes away is waited for,
        up to the farm's reconnect_seconds."""
        frames = {}
        gone_since, backoff = None, 0.25
        last = None  # the last message yielded, as bytes: the same one again is not a change
        while True:
            try:
                first = True
                for s in self.farm._stream("WatchJob", pb.JobId(id=self.id)):
                    gone_since, backoff = None, 0.25
                    raw = s.SerializeToString(deterministic=True)
                    if raw == last and not s.frames_changed_only:
                        continue
                    last = raw
                    status = JobStatus.from_proto(s)
                    if first or not s.frames_changed_only:
                        frames = {f.frame: f for f in status.frames}
                    else:
                        frames.update({f.frame: f for f in status.frames})
                    first = False
                    status.frames = sorted(frames.values(), key=lambda f: f.frame)
                    yield status
                    if status.ended:
                        return
                # A stream that ends without an ended job (a coordinator stopping): again.
            except grpc.RpcError as e:
                if e.code() not in (grpc.StatusCode.UNAVAILABLE, grpc.StatusCode.DEADLINE_EXCEEDED):
                    raise rpc_error(e, self.farm.tls) from None
                gone_since = gone_since or time.monotonic()
                if time.monotonic() - gone_since > self.farm.reconnect_seconds:
                    raise rpc_error(e, self.farm.tls) from None
            time.sleep(backoff)
            backoff = min(2.0, backoff * 2)

    def wait(self, check=True):
        """Waits for the job to end and returns its last JobStatus; with check, a job that
        ended FAILED or CANCELLED raises JobFailed (its error in the message)."""
        last = None
        for last in self.watch():
            pass
        if check and last.state != "DONE":
            raise JobFailed(last)
        return last

    def cancel(self):
        """Stops the job (what was rendered is kept); returns its JobStatus."""
        return JobStatus.from_proto(self.farm._call("CancelJob", pb.JobId(id=self.id)))

    def requeue(self):
        """Takes a FAILED or CANCELLED job (a sequence: its unfinished frames) up again."""
        return JobStatus.from_proto(self.farm._call("RequeueJob", pb.JobId(id=self.id)))

    def set_priority(self, priority):
        """Higher runs first."""
        req = pb.SetPriorityRequest(id=self.id, priority=int(priority))
        return JobStatus.from_proto(self.farm._call("SetJobPriority", req))

    def delete(self):
        """Deletes the job's record, images, checkpoints (and scene, if no other job uses
        it); a live job is cancelled first. Returns the bytes freed on the coordinator."""
        return self.farm._call("DeleteJob", pb.JobId(id=self.id)).bytes_freed

    def events(self, after=0, limit=100):
        return self.farm.events(self, after=after, limit=limit)

    # ---- images ---------------------------------------------------------------------------

    def fetch(self, path, frame=None):
        """Writes the job's latest image to `path` (.exr: the whole film, checked against
        the coordinator's hash; .png: the coordinator's preview, at most 1280 pixels wide,
        where `tessera fetch` writes a full-size PNG from the EXR) and returns
        the list of Fetched written. A sequence's: `frame`, or every finished frame with
        `path`'s last run of '#' as its number. Missing folders are made."""
        path = os.fspath(path)
        ext = os.path.splitext(path)[1].lower()
        if ext not in (".exr", ".png"):
            raise TesseraError(f"{path}: an image is .exr or .png")
        status = self.status()
        if status.frames_total == 0:
            if frame is not None:
                raise TesseraError(f"job {self.id} is a still: it has no frame {frame}")
            return [self._fetch_one(path, None, ext)]
        if frame is not None:
            return [self._fetch_one(frame_path(path, frame), frame, ext)]
        if "#" not in path:
            raise TesseraError(f"job {self.id} is a sequence: give frame=N, or a path with #### for its frames")
        return [self._fetch_one(frame_path(path, f.frame), f.frame, ext) for f in status.frames if f.state == "DONE"]

    def _fetch_one(self, path, frame, ext):
        folder = os.path.dirname(os.path.abspath(path))
        os.makedirs(folder, exist_ok=True)
        req = pb.FetchImageRequest(id=self.id, exr=ext == ".exr", png=ext == ".png")
        if frame is not None:
            req.frame = frame
        if ext == ".png":
            img = self.farm._call("FetchImage", req, timeout=max(self.farm.timeout, 600))
            _write_atomic(path, [img.png])
            return Fetched(path, frame, img.final, img.frame_passes_done)
        return self._fetch_exr(path, frame, req)

    def _fetch_exr(self, path, frame, req):
        fd, tmp = tempfile.mkstemp(dir=os.path.dirname(os.path.abspath(path)), prefix=".tessera-fetch-")
        try:
            with os.fdopen(fd, "w+b") as out:
                # A cut stream goes on from what was received, for up to the farm's
                # reconnect_seconds since the last piece came (as `tessera fetch`).
                last_piece, delay = time.monotonic(), 0.25
                while True:
                    header = None
                    try:
                        for c in self.farm._stream("FetchImageChunks", req, timeout=max(self.farm.timeout, 600)):
                            if header is None:
                                header = c
                                if not c.resumed:
                                    out.seek(0)
                                    out.truncate()
                                    req.offset = 0
                                req.version = c.version
                            if c.offset != req.offset or c.offset + len(c.data) > header.size:
                                raise TesseraError(f"job {self.id}: the image came out of order or longer than "
                                                   f"its size ({header.size} bytes)")
                            out.seek(c.offset)
                            out.write(c.data)
                            req.offset = c.offset + len(c.data)
                            last_piece, delay = time.monotonic(), 0.25
                            if c.last:
                                out.flush()
                                return self._finish_exr(out, tmp, path, frame, header, c)
                        error = TesseraError(f"job {self.id}: the image stream ended before its last piece",
                                             "UNAVAILABLE")
                    except grpc.RpcError as e:
                        if e.code() not in (grpc.StatusCode.UNAVAILABLE, grpc.StatusCode.DEADLINE_EXCEEDED):
                            raise rpc_error(e, self.farm.tls) from None
                        error = rpc_error(e, self.farm.tls)
                    if time.monotonic() - last_piece > self.farm.reconnect_seconds:
                        raise error from None
                    time.sleep(delay)
                    delay = min(2 * delay, 5.0)
        finally:
            if os.path.exists(tmp):
                os.unlink(tmp)

    def _finish_exr(self, out, tmp, path, frame, header, last):
        size = out.tell()
        out.seek(0)
        h = xxhash.xxh64()
        while block := out.read(1 << 20):
            h.update(block)
        if size != header.size or h.intdigest() != last.xxh64:
            raise TesseraError(f"job {self.id}: the image received ({size} bytes) does not match the coordinator's "
                               f"({header.size} bytes, its hash): fetch it again")
        out.close()
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
        return Fetched(path, frame, header.final, header.frame_passes_done)


def _write_atomic(path, parts):
    fd, tmp = tempfile.mkstemp(dir=os.path.dirname(os.path.abspath(path)), prefix=".tessera-fetch-")
    try:
        with os.fdopen(fd, "wb") as f:
            for p in parts:
                f.write(p)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        os.unlink(tmp)
        raise
