#!/usr/bin/python3
"""The denoiser's gallery (docs/gallery.md, "Denoising"): for each scene, a noisy render,
the same render with --denoise and a long reference, as full frames and as crops where a
denoiser fails first (edges, textures, glass, caustics, depth of field), each crop shown 2x
(nearest neighbour) in a noisy | denoised | reference strip. Writes
docs/gallery/denoise-NAME.png (the strip) and docs/gallery/denoise-log.txt (commands,
seconds, relMSE of noisy and denoised against the reference).

Usage: bench/denoise_gallery.py [--spp 64] [--ref-spp 1024] [--out docs/gallery]
Needs a build (build/bin) and ../shared/scenes/cs184/; python3-pil.
"""
import argparse
import json
import os
import subprocess
import sys

from PIL import Image

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BIN = os.path.join(ROOT, "build", "bin")
CS184 = os.path.join(ROOT, "..", "shared", "scenes", "cs184")

# name, scene, flags, crops (x, y, w, h in the frame: what each shows)
SCENES = [
    ("cbspheres", os.path.join(CS184, "CBspheres.dae"), "-r 320 240 -m 8 -l 1",
     [(170, 120, 80, 80, "the glass sphere's rim and highlight"), (60, 100, 80, 80, "the mirror sphere")]),
    ("dof-row", os.path.join(ROOT, "scenes", "dof-row.gltf"), "-r 360 240 -m 8 -b 0.15 -d 7",
     [(0, 150, 90, 90, "checker texture out of focus"), (140, 90, 90, 90, "spheres in and out of focus")]),
    ("cbdragon", os.path.join(CS184, "CBdragon.dae"), "-r 320 240 -m 8 -l 1",
     [(120, 90, 90, 90, "the gold dragon's fine geometry")]),
]


def run(cmd):
    p = subprocess.run(cmd, capture_output=True, text=True)
    if p.returncode != 0:
        sys.exit("error: %s\n%s" % (" ".join(cmd), p.stderr))
    return p.stdout


def render(scene, flags, spp, seed, out_exr, out_png, extra=()):
    stats = out_exr + ".json"
    cmd = [os.path.join(BIN, "tessera"), "render", scene, "-s", str(spp), "--seed", str(seed), "-q", "-f", out_exr,
           "-f", out_png, "--stats-json", stats] + flags.split() + list(extra)
    run(cmd)
    with open(stats) as f:
        st = json.load(f)
    os.remove(stats)
    return " ".join(cmd[1:]), st["seconds"] + st.get("denoise_seconds", 0)


def relmse(image, ref):
    return json.loads(run([os.path.join(BIN, "tessera_compare"), image, ref]))["relmse"]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--ref-spp", type=int, default=1024)
    ap.add_argument("--out", default=os.path.join(ROOT, "docs", "gallery"))
    a = ap.parse_args()
    work = os.path.join(ROOT, "build", "denoise-gallery")
    os.makedirs(work, exist_ok=True)
    log = []
    for name, scene, flags, crops in SCENES:
        if not os.path.exists(scene):
            print("skipping %s: %s is absent" % (name, scene), file=sys.stderr)
            continue
        p = lambda kind, ext: os.path.join(work, "%s-%s.%s" % (name, kind, ext))
        c1, t1 = render(scene, flags, a.spp, 1, p("noisy", "exr"), p("noisy", "png"))
        c2, t2 = render(scene, flags, a.spp, 1, p("denoised", "exr"), p("denoised", "png"), ["--denoise"])
        c3, t3 = render(scene, flags, a.ref_spp, 999, p("ref", "exr"), p("ref", "png"))
        e1, e2 = relmse(p("noisy", "exr"), p("ref", "exr")), relmse(p("denoised", "exr"), p("ref", "exr"))
        log += ["%s: %s" % (name, c) for c in (c1, c2, c3)]
        log.append("%s: %.1f s noisy, %.1f s denoised (render + denoise), %.1f s reference; relMSE %.4g noisy, "
                   "%.4g denoised (%.1fx lower)" % (name, t1, t2, t3, e1, e2, e1 / e2))
        frames = [Image.open(p(k, "png")).convert("RGB") for k in ("noisy", "denoised", "ref")]
        scale, gap = 2, 4
        rows = []
        for x, y, w, h, _ in crops:
            row = Image.new("RGB", (3 * w * scale + 2 * gap, h * scale), "white")
            for i, f in enumerate(frames):
                row.paste(f.crop((x, y, x + w, y + h)).resize((w * scale, h * scale), Image.NEAREST),
                          (i * (w * scale + gap), 0))
            rows.append(row)
        strip = Image.new("RGB", (max(r.width for r in rows), sum(r.height for r in rows) + gap * (len(rows) - 1)),
                          "white")
        y = 0
        for r in rows:
            strip.paste(r, (0, y))
            y += r.height + gap
        strip.save(os.path.join(a.out, "denoise-%s.png" % name), optimize=True)
        for k, f in zip(("noisy", "denoised"), frames):
            f.save(os.path.join(a.out, "denoise-%s-%s-full.jpg" % (name, k)), quality=88)
        print(log[-1])
    with open(os.path.join(a.out, "denoise-log.txt"), "w") as f:
        f.write("\n".join(log) + "\n")


if __name__ == "__main__":
    main()
