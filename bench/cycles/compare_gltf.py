#!/usr/bin/python3
"""Tessera against Blender Cycles 3.4 on glTF files, as Blender itself imports them.

Renders a scene converged in both (bench/cycles/gltf_to_cycles.py for Cycles) under the
same environment map, then compares region means. Regions: one per sphere (a mesh node
with a translation: the inner half of its disc through the file's camera), judged "same
model" from its glTF material (metal, solid glass, emitters: yes; dielectrics and
thin-walled transmission: no, docs/gltf.md explains why), or the regions
bench/cycles/regions.json lists under "gltf:FILE"; plus sky (and, for the material grid,
ground) seen directly. A region passes when every channel's mean agrees within
--tolerance (2%) where the two renderers share the model; the others are reported, not
judged. Each row also shows the luminance difference against the noise (Tessera's standard
error from its variance channel, counted twice for the two renderers). Writes
OUT/NAME-cycles.md and prints it; exits 1 if a region fails.

Usage: bench/cycles/compare_gltf.py [SCENE.gltf] [--env scenes/sky.hdr | --env ''] [--spp 512]
          [--threads 2] [--tolerance 0.02] [--out build/report]
Needs blender (apt-get install blender) and a built tree (build/bin).
"""
import argparse
import json
import math
import os
import struct
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
BIN = os.path.join(ROOT, "build", "bin")

WHY_DIELECTRIC = "Principled v1: Disney diffuse (retro-reflection) not weighted by 1 - F; glTF: Lambert x (1 - F)"


def blender_env():
    """The environment without pyenv's: Blender's Python finds its home from the python3 on
    PATH, and a pyenv one has no NumPy for the glTF importer."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYENV")}
    env["PATH"] = os.pathsep.join(p for p in env.get("PATH", "").split(os.pathsep) if ".pyenv" not in p)
    return env


def gltf_json(path):
    """The JSON of a .gltf, or of a .glb's first chunk."""
    with open(path, "rb") as f:
        data = f.read()
    if data[:4] == b"glTF":
        length, = struct.unpack_from("<I", data, 12)
        data = data[20:20 + length]
    return json.loads(data)


def run(cmd):
    p = subprocess.run(cmd, capture_output=True, text=True, env=blender_env())
    if p.returncode != 0:
        sys.exit("error: %s failed\n%s%s" % (cmd[0], p.stdout[-3000:], p.stderr[-3000:]))
    return p.stdout


def cycles_gltf(scene, out, spp, stats, width, height, threads=2, seed=None, env=()):
    """Cycles' render of a glTF scene as Blender's importer reads it (gltf_to_cycles.py), to
    `out`; its render seconds. `env`: gltf_to_cycles.py's --env arguments."""
    if os.path.exists(out):
        os.remove(out)
    run(["blender", "-b", "--factory-startup", "--python", os.path.join(HERE, "gltf_to_cycles.py"), "--", scene, out] +
        list(env) + ["--spp", str(spp)] + (["--seed", str(seed)] if seed is not None else []) +
        ["--threads", str(threads), "--max-bounces", "16", "--width", str(width), "--height", str(height),
         "--stats", stats])
    if not os.path.exists(out):
        sys.exit("error: blender wrote no image (its Python failed?); run gltf_to_cycles.py by hand to see why")
    with open(stats) as f:
        return json.load(f)["seconds"]


def quat_rotate(q, v):
    """v rotated by the unit quaternion q = (x, y, z, w)."""
    x, y, z, w = q
    t = [2 * (y * v[2] - z * v[1]), 2 * (z * v[0] - x * v[2]), 2 * (x * v[1] - y * v[0])]
    return [v[0] + w * t[0] + (y * t[2] - z * t[1]), v[1] + w * t[1] + (z * t[0] - x * t[2]),
            v[2] + w * t[2] + (x * t[1] - y * t[0])]


def model_of(g, mesh):
    """(same model as Cycles', why not) for the material of a mesh's first primitive."""
    mi = g["meshes"][mesh]["primitives"][0].get("material")
    m = g["materials"][mi] if mi is not None else {}
    if any(m.get("emissiveFactor", [0, 0, 0])):
        return True, ""
    pbr = m.get("pbrMetallicRoughness", {})
    ext = m.get("extensions", {})
    metallic = pbr.get("metallicFactor", 1)
    transmission = ext.get("KHR_materials_transmission", {}).get("transmissionFactor", 0)
    solid = ext.get("KHR_materials_volume", {}).get("thicknessFactor", 0) > 0
    if metallic >= 1:
        return True, ""
    if transmission >= 1 and metallic <= 0:
        return (True, "") if solid else (False, "thin-walled transmission: Blender refracts")
    if metallic > 0:
        return False, "partly dielectric: " + WHY_DIELECTRIC
    return False, WHY_DIELECTRIC


def regions_of(scene, width, height):
    """name -> ([x, y, w, h], same model, why)."""
    g = gltf_json(scene)
    table = json.load(open(os.path.join(HERE, "regions.json"))).get("gltf:" + os.path.basename(scene))
    if table:  # a scene that is not a grid of spheres: its regions by hand
        return {k: (v["box"], v["same"], v.get("why", "")) for k, v in table.items()}
    cam = next(n for n in g["nodes"] if "camera" in n)
    persp = g["cameras"][cam["camera"]]["perspective"]
    eye = cam.get("translation", [0, 0, 0])
    qx, qy, qz, qw = cam.get("rotation", [0, 0, 0, 1])
    inverse = [-qx, -qy, -qz, qw]
    t = math.tan(persp["yfov"] / 2)
    regions = {}
    for n in g["nodes"]:
        if "mesh" not in n or "translation" not in n:
            continue
        acc = g["accessors"][g["meshes"][n["mesh"]]["primitives"][0]["attributes"]["POSITION"]]
        radius = acc["max"][0]
        c = quat_rotate(inverse, [a - b for a, b in zip(n["translation"], eye)])
        d = -c[2]  # in front of the camera, which looks down its -z
        if d <= radius:
            continue
        px = width / 2 + c[0] / d / t * height / 2
        py = height / 2 - c[1] / d / t * height / 2
        r = radius / d / t * height / 2 * 0.5  # the inner half
        x0, y0 = max(0, int(px - r)), max(0, int(py - r))
        x1, y1 = min(width, int(px + r)), min(height, int(py + r))
        if x1 - x0 < 2 or y1 - y0 < 2:
            continue
        same, why = model_of(g, n["mesh"])
        regions[n["name"]] = ([x0, y0, x1 - x0, y1 - y0], same, why)
    regions["sky (environment seen directly)"] = ([5, 5, width - 10, 10], True, "")
    if "material-spheres" in scene:
        regions["ground (environment seen directly)"] = ([5, height - 15, width - 10, 10], True, "")
    return regions


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("scene", nargs="?", default=os.path.join(ROOT, "scenes", "material-spheres.gltf"))
    ap.add_argument("--env", default=os.path.join(ROOT, "scenes", "sky.hdr"), help="'' for none")
    ap.add_argument("--spp", type=int, default=512)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--tolerance", type=float, default=0.02)
    ap.add_argument("--width", type=int, default=480)
    ap.add_argument("--height", type=int, default=360)
    ap.add_argument("--out", default=os.path.join(ROOT, "build", "report"))
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    name = os.path.splitext(os.path.basename(a.scene))[0]
    ours, theirs = os.path.join(a.out, name + "-tessera.exr"), os.path.join(a.out, name + "-cycles.exr")
    stats = os.path.join(a.out, "stats.json")
    env = ["--env", a.env] if a.env else []
    run([os.path.join(BIN, "tessera"), "render", a.scene] + env + ["-s", str(a.spp), "-m", "16", "-r", str(a.width),
        str(a.height), "-t", str(a.threads), "-q", "-f", ours, "--stats-json", stats])
    t_ours = json.load(open(stats))["seconds"]
    t_theirs = cycles_gltf(a.scene, theirs, a.spp, stats, a.width, a.height, a.threads, env=env)
    regions = regions_of(a.scene, a.width, a.height)
    rfile = os.path.join(a.out, name + "-regions.json")
    json.dump({k: v[0] for k, v in regions.items()}, open(rfile, "w"))
    res = json.loads(run([os.path.join(BIN, "tessera_compare"), ours, theirs, "--regions", rfile]))["regions"]
    lines = ["%s, %d spp each, %d threads: Tessera %.1f s, Cycles %.1f s" % (name, a.spp, a.threads, t_ours, t_theirs),
             "", "| region | Tessera (R G B) | Cycles (R G B) | worst channel | luminance, noise | same model | verdict |",
             "|---|---|---|---|---|---|---|"]
    failed = 0
    lum = lambda c: 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]  # noqa: E731
    for region, v in sorted(res.items()):
        rel = [(x - y) / max(y, 1e-6) for x, y in zip(v["image"], v["reference"])]
        worst = max(rel, key=abs)
        ref = max(lum(v["reference"]), 1e-6)
        dl = lum(v["image"]) - lum(v["reference"])
        noise = math.sqrt(2) * v.get("image_luminance_stderr", 0)
        _, same, why = regions[region]
        verdict = ("differs: " + why) if not same else ("ok" if abs(worst) <= a.tolerance else "FAIL")
        failed += verdict == "FAIL"
        lines.append("| %s | %s | %s | %+.1f%% | %+.1f%%, +-%.1f%% | %s | %s |" % (
            region, " ".join("%.4f" % x for x in v["image"]), " ".join("%.4f" % x for x in v["reference"]),
            100 * worst, 100 * dl / ref, 100 * noise / ref, "yes" if same else "no", verdict))
    lines.append("")
    lines.append("%d region(s) outside %.0f%% where the models are the same" % (failed, 100 * a.tolerance))
    text = "\n".join(lines)
    open(os.path.join(a.out, name + "-cycles.md"), "w").write(text + "\n")
    print(text)
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
