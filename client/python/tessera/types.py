"""What the coordinator says, as Python values: numbers as numbers, times as timezone-aware
datetimes (UTC), states as strings ("QUEUED", "RUNNING", "DONE", "CANCELLED", "FAILED")."""
import dataclasses
import datetime
from typing import List, Optional

import grpc
from google.protobuf.descriptor import FieldDescriptor

from tessera._pb import tessera_pb2 as pb

ENDED = ("DONE", "CANCELLED", "FAILED")


class TesseraError(Exception):
    """An error from the farm: `code` is the gRPC status name ("NOT_FOUND",
    "PERMISSION_DENIED", "INVALID_ARGUMENT", "UNAVAILABLE", ...) or "CLIENT" for one this
    client found, `message` the coordinator's own words."""

    def __init__(self, message, code="CLIENT"):
        super().__init__(message)
        self.message = message
        self.code = code


class JobFailed(TesseraError):
    """Job.wait(): the job ended FAILED or CANCELLED; `status` is its last JobStatus."""

    def __init__(self, status):
        super().__init__(f"job {status.id} {status.state.lower()}" + (f": {status.error}" if status.error else ""),
                         status.state)
        self.status = status


def rpc_error(e, tls):
    """A TesseraError for a grpc.RpcError, with the hint the CLI gives for TLS mismatches."""
    code = e.code() if hasattr(e, "code") else grpc.StatusCode.UNKNOWN
    message = e.details() if hasattr(e, "details") else str(e)
    message = message or code.name
    if code in (grpc.StatusCode.UNAVAILABLE, grpc.StatusCode.DEADLINE_EXCEEDED):
        if not tls and ("Socket closed" in message or "Connection reset" in message):
            message += (" (a coordinator that serves TLS closes plaintext connections: give its certificate "
                        "authority, tls_ca=FILE or $TESSERA_TLS_CA)")
        elif tls and any(w in message for w in ("andshake", "SSL", "ssl")):
            message += (" (the TLS handshake failed: the coordinator may not serve TLS, or tls_ca is not the "
                        "authority that signed its certificate)")
    return TesseraError(message, code.name)


def message_dict(msg):
    """A message's fields by their .proto names, every one (defaults too): numbers as
    numbers (64-bit ones too, unlike protobuf's JSON mapping), enums by name, an unset
    optional field as None."""
    out = {}
    for f in msg.DESCRIPTOR.fields:
        value = getattr(msg, f.name)
        if f.label == FieldDescriptor.LABEL_REPEATED:
            out[f.name] = [message_dict(v) if f.type == FieldDescriptor.TYPE_MESSAGE else v for v in value]
        elif f.type == FieldDescriptor.TYPE_MESSAGE:
            out[f.name] = message_dict(value)
        elif f.has_presence and not msg.HasField(f.name):
            out[f.name] = None
        elif f.type == FieldDescriptor.TYPE_ENUM:
            out[f.name] = f.enum_type.values_by_number[value].name
        else:
            out[f.name] = value
    return out


def _time(msg, field):
    if not msg.HasField(field):
        return None
    return getattr(msg, field).ToDatetime().replace(tzinfo=datetime.timezone.utc)


def _state(value):
    return pb.JobStatus.State.Name(value)


@dataclasses.dataclass
class FrameStatus:
    frame: int
    state: str
    samples_done: int
    samples_total: int
    job_id: str  # the frame's own job ("" until it starts)
    frame_passes_done: int
    tiles_done: int

    @classmethod
    def from_proto(cls, f):
        return cls(f.frame, _state(f.state), f.samples_done, f.samples_total, f.job_id, f.frame_passes_done,
                   f.tiles_done)


@dataclasses.dataclass
class JobStatus:
    id: str
    name: str
    state: str
    error: str
    owner: str
    priority: int
    samples_done: int
    samples_total: int
    tiles_done: int
    tiles_total: int
    passes_total: int
    frame_passes_done: int
    elapsed_seconds: float
    eta_seconds: float
    active_workers: int
    frames: List[FrameStatus]
    frames_done: int
    frames_total: int  # 0: a still
    sequence: str  # for a frame's own job: the sequence it belongs to
    submitted_at: Optional[datetime.datetime]
    started_at: Optional[datetime.datetime]
    ended_at: Optional[datetime.datetime]
    settings: dict  # the RenderSettings message's fields, as the .proto names them

    @classmethod
    def from_proto(cls, s):
        return cls(s.id, s.name, _state(s.state), s.error, s.owner, s.priority, s.samples_done, s.samples_total,
                   s.tiles_done, s.tiles_total, s.passes_total, s.frame_passes_done, s.elapsed_seconds,
                   s.eta_seconds, s.active_workers, [FrameStatus.from_proto(f) for f in s.frames], s.frames_done,
                   s.frames_total, s.sequence, _time(s, "submitted_at"), _time(s, "started_at"),
                   _time(s, "ended_at"), message_dict(s.settings))

    @property
    def ended(self):
        return self.state in ENDED

    @property
    def progress(self):
        """Samples done over the most there can be, 0 to 1 (1 once DONE: adaptive and
        noise-targeted jobs finish early)."""
        if self.state == "DONE":
            return 1.0
        return self.samples_done / self.samples_total if self.samples_total else 0.0


@dataclasses.dataclass
class Event:
    id: int
    time: Optional[datetime.datetime]
    kind: str  # job.submitted, job.done, worker.lost, ...
    job_id: str
    worker: str
    who: str  # the token name that did it ("" for the coordinator itself)
    detail: str

    @classmethod
    def from_proto(cls, e):
        return cls(e.id, _time(e, "time"), e.kind, e.job_id, e.worker, e.who, e.detail)


@dataclasses.dataclass
class Fetched:
    """An image Job.fetch() wrote."""
    path: str
    frame: Optional[int]
    final: bool  # the job (or frame) had ended: its whole film
    frame_passes_done: int
