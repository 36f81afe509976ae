"""Render settings as Python keywords: the flags of `tessera submit`, by name, with the same
defaults, so that a job submitted from Python renders the image `tessera render` makes
with the same flags, bit for bit.

    samples=64          -s        camera samples per pixel (a maximum with adaptive or noise_target)
    light_samples=1     -l        samples per area light per shading point
    max_depth=16        -m        scattering events per path (0: emitters only)
    resolution=(480, 360) -r      width, height
    adaptive=None       -a        (batch, tolerance): CS184's adaptive sampling
    lens_radius=0.0     -b        thin-lens radius (0: pinhole)
    focal_distance=4.7  -d        focal distance
    window=None         -p        (x, y, w, h): only this cell, lower-left pixel, y from the bottom
    seed=0              --seed
    frame=None          --frame   a still's frame number (animation time)
    camera="auto"       --camera  "cs184", "file", or "auto" (file for glTF, cs184 for COLLADA)
    camera_path=None    --camera-path  a dict, a JSON string, or a path to a JSON file
    turntable=None      --turntable    frames one turn takes
    env=None            -e        an environment map (.exr/.hdr): sent with the scene
    env_color=None      --env-color    (r, g, b)
    env_strength=1.0, env_rotate=0.0, exposure=0.0, no_default_env=False
    animation="", fps=24.0, pass_spp=16, tile=32, noise_target=0.0, no_nee=False, no_mis=False
    aov=None            --aov     "albedo,normal,depth,alpha,id,halves", a list of them, "all" or "denoising": EXR layers
    denoise=False       --denoise the coordinator denoises the final image (adds aov "denoising")
    light_tracer="auto" --light-tracer  "auto", "on" or "off": light paths for caustics

Unknown keywords raise TypeError naming them; values the coordinator refuses come back as
a TesseraError carrying its message (it checks every setting, as `tessera render` does).
"""
import json
import numbers
import os
import re

from tessera._pb import tessera_pb2 as pb

DEFAULTS = {
    "samples": 64,
    "light_samples": 1,
    "max_depth": 16,
    "resolution": (480, 360),
    "adaptive": None,
    "lens_radius": 0.0,
    "focal_distance": 4.7,
    "window": None,
    "seed": 0,
    "frame": None,
    "camera": "auto",
    "camera_path": None,
    "turntable": None,
    "env": None,
    "env_color": None,
    "env_strength": 1.0,
    "env_rotate": 0.0,
    "exposure": 0.0,
    "no_default_env": False,
    "animation": "",
    "fps": 24.0,
    "pass_spp": 16,
    "tile": 32,
    "noise_target": 0.0,
    "no_nee": False,
    "no_mis": False,
    "aov": None,
    "denoise": False,
    "light_tracer": "auto",
}
LIGHT_TRACER = {"off": 0, "on": 1, "auto": 2}  # RenderSettings.light_tracer
# --aov's names and their bits (core/render/aov.h).
AOVS = {"alpha": 1, "albedo": 2, "normal": 4, "depth": 8, "id": 16, "halves": 32}
ALL_AOVS = 1 | 2 | 4 | 8 | 16  # "all": the compositing passes
DENOISING_AOVS = 2 | 4 | 8 | 32  # "denoising": what the denoiser reads


def aov_bits(value):
    """--aov's list ("albedo,normal", a list of names, "all" or "denoising") as the settings' bits."""
    if not value:
        return 0
    names = value.split(",") if isinstance(value, str) else list(value)
    if not all(isinstance(n, str) for n in names):
        raise ValueError(f"aov: {value!r} is not a list of AOV names")
    bits = 0
    for name in (n.strip() for n in names):
        if name == "all":
            bits |= ALL_AOVS
        elif name == "denoising":
            bits |= DENOISING_AOVS
        elif name in AOVS:
            bits |= AOVS[name]
        elif name:
            raise ValueError(f"aov: '{name}' is not an AOV (alpha, albedo, normal, depth, id, halves, all or denoising)")
    return bits

def whole(name, value, lo=-(1 << 31), hi=(1 << 31) - 1):
    """`value` as an int where it is a whole number within [lo, hi] (the proto field's
    range); a ValueError naming `name` otherwise. 2.7 samples became 2, True became 1, and
    a number past the field's range raised protobuf's own "Value out of range"."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"{name}: must be a whole number (got {value!r})")
    if isinstance(value, float) and not value.is_integer():
        raise ValueError(f"{name}: must be a whole number (got {value!r})")
    n = int(value)
    if n < lo or n > hi:
        raise ValueError(f"{name}: {n} is beyond {lo}..{hi}")
    return n


MAX_FRAMES = 100000  # core/render/frames.h's kMaxFrames
MAX_FRAME = 1000000  # RenderSettings::kMaxFrame


def parse_frames(spec):
    """Frames as `tessera submit --frames` reads them: "1-240", "1-240x2", "1,5,9" or a
    mix ("1-10,20,30-40x5"), in the order given; or an iterable of ints. Raises ValueError
    naming the part that is wrong."""
    if not isinstance(spec, str):
        try:
            frames = [whole("frames", f) for f in spec]
        except TypeError:
            raise ValueError(f"frames: {spec!r} is not \"A-B\", \"1,5,9\" nor a list of frames") from None
    else:
        frames = []
        for part in spec.split(","):
            m = re.fullmatch(r"\s*(-?\d+)(?:\s*-\s*(-?\d+)(?:\s*x\s*(\d+))?)?\s*", part)
            if not m:
                raise ValueError(f"frames: '{part}' is not N, A-B or A-BxSTEP")
            a = int(m.group(1))
            b = int(m.group(2)) if m.group(2) is not None else a
            step = int(m.group(3)) if m.group(3) is not None else 1
            if b < a:
                raise ValueError(f"frames: '{part}' runs backwards")
            if step < 1:
                raise ValueError(f"frames: '{part}': the step must be at least 1")
            if (b - a) // step + 1 + len(frames) > MAX_FRAMES:
                raise ValueError(f"frames: more than {MAX_FRAMES} frames")
            frames.extend(range(a, b + 1, step))
    if not frames:
        raise ValueError("frames: none given")
    seen = set()
    for f in frames:
        if abs(f) > MAX_FRAME:
            raise ValueError(f"frames: {f} is beyond +-{MAX_FRAME}")
        if f in seen:
            raise ValueError(f"frames: {f} is given twice")
        seen.add(f)
    if len(frames) > MAX_FRAMES:
        raise ValueError(f"frames: more than {MAX_FRAMES} frames")
    return frames


def _camera_path_json(value, turntable):
    path = {}
    if value is not None:
        if isinstance(value, dict):
            path = dict(value)
        elif isinstance(value, str) and value.lstrip().startswith("{"):
            path = json.loads(value)
        else:
            with open(value) as f:
                path = json.load(f)
    if turntable is not None and float(turntable) != 0:  # (0: none, as --turntable 0)
        # As the CLI: frame 0 faces as the still, whatever the frames (one rendered again
        # alone is the sequence's).
        path["turntable"] = {"frames": float(turntable), "start": 0.0}
    return json.dumps(path) if path else ""


def to_proto(scene, frames=None, **kwargs):
    """(RenderSettings message, environment map path on disk or None) for `scene` and the
    keywords above."""
    unknown = sorted(set(kwargs) - set(DEFAULTS))
    if unknown:
        raise TypeError(f"unknown render setting{'s' if len(unknown) > 1 else ''}: {', '.join(unknown)} "
                        f"(known: {', '.join(sorted(DEFAULTS))})")
    s = dict(DEFAULTS, **kwargs)
    p = pb.RenderSettings()
    p.spp = whole("samples", s["samples"])
    p.light_samples = whole("light_samples", s["light_samples"])
    p.max_depth = whole("max_depth", s["max_depth"])
    p.adaptive_batch, p.adaptive_tolerance = 32, 0.05
    if s["adaptive"] is not None:
        batch, tolerance = s["adaptive"]
        p.adaptive = True
        p.adaptive_batch = whole("adaptive batch", batch)
        p.adaptive_tolerance = float(tolerance)
    p.seed = whole("seed", s["seed"], 0, (1 << 64) - 1)
    if s["frame"] is not None:
        p.frame = whole("frame", s["frame"])
    if not float(s["fps"]) > 0:  # (the message reads 0 as "not set": 24 was rendered)
        raise ValueError(f"fps: must be > 0 (got {s['fps']!r})")
    p.fps = float(s["fps"])
    p.camera_path = _camera_path_json(s["camera_path"], s["turntable"])
    p.animation = str(s["animation"])
    if s["env_color"] is not None:
        p.environment.extend(float(c) for c in s["env_color"])
    p.no_default_environment = bool(s["no_default_env"])
    if float(s["env_strength"]) != 1.0:
        p.environment_strength = float(s["env_strength"])
    p.environment_rotation = float(s["env_rotate"])
    p.exposure = float(s["exposure"])
    p.pass_spp = whole("pass_spp", s["pass_spp"])
    width, height = s["resolution"]
    p.width, p.height = whole("resolution", width, 0), whole("resolution", height, 0)
    p.lens_radius = float(s["lens_radius"])
    p.focal_distance = float(s["focal_distance"])
    camera = s["camera"]
    if camera not in ("auto", "cs184", "file"):
        raise ValueError(f"camera: '{camera}' is not auto, cs184 or file")
    collada = os.path.splitext(str(scene))[1].lower() == ".dae"
    p.framing = pb.RenderSettings.FILE if camera == "file" or (camera == "auto" and not collada) \
        else pb.RenderSettings.CS184
    if s["window"] is not None:
        # CS184's -p x y w h: lower-left pixel, y counted from the bottom.
        x, y, w, h = (whole("window", v) for v in s["window"])
        if w < 1 or h < 1 or x < 0 or y < 0 or x + w > p.width or y + h > p.height:
            raise ValueError(f"window: ({x}, {y}, {w}, {h}) is not a cell of the {p.width} x {p.height} image")
        p.window.x, p.window.y, p.window.w, p.window.h = x, p.height - (y + h), w, h
    p.tile_size = whole("tile", s["tile"])
    p.noise_target = float(s["noise_target"])
    p.no_nee = bool(s["no_nee"])
    p.no_mis = bool(s["no_mis"])
    p.aovs = aov_bits(s["aov"])
    p.denoise = bool(s["denoise"])
    if p.denoise:
        p.aovs |= DENOISING_AOVS
    if s["light_tracer"] not in LIGHT_TRACER:
        raise ValueError(f"light_tracer: '{s['light_tracer']}' is not auto, on or off")
    p.light_tracer = LIGHT_TRACER[s["light_tracer"]]
    env = os.path.abspath(s["env"]) if s["env"] else None
    return p, env


# The `tessera render` / `tessera submit` flag of each keyword, and how many values it takes.
FLAGS = {
    "samples": ("-s", 1), "light_samples": ("-l", 1), "max_depth": ("-m", 1), "resolution": ("-r", 2),
    "adaptive": ("-a", 2), "lens_radius": ("-b", 1), "focal_distance": ("-d", 1), "window": ("-p", 4),
    "seed": ("--seed", 1), "frame": ("--frame", 1), "camera": ("--camera", 1), "camera_path": ("--camera-path", 1),
    "turntable": ("--turntable", 1), "env": ("-e", 1), "env_color": ("--env-color", 3),
    "env_strength": ("--env-strength", 1), "env_rotate": ("--env-rotate", 1), "exposure": ("--exposure", 1),
    "no_default_env": ("--no-default-env", 0), "animation": ("--animation", 1), "fps": ("--fps", 1),
    "pass_spp": ("--pass-spp", 1), "tile": ("--tile", 1), "noise_target": ("--noise-target", 1),
    "no_nee": ("--no-nee", 0), "no_mis": ("--no-mis", 0), "aov": ("--aov", 1),
    "denoise": ("--denoise", 0), "light_tracer": ("--light-tracer", 1),
}


def cli_flags(**kwargs):
    """The `tessera render` flags that make the image these keywords make on the farm
    (floats written exactly: repr), defaults left out. camera_path must be a file here."""
    unknown = sorted(set(kwargs) - set(DEFAULTS))
    if unknown:
        raise TypeError(f"unknown render setting{'s' if len(unknown) > 1 else ''}: {', '.join(unknown)}")
    out = []
    for key, value in kwargs.items():
        if value is None or value == DEFAULTS[key]:
            continue
        flag, n = FLAGS[key]
        if n == 0:
            if value:
                out.append(flag)
            continue
        if key == "aov" and not isinstance(value, str):
            value = ",".join(value)
        values = list(value) if n > 1 else [value]
        out += [flag] + [repr(float(v)) if isinstance(v, float) else str(v) for v in values]
    return out
