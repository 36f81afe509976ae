#!/usr/bin/python3
"""Speed against error where path tracing is weakest (issue 28): Tessera without and with its
light tracer (--light-tracer off / on) against Blender Cycles 3.4, per image region.

For each scene, sample count and seed, alternately: Cycles (cs184_to_cycles.py for a CS184
.dae, gltf_to_cycles.py for a .gltf or .glb: caustics on, no denoiser, no clamping, no
adaptive sampling, 2 threads), Tessera with the light tracer
off, and on (2 threads). Every image is measured against one converged Tessera reference
(light tracer on, its own seed; cached by bench/error_report.py) over the whole image and
over each region of regions.json (caustic, walls, mirror and glass spheres, floor): relMSE =
mean((x - ref)^2 / (ref^2 + 0.01)). Then, per region, efficiency = 1 / (relMSE x seconds),
each Tessera variant's over Cycles' at the same sample count (the renderers' times differ,
so this is the equal-time ratio for estimators whose error falls as 1/time).

Writes OUT/caustics.csv, OUT/caustics.png (relMSE against seconds, one panel per region) and
prints Markdown tables.

Usage: bench/cycles/caustics_report.py [SCENE.dae...] [--spp 16,64,256] [--seeds 2]
          [--ref-spp 2048] [--flags "-r 480 360 -m 16 -l 1"] [--out build/report] [--no-cycles]
          [--from-csv OUT/caustics.csv]
"""
import argparse
import json
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))
import error_report as er  # noqa: E402
from compare_cycles import cycles  # noqa: E402
from compare_gltf import cycles_gltf  # noqa: E402

SHARED = os.path.join(os.path.dirname(os.path.dirname(HERE)), "..", "shared", "scenes", "cs184")


def measure(img, ref, rfile):
    e = er.compare(img, ref, rfile)
    out = {"image": e["relmse"]}
    for name, v in e.get("regions", {}).items():
        out[name] = v["relmse"]
    return out


def report(rows, a):
    """Markdown tables and the plot, from the rows (rendered now, or read back: --from-csv)."""
    keys = [k for k in rows[0] if k.startswith("relmse:") and any(r[k] > 0 for r in rows)]  # (the light: exact)
    # Mean over seeds.
    groups = {}
    for r in rows:
        groups.setdefault((r["scene"], r["renderer"], r["spp"]), []).append(r)
    table = {k: {f: sum(r[f] for r in g) / len(g) for f in ["seconds"] + keys} for k, g in groups.items()}
    renderers = [r for r in ["cycles", "tessera", "tessera+lt"] if any(k[1] == r for k in table)]
    for scene in sorted({k[0] for k in table}):
        seeds = len({r["seed"] for r in rows})
        print("\n%s, `%s`, mean of %d seeds: seconds and relMSE per region\n" % (scene, a.flags, seeds))
        print("| renderer | spp | seconds | " + " | ".join(k[7:] for k in keys) + " |")
        print("|---|---|---|" + "---|" * len(keys))
        for (sc, rend, spp), t in sorted(table.items(), key=lambda kv: (kv[0][0], renderers.index(kv[0][1]), kv[0][2])):
            if sc == scene:
                print("| %s | %d | %.2f | " % (rend, spp, t["seconds"]) + " | ".join("%.3g" % t[k] for k in keys) + " |")
        pairs = [(r, b) for b in ["cycles", "tessera"] for r in ["tessera", "tessera+lt"]
                 if r != b and r in renderers and b in renderers]
        for rend, base in pairs:
            print("\n%s: efficiency (1 / (relMSE x seconds)) of %s over %s, per region\n" % (scene, rend, base))
            print("| spp | " + " | ".join(k[7:] for k in keys) + " |")
            print("|---|" + "---|" * len(keys))
            for spp in sorted({k[2] for k in table if k[0] == scene}):
                b, t = table[(scene, base, spp)], table[(scene, rend, spp)]
                print("| %d | " % spp + " | ".join(
                    "%.2f" % ((b[k] * b["seconds"]) / (t[k] * t["seconds"])) if t[k] > 0 else "-" for k in keys) + " |")
    try:
        import matplotlib
    except ImportError:
        print("\n(no matplotlib: no plot; apt-get install python3-matplotlib)", file=sys.stderr)
        return
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    cols = 4
    rws = (len(keys) + cols - 1) // cols
    for scene in sorted({k[0] for k in table}):
        fig, axes = plt.subplots(rws, cols, figsize=(3.2 * cols, 2.6 * rws), squeeze=False)
        for i, k in enumerate(keys):
            ax = axes[i // cols][i % cols]
            for rend in renderers:
                pts = sorted((t["seconds"], t[k]) for (sc, r, _), t in table.items() if sc == scene and r == rend)
                ax.loglog([p[0] for p in pts], [p[1] for p in pts], "o-", label=rend, markersize=3)
            ax.set_title(k[7:], fontsize=9)
            ax.grid(True, which="both", alpha=0.3)
            ax.tick_params(labelsize=7)
        for j in range(len(keys), rws * cols):
            axes[j // cols][j % cols].axis("off")
        axes[0][0].legend(fontsize=7)
        fig.suptitle("%s: relMSE against seconds (2 threads), `%s`" % (scene, a.flags), fontsize=9)
        fig.tight_layout()
        fig.savefig(os.path.join(a.out, "caustics-%s.png" % scene), dpi=100)


def read_csv(path):
    import csv
    rows = []
    for r in csv.DictReader(open(path)):
        rows.append({k: (v if k in ("renderer", "scene") else float(v) if "." in v or "e" in v else int(v))
                     for k, v in r.items()})
    return rows


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("scenes", nargs="*")
    ap.add_argument("--spp", default="16,64,256")
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--ref-spp", type=int, default=2048)
    ap.add_argument("--flags", default="-r 480 360 -m 16 -l 1")
    ap.add_argument("--out", default=os.path.join(os.path.dirname(os.path.dirname(HERE)), "build", "report"))
    ap.add_argument("--no-cycles", action="store_true", help="Tessera's two variants only")
    ap.add_argument("--from-csv", help="no renders: the tables and plot of an earlier run's caustics.csv")
    a = ap.parse_args()
    if a.from_csv:
        os.makedirs(a.out, exist_ok=True)
        return report(read_csv(a.from_csv), a)
    scenes = a.scenes or [os.path.join(SHARED, "CBspheres.dae")]
    for s in scenes:
        if not os.path.exists(s):
            sys.exit("error: %s is missing (the CS184 scenes live in ../shared/scenes/cs184)" % s)
    os.makedirs(a.out, exist_ok=True)
    regions = json.load(open(os.path.join(HERE, "regions.json")))
    stats = os.path.join(a.out, "stats.json")
    rows = []
    for scene in scenes:
        name = os.path.splitext(os.path.basename(scene))[0]
        ref = er.reference(scene, a.flags + " --light-tracer on -t 2", a.ref_spp)
        rfile = os.path.join(a.out, "regions-%s.json" % name)
        flags = a.flags.split()
        size = (int(flags[flags.index("-r") + 1]), int(flags[flags.index("-r") + 2])) if "-r" in flags else (480, 360)
        fits = {k: v for k, v in regions.get(name, {}).items() if v[0] + v[2] <= size[0] and v[1] + v[3] <= size[1]}
        json.dump(fits, open(rfile, "w"))
        img = os.path.join(a.out, "caustics.exr")
        for spp in [int(s) for s in a.spp.split(",")]:
            for seed in range(1, a.seeds + 1):
                runs = [] if a.no_cycles else ["cycles"]
                for renderer in runs + ["tessera", "tessera+lt"]:
                    if renderer == "cycles" and scene.endswith((".gltf", ".glb")):
                        secs = cycles_gltf(scene, img, spp, stats, size[0], size[1], seed=seed)
                    elif renderer == "cycles":
                        secs = cycles(scene, img, spp, seed, stats)
                    else:
                        lt = "on" if renderer == "tessera+lt" else "off"
                        er.run([os.path.join(er.BIN, "tessera"), "render", scene, "-s", str(spp), "--seed", str(seed),
                                "-t", "2", "-q", "-f", img, "--stats-json", stats, "--light-tracer", lt] + a.flags.split())
                        secs = json.load(open(stats))["seconds"]
                    row = {"renderer": renderer, "scene": name, "spp": spp, "seed": seed, "seconds": secs}
                    row.update({"relmse:" + k: v for k, v in measure(img, ref, rfile).items()})
                    rows.append(row)
                    print("%s %s %d spp seed %d: %.2f s, relMSE %.4g, caustic %.4g" %
                          (name, renderer, spp, seed, secs, row["relmse:image"], row.get("relmse:caustic", 0)),
                          file=sys.stderr)
    with open(os.path.join(a.out, "caustics.csv"), "w") as f:
        f.write(",".join(rows[0].keys()) + "\n")
        for r in rows:
            f.write(",".join(str(r.get(k, "")) for k in rows[0].keys()) + "\n")
    report(rows, a)
    print("\nwrote %s" % os.path.join(a.out, "caustics.csv"), file=sys.stderr)


if __name__ == "__main__":
    main()
