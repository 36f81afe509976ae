#!/usr/bin/python3
"""Model only what a scene needs, in numbers: for each scene, which techniques the
renderer uses, and what each costs (samples per second) and buys (relMSE and efficiency
against the converged reference), by switching them off or on one at a time:

  all on         the default: NEE + MIS at non-delta vertices; pinhole camera
  no MIS         light sampling alone for area lights (--no-mis)
  no NEE         BSDF sampling alone (--no-nee)
  thin lens      the lens sample drawn per camera ray (-b 0.1 -d 4.8): what the pinhole
                 path saves when the aperture is 0 (the image differs, so only speed counts)

Fresnel and microfacet evaluation are per material: a scene without glass never evaluates
Fresnel, one without microfacet materials never evaluates Beckmann; the table says which
each scene has. Usage: bench/features.py SCENE... [--spp 16] [--ref-spp 2048]
"""
import argparse
import json
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import error_report as er  # noqa: E402

FLAGS = "-r 480 360 -m 16 -l 1"
VARIANTS = [("all on", []), ("no MIS", ["--no-mis"]), ("no NEE", ["--no-nee"]), ("thin lens", ["-b", "0.1", "-d", "4.8"])]


def materials(scene):
    text = open(scene).read()
    return ", ".join(k for k, tag in (("glass (Fresnel)", "<glass>"), ("refraction", "<refraction>"),
                                      ("mirror", "<mirror>"), ("microfacet", "<microfacet>")) if tag in text) or "diffuse only"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("scenes", nargs="+")
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--ref-spp", type=int, default=2048)
    ap.add_argument("--out", default=os.path.join(er.ROOT, "build", "report"))
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    print("| scene | materials | variant | samples/s | cost vs all on | relMSE | efficiency | efficiency vs all on |")
    print("|---|---|---|---|---|---|---|---|")
    for scene in a.scenes:
        name = os.path.splitext(os.path.basename(scene))[0]
        ref = er.reference(scene, FLAGS, a.ref_spp)
        base = None
        for label, extra in VARIANTS:
            img, stats = os.path.join(a.out, "feature.exr"), os.path.join(a.out, "stats.json")
            er.run([os.path.join(er.BIN, "tessera"), "render", scene, "-s", str(a.spp), "--seed", "3", "-t", "2", "-q",
                    "-f", img, "--stats-json", stats] + FLAGS.split() + extra)
            st = json.load(open(stats))
            e = er.compare(img, ref)
            eff = 1 / (e["relmse"] * st["seconds"])
            if base is None:
                base = (st["samples_per_second"], eff)
            lens = label == "thin lens"
            print("| %s | %s | %s | %.2f M | %+.1f%% | %s | %s | %s |" % (
                name, materials(scene), label, st["samples_per_second"] / 1e6, 100 * (base[0] / st["samples_per_second"] - 1),
                "(other image)" if lens else "%.4g" % e["relmse"], "" if lens else "%.4g" % eff,
                "" if lens else "%.2fx" % (eff / base[1])))


if __name__ == "__main__":
    main()
