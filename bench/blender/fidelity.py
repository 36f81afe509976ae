#!/usr/bin/python3
"""Fidelity from Blender (issue 25): scenes built in Blender by script (blender_scenes.py:
diffuse and metal, glass, an emissive mesh with a point light, an HDRI world, an animated
object, a camera with depth of field), sent as the add-on sends them. For each:
  - farm = local: the farm's image (the Python client, a loopback farm) is bit-identical
    to `tessera render` of the exported file with the add-on's settings;
  - Tessera against Cycles: the image in a GRID x GRID grid of regions; per region the mean
    luminance of both, their ratio, and the ratio's noise (Tessera's standard error from
    its variance channel; Cycles' taken equal). A region "agrees" when |ratio - 1| <=
    --tolerance (2%) or within 3 standard errors; regions darker than 2% of the image's mean
    are not judged (noise, not light). Each scene's table says where the models differ and
    why (WHY below, docs/blender.md).
Writes OUT/fidelity.md and .json, OUT/NAME-{tessera,cycles,farm}.exr and, with --gallery,
GALLERY/NAME.jpg: Tessera left, Cycles right (sRGB, clamped).

Usage: bench/blender/fidelity.py [--scenes a,b] [--spp 256] [--width 160] [--height 120]
          [--threads 2] [--build build] [--out build/report/blender] [--gallery docs/blender]
          [--grid 4] [--tolerance 0.02]
Needs blender (apt-get install blender) and a built tree (build/bin, build/python,
build/blender).
"""
import argparse
import json
import os
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
SRC = os.path.dirname(os.path.dirname(HERE))
SCENES = ["diffuse-metal", "glass", "emissive-point", "hdri", "animated", "dof"]
# Where the scenes as authored differ from Cycles by design (docs/blender.md explains it):
# every scene has rough Principled BSDF dielectrics, whose diffuse is Disney's in Cycles 3.4
# and Lambertian in glTF's material model. The Lambertian controls take exactly that away.
WHY = "Principled BSDF's diffuse is Disney's in Cycles 3.4 (brighter towards grazing angles on rough surfaces, " \
      "not weighted by 1 - Fresnel), glTF's is Lambertian: rough floors and walls render 7-25% darker here"


def run(cmd, **kw):
    r = subprocess.run(cmd, capture_output=True, text=True, **kw)
    if r.returncode != 0:
        sys.exit(f"{' '.join(cmd[:3])} ...: exit {r.returncode}\n{r.stdout[-1500:]}\n{r.stderr[-1500:]}")
    return r


def regions(w, h, n):
    return {f"r{j}c{i}": [i * w // n, j * h // n, (i + 1) * w // n - i * w // n, (j + 1) * h // n - j * h // n]
            for j in range(n) for i in range(n)}


def lum(rgb):
    return 0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenes", default=",".join(SCENES))
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--width", type=int, default=160)
    ap.add_argument("--height", type=int, default=120)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--max-bounces", type=int, default=8)
    ap.add_argument("--build", default=os.path.join(SRC, "build"))
    ap.add_argument("--out", default=os.path.join(SRC, "build", "report", "blender"))
    ap.add_argument("--gallery")
    ap.add_argument("--grid", type=int, default=4)
    ap.add_argument("--tolerance", type=float, default=0.02)
    a = ap.parse_args()
    bin_dir = os.path.join(a.build, "bin")
    sys.path[:0] = [os.path.join(a.build, "python"), os.path.join(SRC, "tests", "python")]
    import tessera
    from local_farm import LocalFarm, identical
    os.makedirs(a.out, exist_ok=True)
    grid = regions(a.width, a.height, a.grid)
    with open(os.path.join(a.out, "regions.json"), "w") as f:
        json.dump(grid, f)
    farm = LocalFarm(bin_dir, workers=1, threads=a.threads)
    results = []
    try:
        client = tessera.Farm(farm.address)
        for name in a.scenes.split(","):
            for control in (False, True):
                results.append(one_scene(name, control, a, bin_dir, client, tessera, identical))
    finally:
        farm.stop()
    with open(os.path.join(a.out, "fidelity.json"), "w") as f:
        json.dump(results, f, indent=1)
    with open(os.path.join(a.out, "fidelity.md"), "w") as f:
        f.write(report(results, a))
    print(report(results, a))
    ok = all(r["farm_equals_local"] for r in results) and \
        all(r["agree"] == r["judged"] for r in results if r["control"])
    return 0 if ok else 1


def one_scene(name, control, a, bin_dir, client, tessera, identical):
    """The scene as authored, or its Lambertian control, through Blender, Cycles, tessera
    render and the farm."""
    t0 = time.time()
    out = os.path.join(a.out, "control" if control else "authored")
    os.makedirs(out, exist_ok=True)
    run(["blender", "-b", "--factory-startup", "--python-exit-code", "1", "--python",
         os.path.join(HERE, "blender_scenes.py"), "--", name, out, os.path.join(a.build, "blender"),
         "--spp", str(a.spp), "--width", str(a.width), "--height", str(a.height), "--threads", str(a.threads),
         "--max-bounces", str(a.max_bounces), "--env", os.path.join(SRC, "scenes", "sky.hdr"),
         "--control", "1" if control else "0"])
    path = lambda suffix: os.path.join(out, name + suffix)  # noqa: E731
    with open(path(".json")) as f:
        meta = json.load(f)
    with open(path("-cycles.json")) as f:
        cycles_seconds = json.load(f)["seconds"]
    s, frame = meta["settings"], meta["frame"]
    t1 = time.time()
    run([os.path.join(bin_dir, "tessera"), "render", path(".glb"), *tessera.settings.cli_flags(frame=frame, **s),
         "-t", str(a.threads), "-q", "-f", path("-tessera.exr")])
    tessera_seconds = time.time() - t1
    job = client.submit(path(".glb"), frame=frame, **s)
    job.wait()
    job.fetch(path("-farm.exr"))
    same = identical(bin_dir, path("-farm.exr"), path("-tessera.exr"))
    cmp = json.loads(run([os.path.join(bin_dir, "tessera_compare"), path("-tessera.exr"), path("-cycles.exr"),
                          "--regions", os.path.join(a.out, "regions.json")]).stdout)
    r = judge(name, cmp, a, same, tessera_seconds, cycles_seconds, meta["notes"])
    r["control"] = control
    print(f"{name}{' (control)' if control else ''}: farm = local {same}; {r['agree']} of {r['judged']} regions "
          f"agree ({time.time() - t0:.0f} s)", flush=True)
    if a.gallery:
        os.makedirs(a.gallery, exist_ok=True)
        run(["blender", "-b", "--factory-startup", "--python-exit-code", "1", "--python",
             os.path.join(HERE, "side_by_side.py"), "--", path("-tessera.exr"), path("-cycles.exr"),
             os.path.join(a.gallery, name + ("-control" if control else "") + ".jpg")])
    return r


def judge(name, cmp, a, same, tessera_seconds, cycles_seconds, notes):
    regs = cmp["regions"]
    mean = sum(lum(r["reference"]) for r in regs.values()) / len(regs)
    rows, agree, judged = [], 0, 0
    for key, r in sorted(regs.items()):
        t, c = lum(r["image"]), lum(r["reference"])
        se = r.get("image_luminance_stderr", 0.0)
        if c < 0.02 * mean:
            rows.append({"region": key, "tessera": t, "cycles": c, "judged": False})
            continue
        ratio = t / c
        sigma = (2 ** 0.5) * se / c  # both renderers' noise, Cycles' taken as ours
        ok = abs(ratio - 1) <= a.tolerance or abs(ratio - 1) <= 3 * sigma
        judged += 1
        agree += ok
        rows.append({"region": key, "tessera": t, "cycles": c, "ratio": ratio, "sigma": sigma, "agrees": ok,
                     "judged": True})
    return {"scene": name, "farm_equals_local": same, "judged": judged, "agree": agree, "regions": rows,
            "relmse": cmp["relmse"], "tessera_seconds": tessera_seconds, "cycles_seconds": cycles_seconds,
            "why": WHY, "notes": notes}


def report(results, a):
    lines = [f"# Fidelity from Blender: Tessera against Cycles 3.4 ({a.width}x{a.height}, {a.spp} spp, "
             f"{a.max_bounces} bounces, {a.threads} threads; regions {a.grid}x{a.grid}, tolerance "
             f"{100 * a.tolerance:.0f}% or 3 sigma)", "",
             "| scene | materials | farm = local | regions agreeing | worst ratio | relMSE | Tessera s | Cycles s |",
             "|---|---|---|---|---|---|---|---|"]
    for r in results:
        judged = [x for x in r["regions"] if x["judged"]]
        worst = max(judged, key=lambda x: abs(x["ratio"] - 1)) if judged else None
        kind = "Lambertian control" if r["control"] else "as authored"
        lines.append(f"| {r['scene']} | {kind} | {'yes' if r['farm_equals_local'] else 'NO'} | "
                     f"{r['agree']} / {r['judged']} | "
                     f"{worst['ratio']:.3f} ({worst['region']}) | {r['relmse']:.4f} | {r['tessera_seconds']:.1f} | "
                     f"{r['cycles_seconds']:.1f} |" if worst else f"| {r['scene']} | {kind} | - | 0 / 0 | - | - | - | - |")
    lines.append("")
    for r in results:
        if (r["why"] and not r["control"]) or r["agree"] < r["judged"]:
            off = ", ".join(f"{x['region']} {x['ratio']:.3f}" for x in r["regions"] if x["judged"] and not x["agrees"])
            lines.append(f"- **{r['scene']}**{' (control)' if r['control'] else ''}: "
                         f"{(r['why'] if not r['control'] else '') or 'unexplained'}" + (f" (regions off: {off})" if off else ""))
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    sys.exit(main())
