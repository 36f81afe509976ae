#!/usr/bin/env python3
"""The farm against a local render of the same frame on the same cores.

On whatever machine it runs: renders one frame with `tessera render -t N` (N = every core)
and through a local farm (a coordinator on 127.0.0.1 and W workers of T threads, W x T = N)
for every split of the cores, each farm run beside a local run, REPEAT times. Prints per
split the median seconds of the whole commands, the median of the farm/local ratios of
those pairs, the workers' render-thread utilization during
the job (busy thread-seconds over threads x the job's elapsed time), the results' bytes a
job (compressed sums, and the light paths' splat records: tessera_result_bytes_total and
tessera_splat_bytes_total), and whether the farm image equals the local one bit for bit. Exits non-zero if an image differs.

Usage: bench/farm_scale.py [--bin DIR] [--scene FILE] [--cores N] [--splits 1x2,2x1]
                           [--repeat R] [--json FILE] [--markdown] [-- RENDER FLAGS...]
Default flags: -r 480 360 -s 64 (our Cornell box).
"""
import argparse
import json
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
import urllib.request

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def splits_of(n):
    return [(w, n // w) for w in range(1, n + 1) if n % w == 0]


class Farm:
    """A coordinator and W workers of T threads on loopback, started and stopped by us."""

    def __init__(self, bin_dir, workers, threads, tmp, coordinator_flags=()):
        self.procs = []
        os.makedirs(tmp, exist_ok=True)
        data = os.path.join(tmp, "data")
        out = open(os.path.join(tmp, "coordinator.out"), "w+")
        self.procs.append(subprocess.Popen(
            [os.path.join(bin_dir, "tessera-coordinator"), "--listen", "127.0.0.1:0", "--http", "127.0.0.1:0",
             "--data", data, *coordinator_flags], stdout=out, stderr=subprocess.DEVNULL))
        self.grpc = self.http = None
        for _ in range(200):
            out.seek(0)
            text = out.read()
            g = re.search(r"grpc listening on (\S+)", text)
            h = re.search(r"http listening on (\S+)", text)
            if g and h:
                self.grpc, self.http = g.group(1), h.group(1)
                break
            time.sleep(0.05)
        if not self.grpc:
            self.stop()
            raise RuntimeError("the coordinator did not start")
        for i in range(workers):
            self.procs.append(subprocess.Popen(
                [os.path.join(bin_dir, "tessera-worker"), "--coordinator", self.grpc, "--threads", str(threads),
                 "--cache", os.path.join(tmp, f"cache{i}"), "--name", f"w{i}"],
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        for _ in range(200):  # every worker registered before the clock starts
            if len(self.status()["workers"]) == workers:
                return
            time.sleep(0.05)
        self.stop()
        raise RuntimeError("the workers did not register")

    def status(self):
        with urllib.request.urlopen(f"http://{self.http}/api/status", timeout=10) as r:
            return json.load(r)

    def counter(self, name):
        """A counter of the coordinator's /metrics (0 when absent)."""
        with urllib.request.urlopen(f"http://{self.http}/metrics", timeout=10) as r:
            m = re.search(r"^" + name + r" (\S+)$", r.read().decode(), re.M)
            return float(m.group(1)) if m else 0.0

    def stop(self):
        for p in reversed(self.procs):
            p.terminate()
        for p in self.procs:
            try:
                p.wait(10)
            except subprocess.TimeoutExpired:
                p.kill()


def timed(cmd):
    t0 = time.monotonic()
    r = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    if r.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)}: exit {r.returncode}: {r.stderr.strip()}")
    return time.monotonic() - t0, r.stdout


def frames_of(spec):
    """The frames of a --frames SPEC (as core/render/frames.h reads it: 1-8, 1-9x2, 1,5,9)."""
    out = []
    for part in spec.split(","):
        m = re.fullmatch(r"(-?\d+)(?:-(-?\d+)(?:x(\d+))?)?", part)
        if not m:
            raise SystemExit(f"--frames: cannot read '{part}'")
        a, b, step = int(m[1]), int(m[2] if m[2] else m[1]), int(m[3] or 1)
        out += list(range(a, b + 1, step))
    return out


def frame_path(pattern, n):
    """`pattern` with its last run of '#' replaced by the zero-padded frame number."""
    m = list(re.finditer(r"#+", pattern))
    if not m:
        return pattern
    r = m[-1]
    return pattern[:r.start()] + str(n).zfill(len(r[0])) + pattern[r.end():]


def identical(bin_dir, a, b):
    r = subprocess.run([os.path.join(bin_dir, "tessera_compare"), a, b], stdout=subprocess.PIPE, text=True, check=True)
    return json.loads(r.stdout)["identical"]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    ap.add_argument("--bin", default=os.path.join(ROOT, "build", "bin"))
    ap.add_argument("--scene", default=os.path.join(ROOT, "scenes", "cornell-spheres.dae"))
    ap.add_argument("--cores", type=int, default=os.cpu_count())
    ap.add_argument("--splits", help="comma-separated WxT, default every split of --cores")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--json", help="write the results here")
    ap.add_argument("--markdown", action="store_true", help="print the table as Markdown")
    ap.add_argument("--coordinator-flags", default="",
                    help="extra coordinator flags, e.g. '--verify-fraction 0' (quoted, split on spaces)")
    ap.add_argument("--frames", help="a sequence (--frames SPEC) instead of one frame: every frame compared")
    ap.add_argument("flags", nargs="*", help="render flags (after --)")
    a = ap.parse_args()
    flags = a.flags or ["-r", "480", "360", "-s", "64"]
    frames = frames_of(a.frames) if a.frames else [None]
    if a.frames:
        flags = [*flags, "--frames", a.frames]
    suffix = ".####.exr" if a.frames else ".exr"

    def same_images(x, y):
        return all(identical(a.bin, frame_path(x, n) if n is not None else x, frame_path(y, n) if n is not None else y)
                   for n in frames)
    splits = [tuple(int(x) for x in s.split("x")) for s in a.splits.split(",")] if a.splits else splits_of(a.cores)
    tmp = tempfile.mkdtemp(prefix="tessera_farm_scale_")
    tessera = os.path.join(a.bin, "tessera")
    rows = []
    try:
        local_exr = os.path.join(tmp, "local" + suffix)
        local = [timed([tessera, "render", a.scene, *flags, "-t", str(a.cores), "-q", "-f", local_exr])[0]
                 for _ in range(a.repeat)]
        for w, t in splits:
            farm = Farm(a.bin, w, t, os.path.join(tmp, f"{w}x{t}"), a.coordinator_flags.split())
            try:
                secs, ratios, utils, same = [], [], [], True
                for r in range(a.repeat):
                    # Each farm run beside a local run: the ratio of the pair is what a
                    # shared, drifting machine changes least.
                    local.append(timed([tessera, "render", a.scene, *flags, "-t", str(a.cores), "-q", "-f",
                                        local_exr])[0])
                    before = {x["id"]: x["busy_thread_seconds"] for x in farm.status()["workers"]}
                    out = os.path.join(tmp, f"farm_{w}x{t}_{r}" + suffix)
                    s, stdout = timed([tessera, "submit", a.scene, *flags, "--coordinator", farm.grpc, "--wait", "-q",
                                       "--json", "-f", out])
                    job = json.loads(stdout)
                    st = farm.status()
                    busy = sum(x["busy_thread_seconds"] - before.get(x["id"], 0) for x in st["workers"])
                    threads = sum(x["threads"] for x in st["workers"])
                    secs.append(s)
                    ratios.append(s / local[-1])
                    utils.append(busy / (threads * job["elapsed_seconds"]) if job["elapsed_seconds"] > 0 else 0)
                    same = same and same_images(out, local_exr)
                sums_bytes = farm.counter("tessera_result_bytes_total") / a.repeat
                splat_bytes = farm.counter("tessera_splat_bytes_total") / a.repeat
            finally:
                farm.stop()
            rows.append({"workers": w, "threads": t, "seconds": statistics.median(secs),
                         "farm_over_local": statistics.median(ratios), "utilization": statistics.median(utils),
                         "sums_bytes": sums_bytes, "splat_bytes": splat_bytes, "identical": same})
        local_s = statistics.median(local)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)

    title = f"{os.path.basename(a.scene)} {' '.join(flags)}, {a.cores} cores, median of {a.repeat}"
    if a.markdown:
        print(f"{title}\n\n| run | seconds | farm/local | utilization | sums, splats a job (MB) | image |\n"
              "|---|---|---|---|---|---|")
        print(f"| `tessera render -t {a.cores}` | {local_s:.2f} | 1.000 | | | reference |")
        for r in rows:
            print(f"| farm, {r['workers']} x {r['threads']} | {r['seconds']:.2f} | {r['farm_over_local']:.3f} | "
                  f"{100 * r['utilization']:.1f}% | {r['sums_bytes'] / 1e6:.2f}, {r['splat_bytes'] / 1e6:.2f} | "
                  f"{'identical' if r['identical'] else 'DIFFERS'} |")
    else:
        print(title)
        print(f"{'run':<24}{'seconds':>9}{'farm/local':>12}{'util':>8}{'sums MB':>9}{'splats MB':>10}  image")
        print(f"{'local -t ' + str(a.cores):<24}{local_s:>9.2f}{1:>12.3f}{'':>8}{'':>9}{'':>10}  reference")
        for r in rows:
            print(f"{'farm ' + str(r['workers']) + ' x ' + str(r['threads']):<24}{r['seconds']:>9.2f}"
                  f"{r['farm_over_local']:>12.3f}{100 * r['utilization']:>7.1f}%{r['sums_bytes'] / 1e6:>9.2f}"
                  f"{r['splat_bytes'] / 1e6:>10.2f}  {'identical' if r['identical'] else 'DIFFERS'}")
    if a.json:
        with open(a.json, "w") as f:
            json.dump({"scene": a.scene, "flags": flags, "cores": a.cores, "local_seconds": local_s,
                       "splits": rows}, f, indent=2)
    return 0 if all(r["identical"] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
