#!/usr/bin/python3
"""Tessera against Blender Cycles 3.4 on glTF files, as Blender itself imports them.

Renders each scene converged in both (bench/cycles/gltf_to_cycles.py for Cycles) under the
same environment map, then compares region means: one region per sphere of
scenes/material-spheres.gltf (the inner half of its disc, found by projecting the file's
nodes through its camera) plus sky and ground seen directly. A region passes when every
channel's mean agrees within --tolerance (2%) where the two renderers share the model;
regions where the models differ are reported, not judged (docs/gltf.md explains each).
Writes OUT/gltf-cycles.md (the table) and prints it.

Usage: bench/cycles/compare_gltf.py [SCENE.gltf] [--env scenes/sky.hdr] [--spp 512]
          [--threads 2] [--tolerance 0.02] [--out build/report]
Needs blender (apt-get install blender) and a built tree (build/bin).
"""
import argparse
import json
import math
import os
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
BIN = os.path.join(ROOT, "build", "bin")

# What differs between glTF's model as we render it and Cycles 3.4's Principled BSDF (v1),
# by material name prefix (docs/gltf.md, "Compared with Cycles").
DIFFERENT = {
    "plastic": "Principled v1: Disney diffuse (retro-reflection) not weighted by 1 - F; glTF: Lambert x (1 - F)",
    "half-metal": "half of it is the plastic difference",
}


def blender_env():
    """The environment without pyenv's: Blender's Python finds its home from the python3 on
    PATH, and a pyenv one has no NumPy for the glTF importer."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYENV")}
    env["PATH"] = os.pathsep.join(p for p in env.get("PATH", "").split(os.pathsep) if ".pyenv" not in p)
    return env


def run(cmd):
    p = subprocess.run(cmd, capture_output=True, text=True, env=blender_env())
    if p.returncode != 0:
        sys.exit("error: %s failed\n%s%s" % (cmd[0], p.stdout[-3000:], p.stderr[-3000:]))
    return p.stdout


def regions_of(scene, width, height):
    """Boxes [x, y, w, h] for each named mesh node (inner half of its disc) and background."""
    g = json.load(open(scene))
    cam = next(n for n in g["nodes"] if "camera" in n)
    persp = g["cameras"][cam["camera"]]["perspective"]
    eye = cam.get("translation", [0, 0, 0])
    t = math.tan(persp["yfov"] / 2)
    regions = {}
    for n in g["nodes"]:
        if "mesh" not in n:
            continue
        c = [a - b for a, b in zip(n.get("translation", [0, 0, 0]), eye)]
        d = -c[2]  # the camera looks down -z, unrotated
        px = width / 2 + c[0] / d / t * height / 2
        py = height / 2 - c[1] / d / t * height / 2
        r = 0.4 / d / t * height / 2 * 0.5  # radius 0.4; the inner half
        regions[n["name"]] = [int(px - r), int(py - r), int(2 * r), int(2 * r)]
    regions["sky (environment seen directly)"] = [5, 5, width - 10, 10]
    regions["ground (environment seen directly)"] = [5, height - 15, width - 10, 10]
    return regions


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("scene", nargs="?", default=os.path.join(ROOT, "scenes", "material-spheres.gltf"))
    ap.add_argument("--env", default=os.path.join(ROOT, "scenes", "sky.hdr"))
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
    run([os.path.join(BIN, "tessera"), "render", a.scene, "--env", a.env, "-s", str(a.spp), "-m", "16",
         "-r", str(a.width), str(a.height), "-t", str(a.threads), "-q", "-f", ours, "--stats-json", stats])
    t_ours = json.load(open(stats))["seconds"]
    run(["blender", "-b", "--factory-startup", "--python", os.path.join(HERE, "gltf_to_cycles.py"), "--", a.scene,
         theirs, "--env", a.env, "--spp", str(a.spp), "--threads", str(a.threads), "--max-bounces", "16",
         "--width", str(a.width), "--height", str(a.height), "--stats", stats])
    if not os.path.exists(theirs):
        sys.exit("error: blender wrote no image (its Python failed?); run gltf_to_cycles.py by hand to see why")
    t_theirs = json.load(open(stats))["seconds"]
    rfile = os.path.join(a.out, name + "-regions.json")
    json.dump(regions_of(a.scene, a.width, a.height), open(rfile, "w"))
    res = json.loads(run([os.path.join(BIN, "tessera_compare"), ours, theirs, "--regions", rfile]))["regions"]
    lines = ["%s, %d spp each, %d threads: Tessera %.1f s, Cycles %.1f s" % (name, a.spp, a.threads, t_ours, t_theirs),
             "", "| region | Tessera (R G B) | Cycles (R G B) | worst channel | luminance, noise | same model | verdict |",
             "|---|---|---|---|---|---|---|"]
    failed = 0
    for region, v in res.items():
        rel = [(x - y) / max(y, 1e-6) for x, y in zip(v["image"], v["reference"])]
        worst = max(rel, key=abs)
        # Luminance difference against the noise of the difference: Tessera's standard error
        # (its variance channel) counted twice, Cycles' being of the same order.
        lum = lambda c: 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]
        dl = lum(v["image"]) - lum(v["reference"])
        noise = math.sqrt(2) * v.get("image_luminance_stderr", 0)
        why = next((w for k, w in DIFFERENT.items() if region.startswith(k)), None)
        verdict = "differs: see docs/gltf.md" if why else ("ok" if abs(worst) <= a.tolerance else "FAIL")
        failed += verdict == "FAIL"
        lines.append("| %s | %s | %s | %+.1f%% | %+.1f%%, +-%.1f%% | %s | %s |" % (
            region, " ".join("%.4f" % x for x in v["image"]), " ".join("%.4f" % x for x in v["reference"]),
            100 * worst, 100 * dl / max(lum(v["reference"]), 1e-6), 100 * noise / max(lum(v["reference"]), 1e-6),
            "no" if why else "yes", verdict))
    lines.append("")
    lines.append("%d region(s) outside %.0f%% where the models are the same" % (failed, 100 * a.tolerance))
    text = "\n".join(lines)
    open(os.path.join(a.out, "gltf-cycles.md"), "w").write(text + "\n")
    print(text)
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
