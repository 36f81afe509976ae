#!/usr/bin/python3
"""Speed against error: for each scene, renders at several sample counts and seeds,
measures each image against a converged reference and reports, per sample count, the
seconds, RMSE, relMSE = mean((x - ref)^2 / (ref^2 + 0.01)) and efficiency =
1 / (relMSE x seconds). Writes OUT/error.csv, OUT/error.png (log-log relMSE against
seconds with the ideal slope -1) and prints a Markdown table.

The reference is a long render with a seed no test render uses, cached under
build/reference/ by scene and settings; the report says how many samples it has.

With --denoise every render is also made with `--denoise` (renderer "tessera+denoise",
its seconds the render's and the denoiser's together), and the report checks issue 26's
aim at the largest sample count N: the denoised N-sample image's error at most that of 4N
samples without (measured when 4N is in --spp, else predicted as N's relMSE / 4), in at
most 1.2x the N-sample render's time.

Usage: bench/error_report.py SCENE... [--spp 4,16,64,256] [--seeds 3] [--ref-spp 2048]
                             [--flags "-r 480 360 -m 16 -l 1"] [--out build/report] [--denoise]
"""
import argparse
import csv
import hashlib
import json
import os
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BIN = os.path.join(ROOT, "build", "bin")


def run(cmd):
    p = subprocess.run(cmd, capture_output=True, text=True)
    if p.returncode != 0:
        sys.exit("error: %s\n%s" % (" ".join(cmd), p.stderr))
    return p.stdout


def reference(scene, flags, ref_spp):
    key = hashlib.sha1(("%s|%s|%d" % (os.path.abspath(scene), flags, ref_spp)).encode()).hexdigest()[:10]
    path = os.path.join(ROOT, "build", "reference", "%s-%s.exr" % (os.path.splitext(os.path.basename(scene))[0], key))
    if not os.path.exists(path):
        os.makedirs(os.path.dirname(path), exist_ok=True)
        print("rendering the reference for %s (%d spp) ..." % (scene, ref_spp), file=sys.stderr)
        t0 = time.time()
        run([os.path.join(BIN, "tessera"), "render", scene, "-s", str(ref_spp), "--seed", "999999", "-q", "-f", path] + flags.split())
        print("  done in %.0f s" % (time.time() - t0), file=sys.stderr)
    return path


def compare(image, ref, regions=None):
    cmd = [os.path.join(BIN, "tessera_compare"), image, ref] + (["--regions", regions] if regions else [])
    return json.loads(run(cmd))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("scenes", nargs="+")
    ap.add_argument("--spp", default="4,16,64,256")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--ref-spp", type=int, default=2048)
    ap.add_argument("--flags", default="-r 480 360 -m 16 -l 1")
    ap.add_argument("--out", default=os.path.join(ROOT, "build", "report"))
    ap.add_argument("--denoise", action="store_true", help="also with --denoise, and check the aim")
    ap.add_argument("--keep", action="store_true", help="keep the images (for crops: bench/denoise_crops.py)")
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    rows = []
    for scene in a.scenes:
        ref = reference(scene, a.flags, a.ref_spp)
        name = os.path.splitext(os.path.basename(scene))[0]
        for spp in [int(s) for s in a.spp.split(",")]:
            for seed in range(1, a.seeds + 1):
                for renderer, extra in [("tessera", [])] + ([("tessera+denoise", ["--denoise"])] if a.denoise else []):
                    img = os.path.join(a.out, "%s-%d-%d%s.exr" % (name, spp, seed, "-denoised" if extra else ""))
                    stats = os.path.join(a.out, "stats.json")
                    run([os.path.join(BIN, "tessera"), "render", scene, "-s", str(spp), "--seed", str(seed), "-q",
                         "-f", img, "--stats-json", stats] + a.flags.split() + extra)
                    with open(stats) as f:
                        st = json.load(f)
                    seconds = st["seconds"] + st.get("denoise_seconds", 0)
                    e = compare(img, ref)
                    rows.append({"renderer": renderer, "scene": name, "spp": spp, "seed": seed, "seconds": seconds,
                                 "rmse": e["rmse"], "relmse": e["relmse"], "efficiency": 1 / (e["relmse"] * seconds)})
                    if not a.keep:
                        os.remove(img)
    write_outputs(rows, a.out, "Tessera, flags `%s`, reference %d spp" % (a.flags, a.ref_spp))
    if a.denoise:
        check_aim(summarize(rows))


def check_aim(table):
    """Issue 26's aim: a denoised render has the error of 4x the samples in at most 1.2x the
    time."""
    print("\n| scene | spp | denoised relMSE | relMSE at 4x spp | time ratio | aim met |")
    print("|---|---|---|---|---|---|")
    for scene in sorted({t["scene"] for t in table}):
        plain = {t["spp"]: t for t in table if t["scene"] == scene and t["renderer"] == "tessera"}
        den = {t["spp"]: t for t in table if t["scene"] == scene and t["renderer"] == "tessera+denoise"}
        # The largest count whose 4x was rendered too; else the largest, its 4x predicted.
        measured = [s for s in den if 4 * s in plain]
        n = max(measured) if measured else max(den)
        target = plain[4 * n]["relmse"] if 4 * n in plain else plain[n]["relmse"] / 4
        ratio = den[n]["seconds"] / plain[n]["seconds"]
        met = den[n]["relmse"] <= target and ratio <= 1.2
        print("| %s | %d | %.4g | %.4g%s | %.3f | %s |" % (scene, n, den[n]["relmse"], target,
                                                         "" if 4 * n in plain else " (predicted)", ratio,
                                                         "yes" if met else "no"))


def summarize(rows):
    groups = {}
    for r in rows:
        groups.setdefault((r["renderer"], r["scene"], r["spp"]), []).append(r)
    out = []
    for (renderer, scene, spp), g in sorted(groups.items()):
        sec = sum(r["seconds"] for r in g) / len(g)
        rel = sum(r["relmse"] for r in g) / len(g)
        rmse = sum(r["rmse"] for r in g) / len(g)
        out.append({"renderer": renderer, "scene": scene, "spp": spp, "seeds": len(g), "seconds": sec, "rmse": rmse,
                    "relmse": rel, "efficiency": 1 / (rel * sec)})
    return out


def write_outputs(rows, out, title):
    with open(os.path.join(out, "error.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0].keys()))
        w.writeheader()
        w.writerows(rows)
    table = summarize(rows)
    print("| renderer | scene | spp | seeds | seconds | RMSE | relMSE | efficiency |")
    print("|---|---|---|---|---|---|---|---|")
    for t in table:
        print("| %s | %s | %d | %d | %.2f | %.4g | %.4g | %.4g |" % (t["renderer"], t["scene"], t["spp"], t["seeds"],
                                                                    t["seconds"], t["rmse"], t["relmse"], t["efficiency"]))
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    for key in sorted({(t["renderer"], t["scene"]) for t in table}):
        pts = [t for t in table if (t["renderer"], t["scene"]) == key]
        xs, ys = [p["seconds"] for p in pts], [p["relmse"] for p in pts]
        line, = ax.loglog(xs, ys, "o-", label="%s %s" % key)
        ax.loglog([xs[0], xs[-1]], [ys[0], ys[0] * xs[0] / xs[-1]], "--", color=line.get_color(), alpha=0.5, linewidth=1)
    ax.set_xlabel("seconds (2 threads)")
    ax.set_ylabel("relMSE against the reference")
    ax.set_title(title, fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, title="dashed: ideal slope -1", title_fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "error.png"), dpi=110)
    print("\nwrote %s and %s" % (os.path.join(out, "error.csv"), os.path.join(out, "error.png")), file=sys.stderr)


if __name__ == "__main__":
    main()
