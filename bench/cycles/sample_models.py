#!/usr/bin/python3
"""Public glTF sample models in Tessera and in Blender 3.4's Cycles, as Blender imports them.

Each model is rendered by both at the same camera (the file's first camera; without one,
Tessera's three-quarter framing of the bounds, which bench/cycles/gltf_to_cycles.py
reproduces) under the same environment map (scenes/sky.hdr, as compare_gltf.py), at its
rest pose (Tessera's still; Blender imports no animation: --rest-pose 1). Per model:
  - relMSE of Tessera against Cycles over the whole image, in luminance: mean over pixels of
    (T - C)^2 / (C^2 + 0.01), both renderers' noise included;
  - ratio: mean luminance T / C over the whole image (sky and ground included), and over
    the model's own pixels (covered in both: coverage from a 16 spp emitters-only Tessera
    render against uniform backgrounds of 1 and of 0.5, and Cycles' alpha with a transparent
    film);
  - silhouette: sum |coverage T - coverage C| / sum coverage C, both blurred 5 x 5 (the
    noise of stochastic transparency); edge noise is a percent or less, a framing or pose
    difference makes it large;
  - noise: Tessera's standard error of its whole-image mean luminance (variance channel);
  - the glTF extensions and features the file uses;
  - verdict: "ok" when |ratio - 1| <= --tolerance (2%) and the silhouettes agree (within
    --silhouette, 5%) for a model whose features both renderers render the same way.
    Otherwise the Lambertian control: the same scene with every material made Lambertian
    (exactly so in glTF's model and in Cycles; lambert_copy) at --control-spp, which keeps
    geometry, pose, camera, textures, alpha, normal maps and light and drops the BSDFs. If
    it agrees (image and model's pixels within the tolerance), the model "differs" by its
    BSDFs: by a feature with a known, documented difference (DIFFERS below, docs/gltf.md),
    or by Principled v1's dielectric and Cycles 3.4's separable Smith G (WHY_BSDF, measured
    in docs/gallery.md; within BSDF_RANGE). Anything else is "FAIL". A difference of
    shape or normals the control keeps (NOT_BSDF: morph targets without NORMAL) is
    "differs" unchecked. A file Tessera
    refuses is listed with its error. Debian's Blender has no Draco decoder: a Draco file's
    Cycles image is that of its uncompressed twin in the same run, when there is one.
Writes OUT/sample-models.md (and .json), OUT/NAME-{tessera,cycles}.exr, one side-by-side
JPEG per model (Tessera left, Cycles right, sRGB, clamped) in --gallery (default OUT) as
sample-NAME.jpg, prints the table; exits 1 if a judged model misses the aim.

Usage: bench/cycles/sample_models.py [MODEL.gltf|.glb ...] [--models DIR] [--spp 256]
          [--width 320] [--height 240] [--threads 2] [--env scenes/sky.hdr]
          [--control-spp 64] [--out build/report/sample-models] [--gallery docs/gallery]
          [--tolerance 0.02] [--silhouette 0.05] [--skip NAMES]
       bench/cycles/sample_models.py --furnace [--spp 1024]
--models is searched recursively for .gltf and .glb, less the deliberately broken test
files (--skip: folder or file names, comma-separated). The models: the Khronos glTF Sample
Models (https://github.com/KhronosGroup/glTF-Sample-Models; licences per model), e.g. as
assimp (test/models/glTF2) and bevy (assets/models) carry them; docs/gallery.md.
--furnace instead renders white planes of five materials in a white furnace at five angles
(each pixel the BSDF's directional albedo) in both: the BSDFs alone, OUT/furnace.md.
Needs blender (apt-get install blender), python3-numpy, python3-pil and a built tree.
"""
import argparse
import base64
import json
import math
import os
import re
import shutil
import struct
import subprocess
import sys
import tempfile
import time
import urllib.parse

import numpy
from PIL import Image

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from compare_gltf import BIN, HERE, ROOT, blender_env, gltf_json  # noqa: E402

BROKEN = ("IndexOutOfRange,wrongTypes,MissingBin,SchemaFailures,IncorrectVertexArrays,RecursiveNodes,"
          "TestNoRootNode,BoxWithInfinites,BoxBadNormals,issue_3269")

# Features the two renderers render differently, by design or by Blender 3.4's importer and
# Principled v1 (docs/gltf.md): short name, why. A model that uses one is not judged; it is
# "differs" when its Lambertian control agrees (below), "FAIL" when not (NOT_BSDF aside).
DIFFERS = {
    "KHR_materials_clearcoat": ("clearcoat", "Principled v1's clearcoat is a GTR1 lobe at 0.25 x the weight over an "
                                "undimmed base; glTF's coat dims the base by its Fresnel"),
    "KHR_materials_sheen": ("sheen", "the importer makes Principled v1's Sheen, not glTF's Charlie lobe"),
    "KHR_materials_specular": ("specular", "the importer maps it to Principled v1's Specular and Specular Tint"),
    "KHR_materials_anisotropy": ("anisotropy", "Tessera renders it without the lobe (warned)"),
    "KHR_materials_iridescence": ("iridescence", "Tessera renders it without the lobe (warned)"),
    "KHR_materials_dispersion": ("dispersion", "Tessera renders it without dispersion (warned)"),
    "KHR_materials_diffuse_transmission": ("diffuse transmission", "Tessera renders it without the lobe (warned)"),
    "KHR_materials_unlit": ("unlit", "Tessera renders unlit materials lit (warned)"),
    "KHR_materials_pbrSpecularGlossiness": ("specular-glossiness", "Tessera renders the metallic-roughness fallback "
                                            "(warned); Blender the specular-glossiness material"),
    "thin-walled transmission": ("thin-walled", "KHR_materials_transmission without a volume is thin-walled in glTF; "
                                 "Blender refracts a solid"),
    "morph without NORMAL": ("morph normals", "the morph targets move positions but carry no NORMAL: glTF keeps "
                             "the file's normals; Blender's custom normals turn with the morphed faces"),
}
# Differences of shape or shading normals, which the Lambertian control keeps: not checked by it.
NOT_BSDF = {"morph without NORMAL"}
# Where the images differ but the Lambertian control agrees, the difference is the BSDFs'.
# Measured on a white plane in a white furnace (docs/gallery.md): Tessera / Cycles from
# 0.85 (rough dielectric at 70 degrees) to 1.16 (rough metal at 70 degrees); a ratio of the
# model's pixels outside BSDF_RANGE is more than the BSDFs explain.
WHY_BSDF = ("BSDF", "with every material Lambertian the two agree: Principled v1's dielectric is Disney diffuse (with "
            "retro-reflection) not weighted by 1 - F, brighter than glTF's Lambert x (1 - F) + specular, and Cycles "
            "3.4's GGX uses the separable Smith G1 x G1, darker on rough surfaces seen obliquely than glTF's "
            "height-correlated G")
BSDF_RANGE = (0.84, 1.18)


def features(g):
    """The extensions and core features a glTF document uses, for the table and DIFFERS."""
    out = list(g.get("extensionsUsed", []))
    mats = g.get("materials", [])
    prims = [p for m in g.get("meshes", []) for p in m.get("primitives", [])]
    for name, used in (
            ("camera", g.get("cameras")), ("skin", g.get("skins")), ("morph", any(p.get("targets") for p in prims)),
            ("animation", g.get("animations")), ("textures", g.get("textures")),
            ("vertex colours", any("COLOR_0" in p.get("attributes", {}) for p in prims)),
            ("alpha blend", any(m.get("alphaMode") == "BLEND" for m in mats)),
            ("alpha mask", any(m.get("alphaMode") == "MASK" for m in mats)),
            ("emissive", any(any(m.get("emissiveFactor", [0, 0, 0])) for m in mats)),
            ("default material", any("material" not in p for p in prims)),
            ("metal", any(m.get("pbrMetallicRoughness", {}).get("metallicFactor", 1) > 0 for m in mats)),
            ("dielectric", any(m.get("pbrMetallicRoughness", {}).get("metallicFactor", 1) < 1 or
                               "metallicRoughnessTexture" in m.get("pbrMetallicRoughness", {}) for m in mats))):
        if used:
            out.append(name)
    for m in mats:
        ext = m.get("extensions", {})
        if "KHR_materials_transmission" in ext and "KHR_materials_volume" not in ext:
            out.append("thin-walled transmission")
            break
    for n in g.get("nodes", []):  # a still's weights: the node's, else the mesh's
        mesh = g.get("meshes", [])[n["mesh"]] if "mesh" in n else {}
        weights = n.get("weights") or mesh.get("weights") or []
        if any(w and "NORMAL" in p.get("attributes", {}) and "POSITION" in t and "NORMAL" not in t
               for p in mesh.get("primitives", []) for t, w in zip(p.get("targets", []), weights)):
            out.append("morph without NORMAL")
            break
    return out


def find_models(a):
    files = list(a.files)
    skip = set(filter(None, a.skip.split(",")))
    if a.models:
        for d, dirs, names in sorted(os.walk(a.models)):
            dirs.sort()
            if skip & set(os.path.relpath(d, a.models).split(os.sep)):
                continue
            files += [os.path.join(d, n) for n in sorted(names)
                      if n.lower().endswith((".gltf", ".glb")) and os.path.splitext(n)[0] not in skip]
    return files


def slugs(files):
    """Output names: the file's stem; where stems repeat, with the extension; where that
    repeats too, the folder's name (with the stem unless the folder's name says it)."""
    clean = lambda s: re.sub(r"[^A-Za-z0-9_-]", "-", s)  # noqa: E731
    stems = [clean(os.path.splitext(os.path.basename(f))[0]) for f in files]
    names = [s + "-" + f.rsplit(".", 1)[1] if stems.count(s) > 1 else s for s, f in zip(stems, files)]
    folder = lambda f, s: clean(os.path.basename(os.path.dirname(f)))  # noqa: E731
    return [n if names.count(n) == 1 else folder(f, s) if s.lower() in folder(f, s).lower() else folder(f, s) + "-" + s
            for n, s, f in zip(names, stems, files)]


def run(cmd, env=None):
    for attempt in range(6):  # an executable being relinked by a build cannot start: wait for it
        try:
            p = subprocess.run(cmd, capture_output=True, text=True, env=env)
            return p.returncode, p.stdout + p.stderr
        except OSError as e:
            if attempt == 5:
                return 127, "%s: %s" % (cmd[0], e)
            time.sleep(10)


CONVERT = """
import bpy, numpy, sys
a = sys.argv[sys.argv.index('--') + 1:]
for src, dst in zip(a[::2], a[1::2]):
    im = bpy.data.images.load(src)
    w, h = im.size
    p = numpy.empty(w * h * 4, numpy.float32)
    im.pixels.foreach_get(p)
    numpy.save(dst, p.reshape(h, w, 4)[::-1])
"""


def read_exrs(paths):
    """RGBA float arrays (row 0 at the top) of EXR files, read by Blender (no EXR module here)."""
    args = [x for p in paths for x in (p, p + ".npy")]
    rc, log = run(["blender", "-b", "--factory-startup", "--python-expr", CONVERT, "--"] + args, blender_env())
    if rc != 0 or not all(os.path.exists(p + ".npy") for p in paths):
        raise RuntimeError("blender could not read the EXRs:\n" + log[-2000:])
    out = [numpy.load(p + ".npy") for p in paths]
    for p in paths:
        os.remove(p + ".npy")
    return out


def luminance(img):
    return 0.2126 * img[..., 0] + 0.7152 * img[..., 1] + 0.0722 * img[..., 2]


def box5(x):
    """A 5 x 5 box blur: averages the per-pixel noise of stochastic transparency out of a
    coverage map, while a shifted edge still differs by the shift times its length."""
    p = numpy.pad(x, 2, mode="edge")
    h, w = x.shape
    return sum(p[dy:dy + h, dx:dx + w] for dy in range(5) for dx in range(5)) / 25


def srgb8(img):
    x = numpy.clip(img[..., :3], 0, 1)
    x = numpy.where(x <= 0.0031308, 12.92 * x, 1.055 * numpy.power(x, 1 / 2.4) - 0.055)
    return (x * 255 + 0.5).astype(numpy.uint8)


def lambert_copy(path, g, folder):
    """A copy of the model (in folder, with the files it refers to) whose every material is
    Lambertian in both renderers: metallicFactor 0 and KHR_materials_ior 1 (glTF's model is
    then exactly Lambert; gltf_to_cycles.py gives it Cycles' Diffuse BSDF), the other
    material extensions dropped; colour, textures, alpha, normal maps and emission kept."""
    g = json.loads(json.dumps(g))
    dropped = set()
    prims = [p for m in g.get("meshes", []) for p in m.get("primitives", [])]
    mats = g.setdefault("materials", [])
    if any("material" not in p for p in prims):  # glTF's default material, made Lambertian too
        for p in prims:
            p.setdefault("material", len(mats))
        mats.append({"name": "glTF default"})
    for m in mats:
        m.setdefault("pbrMetallicRoughness", {})["metallicFactor"] = 0
        ext = m.setdefault("extensions", {})
        dropped |= {k for k in ext if k.startswith("KHR_materials_") and k != "KHR_materials_emissive_strength"}
        for k in list(ext):
            if k in dropped:
                del ext[k]
        ext["KHR_materials_ior"] = {"ior": 1}
    g["extensionsUsed"] = [e for e in g.get("extensionsUsed", []) if e not in dropped] + ["KHR_materials_ior"]
    if "extensionsRequired" in g:
        g["extensionsRequired"] = [e for e in g["extensionsRequired"] if e not in dropped]
    src = os.path.dirname(path)
    os.makedirs(folder, exist_ok=True)
    for item in g.get("buffers", []) + g.get("images", []):
        uri = item.get("uri", "")
        if uri and not uri.startswith("data:"):
            rel = urllib.parse.unquote(uri)
            os.makedirs(os.path.dirname(os.path.join(folder, rel)), exist_ok=True)
            shutil.copyfile(os.path.join(src, rel), os.path.join(folder, rel))
    out = os.path.join(folder, os.path.basename(path))
    text = json.dumps(g).encode()
    if path.lower().endswith(".glb"):  # the same binary chunk after the new JSON chunk
        with open(path, "rb") as f:
            data = f.read()
        n, = struct.unpack_from("<I", data, 12)
        rest = data[20 + n:]
        text += b" " * (-len(text) % 4)
        body = struct.pack("<I4s", len(text), b"JSON") + text + rest
        text = struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body
    with open(out, "wb") as f:
        f.write(text)
    return out


def twin_of(path, g, files):
    """For a Draco-compressed file, the run's uncompressed copy of the same model (same
    stem; the same nodes, meshes, materials and cameras), or None."""
    count = lambda d: [len(d.get(k, [])) for k in ("nodes", "meshes", "materials", "cameras")]  # noqa: E731
    stem = os.path.splitext(os.path.basename(path))[0].lower()
    for f in files:
        if f != path and os.path.splitext(os.path.basename(f))[0].lower() == stem:
            t = gltf_json(f)
            if "KHR_draco_mesh_compression" not in t.get("extensionsUsed", []) and count(t) == count(g):
                return f
    return None


def render_pair(path, cycles_path, base, spp, a):
    """Tessera renders path, Cycles cycles_path, both with coverage; returns (metrics, None)
    or (None, why not). Files: base-{tessera,cycles}[-coverage].exr."""
    ours, theirs = base + "-tessera.exr", base + "-cycles.exr"
    ours_cov, theirs_cov = base + "-tessera-coverage.exr", base + "-cycles-coverage.exr"
    stats = base + "-stats.json"
    tessera = [os.path.join(BIN, "tessera"), "render", path, "-r", str(a.width), str(a.height), "-t", str(a.threads),
               "-q"]
    rc, log = run(tessera + ["--env", a.env, "-s", str(spp), "-m", "16", "-f", ours, "--stats-json", stats])
    if rc != 0:
        errors = [x for x in log.splitlines() if x.startswith("tessera: error:")] or log.strip().splitlines()[-1:]
        return None, "refused: " + " ".join(errors)
    m = {"tessera_s": json.load(open(stats))["seconds"]}
    for grey, f in ((1, ours_cov), (0.5, ours_cov + "-half.exr")):
        rc, log = run(tessera + ["--env-color", str(grey), str(grey), str(grey), "-m", "0", "-s", "16", "-f", f])
        if rc != 0:
            return None, "Tessera's coverage render failed: " + log.strip().splitlines()[-1]
    for f in (theirs, theirs_cov):
        if os.path.exists(f):
            os.remove(f)
    rc, log = run(["blender", "-b", "--factory-startup", "--python", os.path.join(HERE, "gltf_to_cycles.py"), "--",
                   cycles_path, theirs, "--env", a.env, "--spp", str(spp), "--threads", str(a.threads),
                   "--max-bounces", "16", "--width", str(a.width), "--height", str(a.height), "--stats", stats,
                   "--rest-pose", "1", "--coverage", theirs_cov], blender_env())
    if rc != 0 or not os.path.exists(theirs) or not os.path.exists(theirs_cov):
        last = [x for x in log.strip().splitlines() if "Error" in x or "error" in x] or log.strip().splitlines()
        return None, "Blender failed: " + last[-1].strip()
    m["cycles_s"] = json.load(open(stats))["seconds"]
    t, c, tc, th, cc = read_exrs([ours, theirs, ours_cov, ours_cov + "-half.exr", theirs_cov])
    lt, lc = luminance(t), luminance(c)
    m["relmse"] = float(numpy.mean((lt - lc) ** 2 / (lc ** 2 + 0.01)))
    m["ratio"] = float(lt.mean() / lc.mean())
    # The same paths under a background of 1 and of 0.5 (same samples): what differs is the
    # background's share of the pixel, 1 - coverage; emitters cancel out.
    cov_t = numpy.clip(1 - 2 * (tc[..., 1] - th[..., 1]), 0, 1)
    cov_c = cc[..., 3]
    m["coverage"] = float(cov_c.mean())
    m["silhouette"] = float(numpy.abs(box5(cov_t) - box5(cov_c)).sum() / max(cov_c.sum(), 1e-9))
    both = (cov_t > 0.5) & (cov_c > 0.5)
    m["model_ratio"] = float(lt[both].sum() / lc[both].sum()) if both.any() else None
    region = base + "-all.json"
    json.dump({"all": [0, 0, a.width, a.height]}, open(region, "w"))
    rc, log = run([os.path.join(BIN, "tessera_compare"), ours, theirs, "--regions", region])
    if rc == 0:
        m["noise"] = json.loads(log)["regions"]["all"]["image_luminance_stderr"] / float(lt.mean())
    m["images"] = t, c
    return m, None


def render_model(path, slug, files, a):
    """Renders one model both ways (and, where they differ, its Lambertian control); returns
    its row (a dict)."""
    g = gltf_json(path)
    feats = features(g)
    row = {"model": path, "name": slug, "features": feats}
    base = os.path.join(a.out, slug)
    m, why = render_pair(path, path, base, a.spp, a)
    twin = twin_of(path, g, files) if why and "draco" in why.lower() else None
    if twin:  # Debian's Blender 3.4 has no Draco decoder (libextern_draco.so)
        m, why = render_pair(path, twin, base, a.spp, a)
        row["cycles_model"] = twin
    if why:
        row["verdict"] = why
        return row
    t, c = m.pop("images")
    row.update(m)
    side = numpy.concatenate([srgb8(t), srgb8(c)], axis=1)
    Image.fromarray(side).save(os.path.join(a.gallery, "sample-%s.jpg" % slug), quality=80, optimize=True)
    reasons = [DIFFERS[f] for f in feats if f in DIFFERS]
    note = " (Cycles: the uncompressed %s; Blender has no Draco decoder)" % os.path.basename(twin) if twin else ""
    agree = abs(row["ratio"] - 1) <= a.tolerance and row["silhouette"] <= a.silhouette
    if agree and not reasons:
        row["verdict"] = "ok" + note
        return row
    if row["silhouette"] > a.silhouette:
        row["verdict"] = "FAIL (silhouettes differ)" + note
        return row
    if NOT_BSDF & set(feats):
        row["verdict"] = "differs (%s)" % ", ".join(r[0] for r in reasons) + note
        row["why"] = [r[1] for r in reasons]
        return row
    with tempfile.TemporaryDirectory() as tmp:  # the same scene with Lambertian materials: all but the BSDFs
        ours = lambert_copy(path, g, os.path.join(tmp, "t"))
        theirs = lambert_copy(twin, gltf_json(twin), os.path.join(tmp, "c")) if twin else ours
        ctl, why = render_pair(ours, theirs, base + "-lambert", a.control_spp, a)
    if ctl:
        ctl.pop("images")
        row["control"] = ctl
    control_agrees = ctl and all(abs(x - 1) <= a.tolerance for x in (ctl["ratio"], ctl["model_ratio"] or 1))
    in_range = BSDF_RANGE[0] <= (row["model_ratio"] or 1) <= BSDF_RANGE[1]
    if control_agrees and (reasons or in_range):
        row["verdict"] = "differs (%s)" % ", ".join(r[0] for r in reasons or [WHY_BSDF]) + note
        row["why"] = [r[1] for r in reasons or [WHY_BSDF]]
    else:
        row["verdict"] = "FAIL" + note + (" (Lambertian control: %s)" % why if why else
                                          "" if control_agrees else " (the Lambertian control differs too)")
    return row


def table(rows, a):
    fmt = lambda x, f: "-" if x is None else f % x  # noqa: E731
    lines = ["%d models, %dx%d, %d spp each (Lambertian controls %d), max 16 bounces, %d threads, environment %s" % (
                 len(rows), a.width, a.height, a.spp, a.control_spp, a.threads, os.path.relpath(a.env, ROOT)), "",
             "| model | features | ratio T/C | model's pixels T/C | relMSE | silhouette | noise | Lambertian control "
             "T/C (image, model's pixels) | Tessera s | Cycles s | verdict |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    why = {}
    for r in rows:
        ctl = r.get("control")
        lines.append("| %s | %s | %s | %s | %s | %s | %s | %s | %s | %s | %s |" % (
            r["name"], ", ".join(r["features"]) or "-", fmt(r.get("ratio"), "%.3f"), fmt(r.get("model_ratio"), "%.3f"),
            fmt(r.get("relmse"), "%.4f"), fmt(r.get("silhouette") and 100 * r["silhouette"], "%.1f%%"),
            fmt(r.get("noise") and 100 * r["noise"], "%.2f%%"),
            "%.3f, %s" % (ctl["ratio"], fmt(ctl["model_ratio"], "%.3f")) if ctl else "-",
            fmt(r.get("tessera_s"), "%.1f"), fmt(r.get("cycles_s"), "%.1f"), r["verdict"].replace("|", "/")))
        for short, long in zip(r["verdict"][9:r["verdict"].find(")")].split(", "), r.get("why", [])):
            why[short] = long
    failed = sum(r["verdict"].startswith("FAIL") for r in rows)
    judged = sum(r["verdict"].startswith(("ok", "FAIL")) for r in rows)
    lines += [""] + ["- %s: %s" % kv for kv in sorted(why.items())]
    lines += ["", "%d of %d judged model(s) miss the aim (ratio within %.0f%%, silhouettes within %.0f%%)" % (
        failed, judged, 100 * a.tolerance, 100 * a.silhouette)]
    return "\n".join(lines), failed


FURNACE = (("metal, roughness 1", 1, 1.0), ("metal, roughness 0.5", 1, 0.5), ("dielectric, roughness 1", 0, 1.0),
           ("dielectric, roughness 0.5", 0, 0.5), ("dielectric, roughness 0", 0, 0.0))
ANGLES = (0, 30, 52, 60, 70)


def plane(metal, rough, theta):
    """A white glTF plane (2000 units wide, +Y up) of one material, seen at theta degrees
    from its normal through a 1-degree camera 10 units away."""
    s = 1000.0
    buf = struct.pack("<24f", *[-s, 0, -s, s, 0, -s, s, 0, s, -s, 0, s] + [0, 1, 0] * 4) + struct.pack("<6H2x", 0, 2, 1,
                                                                                                         0, 3, 2)
    t, phi = math.radians(theta), math.radians(theta - 90) / 2
    return {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0, 1]}],
            "nodes": [{"mesh": 0}, {"camera": 0, "translation": [0, 10 * math.cos(t), 10 * math.sin(t)],
                                    "rotation": [math.sin(phi), 0, 0, math.cos(phi)]}],
            "cameras": [{"type": "perspective", "perspective": {"yfov": math.radians(1), "znear": 0.01, "zfar": 1e5}}],
            "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1}, "indices": 2, "material": 0}]}],
            "materials": [{"pbrMetallicRoughness": {"metallicFactor": metal, "roughnessFactor": rough}}],
            "buffers": [{"byteLength": len(buf), "uri": "data:application/octet-stream;base64," +
                         base64.b64encode(buf).decode()}],
            "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 48}, {"buffer": 0, "byteOffset": 48,
                                                                                "byteLength": 48},
                            {"buffer": 0, "byteOffset": 96, "byteLength": 12}],
            "accessors": [{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3", "min": [-s, 0, -s],
                           "max": [s, 0, s]}, {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC3"},
                          {"bufferView": 2, "componentType": 5123, "count": 6, "type": "SCALAR"}]}


def furnace(a):
    """White planes in a white furnace (radiance 1 from every direction): each pixel is the
    BSDF's directional albedo at the angle, in Tessera and in Cycles (as imported)."""
    lines = ["White plane, uniform environment of radiance 1, %d spp: albedo Tessera / Cycles (T/C)" % a.spp, "",
             "| material | " + " | ".join("%d degrees" % t for t in ANGLES) + " |", "|---" * (len(ANGLES) + 1) + "|"]
    with tempfile.TemporaryDirectory() as tmp:
        env = os.path.join(tmp, "white.hdr")  # Radiance RGBE, flat scanlines: (1, 1, 1) everywhere
        open(env, "wb").write(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 8 +X 16\n" + bytes([128, 128, 128, 129]) * 128)
        region = os.path.join(tmp, "all.json")
        json.dump({"all": [0, 0, 16, 16]}, open(region, "w"))
        for name, metal, rough in FURNACE:
            cells = []
            for theta in ANGLES:
                f, ours, theirs = (os.path.join(tmp, "plane" + x) for x in (".gltf", "-t.exr", "-c.exr"))
                json.dump(plane(metal, rough, theta), open(f, "w"))
                run([os.path.join(BIN, "tessera"), "render", f, "--env", env, "-s", str(a.spp), "-r", "16", "16", "-t",
                     str(a.threads), "-q", "-f", ours])
                run(["blender", "-b", "--factory-startup", "--python", os.path.join(HERE, "gltf_to_cycles.py"), "--",
                     f, theirs, "--env", env, "--spp", str(a.spp), "--threads", str(a.threads), "--width", "16",
                     "--height", "16"], blender_env())
                rc, log = run([os.path.join(BIN, "tessera_compare"), ours, theirs, "--regions", region])
                r = json.loads(log)["regions"]["all"] if rc == 0 else None
                cells.append("%.4f / %.4f (%.3f)" % (r["image"][1], r["reference"][1], r["image"][1] / r["reference"][1])
                             if r else "-")
            lines.append("| %s | %s |" % (name, " | ".join(cells)))
    return "\n".join(lines)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("files", nargs="*")
    ap.add_argument("--models", help="a folder searched recursively for .gltf and .glb")
    ap.add_argument("--skip", default=BROKEN, help="folder or file names to leave out of --models")
    ap.add_argument("--env", default=os.path.join(ROOT, "scenes", "sky.hdr"))
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--control-spp", type=int, default=64, help="samples of the Lambertian control")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--width", type=int, default=320)
    ap.add_argument("--height", type=int, default=240)
    ap.add_argument("--tolerance", type=float, default=0.02)
    ap.add_argument("--silhouette", type=float, default=0.05)
    ap.add_argument("--out", default=os.path.join(ROOT, "build", "report", "sample-models"))
    ap.add_argument("--gallery", help="where the side-by-side JPEGs go (default: --out)")
    ap.add_argument("--furnace", action="store_true", help="only the white-furnace planes (FURNACE x ANGLES)")
    a = ap.parse_args()
    a.env = os.path.abspath(a.env)
    a.gallery = a.gallery or a.out
    if a.furnace:
        text = furnace(a)
        os.makedirs(a.out, exist_ok=True)
        open(os.path.join(a.out, "furnace.md"), "w").write(text + "\n")
        print(text)
        return
    files = find_models(a)
    if not files:
        sys.exit("error: no models (give files or --models DIR)")
    os.makedirs(a.out, exist_ok=True)
    os.makedirs(a.gallery, exist_ok=True)
    rows = []
    for path, slug in zip(files, slugs(files)):
        rows.append(render_model(os.path.abspath(path), slug, [os.path.abspath(f) for f in files], a))
        r = rows[-1]
        print("%s: ratio %s, relMSE %s, silhouette %s: %s" % (
            slug, r.get("ratio"), r.get("relmse"), r.get("silhouette"), r["verdict"]), file=sys.stderr, flush=True)
    text, failed = table(rows, a)
    open(os.path.join(a.out, "sample-models.md"), "w").write(text + "\n")
    json.dump(rows, open(os.path.join(a.out, "sample-models.json"), "w"), indent=1)
    print(text)
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
