#!/usr/bin/python3
"""Tessera against Blender Cycles 3.4, side by side in one run, on CS184 scenes.

For each scene and sample count, alternately: Cycles (through cs184_to_cycles.py) and
Tessera, both with 2 threads, several seeds, both measured against the same converged
Tessera reference (bench/error_report.py's cache). Then:
  - the equal-time relMSE ratio Tessera/Cycles: Tessera's relMSE interpolated (log-log)
    at each Cycles time;
  - the efficiency ratio, 1/(relMSE x seconds), Tessera over Cycles, per sample count;
  - converged region means (walls, spheres, caustic, floor ...) of a long Cycles render
    against the reference.
Writes OUT/cycles.csv, OUT/cycles.png and prints Markdown tables.

Usage: bench/cycles/compare_cycles.py SCENE.dae... [--spp 4,16,64] [--seeds 2]
          [--converged-spp 1024] [--ref-spp 2048] [--out build/report]
"""
import argparse
import json
import math
import os
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))
import error_report as er  # noqa: E402

FLAGS = "-r 480 360 -m 16 -l 1"


def cycles(scene, out, spp, seed, stats):
    cmd = ["blender", "-b", "--factory-startup", "--python", os.path.join(HERE, "cs184_to_cycles.py"), "--", scene, out,
           "--spp", str(spp), "--seed", str(seed), "--threads", "2", "--max-bounces", "16", "--stats", stats]
    p = subprocess.run(cmd, capture_output=True, text=True)
    if p.returncode != 0 or not os.path.exists(out):
        sys.exit("error: blender failed\n" + p.stdout[-2000:] + p.stderr[-2000:])
    with open(stats) as f:
        return json.load(f)["seconds"]


def interp_loglog(xs, ys, x):
    pts = sorted(zip(xs, ys))
    if x <= pts[0][0]:
        (x0, y0), (x1, y1) = pts[0], pts[1]
    elif x >= pts[-1][0]:
        (x0, y0), (x1, y1) = pts[-2], pts[-1]
    else:
        for (x0, y0), (x1, y1) in zip(pts, pts[1:]):
            if x0 <= x <= x1:
                break
    t = (math.log(x) - math.log(x0)) / (math.log(x1) - math.log(x0))
    return math.exp(math.log(y0) + t * (math.log(y1) - math.log(y0)))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("scenes", nargs="+")
    ap.add_argument("--spp", default="4,16,64")
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--converged-spp", type=int, default=1024)
    ap.add_argument("--ref-spp", type=int, default=2048)
    ap.add_argument("--out", default=os.path.join(os.path.dirname(os.path.dirname(HERE)), "build", "report"))
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    regions = json.load(open(os.path.join(HERE, "regions.json")))
    rows, region_rows = [], []
    stats = os.path.join(a.out, "stats.json")
    for scene in a.scenes:
        name = os.path.splitext(os.path.basename(scene))[0]
        ref = er.reference(scene, FLAGS, a.ref_spp)
        for spp in [int(s) for s in a.spp.split(",")]:
            for seed in range(1, a.seeds + 1):
                img = os.path.join(a.out, "cmp.exr")
                secs = cycles(scene, img, spp, seed, stats)
                e = er.compare(img, ref)
                rows.append({"renderer": "cycles", "scene": name, "spp": spp, "seed": seed, "seconds": secs,
                             "rmse": e["rmse"], "relmse": e["relmse"], "efficiency": 1 / (e["relmse"] * secs)})
                er.run([os.path.join(er.BIN, "tessera"), "render", scene, "-s", str(spp), "--seed", str(seed), "-t", "2",
                        "-q", "-f", img, "--stats-json", stats] + FLAGS.split())
                secs = json.load(open(stats))["seconds"]
                e = er.compare(img, ref)
                rows.append({"renderer": "tessera", "scene": name, "spp": spp, "seed": seed, "seconds": secs,
                             "rmse": e["rmse"], "relmse": e["relmse"], "efficiency": 1 / (e["relmse"] * secs)})
                print("%s %4d spp seed %d: cycles %.4g relMSE, tessera %.4g" % (name, spp, seed, rows[-2]["relmse"],
                                                                               rows[-1]["relmse"]), file=sys.stderr)
        if a.converged_spp and name in regions:
            img = os.path.join(a.out, "%s-cycles-%d.exr" % (name, a.converged_spp))
            if not os.path.exists(img):
                cycles(scene, img, a.converged_spp, 7, stats)
            rfile = os.path.join(a.out, "regions-%s.json" % name)
            json.dump(regions[name], open(rfile, "w"))
            for region, v in er.compare(img, ref, rfile)["regions"].items():
                lum = lambda c: 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]
                region_rows.append((name, region, lum(v["image"]), lum(v["reference"])))
    er.write_outputs(rows, a.out, "Tessera and Cycles 3.4, 2 threads, `%s`" % FLAGS)
    os.replace(os.path.join(a.out, "error.csv"), os.path.join(a.out, "cycles.csv"))
    os.replace(os.path.join(a.out, "error.png"), os.path.join(a.out, "cycles.png"))
    table = er.summarize(rows)
    print("\n| scene | spp | Cycles s | Cycles relMSE | Tessera relMSE at Cycles' time | ratio T/C at equal time | efficiency ratio T/C |")
    print("|---|---|---|---|---|---|---|")
    for scene in sorted({t["scene"] for t in table}):
        tes = [t for t in table if t["scene"] == scene and t["renderer"] == "tessera"]
        cyc = [t for t in table if t["scene"] == scene and t["renderer"] == "cycles"]
        for c in cyc:
            t_at = interp_loglog([t["seconds"] for t in tes], [t["relmse"] for t in tes], c["seconds"])
            t_same = [t for t in tes if t["spp"] == c["spp"]][0]
            print("| %s | %d | %.2f | %.4g | %.4g | %.3f | %.2f |" % (scene, c["spp"], c["seconds"], c["relmse"], t_at,
                                                                     t_at / c["relmse"], t_same["efficiency"] / c["efficiency"]))
    if region_rows:
        print("\n| scene | region | Cycles %d spp (luminance) | Tessera reference | Cycles / Tessera - 1 |" % a.converged_spp)
        print("|---|---|---|---|---|")
        for scene, region, c, t in region_rows:
            print("| %s | %s | %.4f | %.4f | %+.1f%% |" % (scene, region, c, t, 100 * (c / t - 1)))


if __name__ == "__main__":
    main()
