#!/usr/bin/env python3
"""Big work in bounded memory (issue 22): a big frame, a long sequence, a big scene.

Each part starts its own local farm (a coordinator on 127.0.0.1, default settings, and 2
workers of nproc/2 threads) and reads the coordinator's RSS from /proc (the peak: VmHWM just
before SIGTERM, else the most VmRSS seen every 0.2 s) and its I/O (/proc/PID/io):
  still     one frame by `tessera render -t 0` and by the farm: seconds, the coordinator's
            peak RSS against one film's sums (width x height x 40 B; the aim is <= 1.5),
            its bytes read and written, the EXRs' sizes, pixels identical (tessera_compare).
  sequence  many small frames by the farm: the coordinator's RSS after startup, at 10% of
            the frames, at the end and its peak, seconds, the data folder at the end and
            after `tessera delete` (it should be ~the database only).
  scene     a glTF whose .bin is N MiB (a small box, then filler no accessor reads), tiny,
            locally and by the farm: upload+render seconds, the coordinator's peak RSS
            against the bundle's size, image equality.
Exits 1 if an image differs, 2 if something failed (the processes' stderr is shown).

Usage: bench/big_frame.py [--bin DIR] [--parts still,sequence,scene] [--scene FILE] [--rtt-ms MS] [--mbit M]
                          [--still-flags "-r 7680 4320 -s 2"] [--seq-flags "-r 64 48 -s 1 --pass-spp 1"]
                          [--seq-frames 1-1000] [--scene-mb 1024] [--json FILE] [--markdown] [--keep]
Small try: bench/big_frame.py --still-flags "-r 640 360 -s 1" --seq-frames 1-40 --scene-mb 20
"""
import argparse
import json
import os
import re
import shlex
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
import threading
import time
import urllib.request

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
MB = 1 << 20


def proc_kb(pid, key):
    """A /proc/PID/status field (VmRSS, VmHWM) in bytes, or None."""
    try:
        m = re.search(key + r":\s+(\d+) kB", open(f"/proc/{pid}/status").read())
        return int(m[1]) * 1024 if m else None
    except OSError:
        return None


def disk_usage(path):
    """Bytes on disk under path, as du counts them (blocks, each inode once)."""
    names = [os.path.join(d, f) for d, ds, fs in os.walk(path) for f in [""] + fs] if os.path.isdir(path) else [path]
    stats = {(st.st_dev, st.st_ino): st.st_blocks for st in map(os.lstat, filter(os.path.lexists, names))}
    return 512 * sum(stats.values())


class Farm:
    """A coordinator (default settings) and W workers of T threads on loopback; stderr to files."""

    def __init__(self, bin_dir, workers, threads, tmp, rtt_ms=0, mbit=0):
        self.rss_max, self.final, self.polling, self.data = 0, None, True, os.path.join(tmp, "data")
        os.makedirs(tmp, exist_ok=True)
        out = open(os.path.join(tmp, "coordinator.out"), "w+")
        self.coordinator = subprocess.Popen(
            [os.path.join(bin_dir, "tessera-coordinator"), "--listen", "127.0.0.1:0", "--http", "127.0.0.1:0",
             "--data", self.data], stdout=out, stderr=open(os.path.join(tmp, "coordinator.err"), "w"))
        self.procs = [self.coordinator]
        threading.Thread(target=self._poll, daemon=True).start()
        try:
            for _ in range(200):
                out.seek(0)
                m = re.search(r"grpc listening on (\S+)[\s\S]*http listening on (\S+)", out.read())
                if m:
                    break
                time.sleep(0.05)
            if not m:
                raise RuntimeError("the coordinator did not start")
            self.grpc, self.http = m[1], m[2]
            for i in range(workers):
                addr = self.grpc
                if rtt_ms or mbit:  # each worker behind its own long link (bench/wan/wan_link.h)
                    proxy = subprocess.Popen(
                        [os.path.join(bin_dir, "tessera-wan-proxy"), "--to", self.grpc, "--rtt-ms", str(rtt_ms),
                         "--mbit", str(mbit)], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
                    self.procs.append(proxy)
                    addr = proxy.stdout.readline().split()[-1]
                self.procs.append(subprocess.Popen(
                    [os.path.join(bin_dir, "tessera-worker"), "--coordinator", addr, "--threads",
                     str(threads), "--cache", os.path.join(tmp, f"cache{i}"), "--name", f"w{i}"],
                    stdout=subprocess.DEVNULL, stderr=open(os.path.join(tmp, f"worker{i}.err"), "w")))
            for _ in range(200):  # every worker registered before the clock starts
                if len(self.status()["workers"]) == workers:
                    return
                time.sleep(0.05)
            raise RuntimeError("the workers did not register")
        except BaseException:
            self.stop()
            raise

    def _poll(self):
        while self.polling:  # the peak where VmHWM is missing
            self.rss_max = max(self.rss_max, self.rss() or 0)
            time.sleep(0.2)

    def rss(self):
        return proc_kb(self.coordinator.pid, "VmRSS")

    def status(self):
        with urllib.request.urlopen(f"http://{self.http}/api/status", timeout=30) as r:
            return json.load(r)

    def stop(self):
        """Stops every process; the coordinator's peak RSS and I/O are read just before."""
        if self.final is None:  # (a coordinator gone already: what was polled)
            hwm = proc_kb(self.coordinator.pid, "VmHWM") if self.coordinator.poll() is None else None
            self.final = {"peak_rss": hwm or max(self.rss_max, self.rss() or 0), "io": {}}
            try:
                io = open(f"/proc/{self.coordinator.pid}/io")
                self.final["io"] = {k: int(v) for k, v in (x.split(":") for x in io)}
            except OSError:
                pass
        self.polling = False
        for p in reversed(self.procs):
            if p.poll() is None:
                p.send_signal(signal.SIGTERM)
        for p in self.procs:
            try:
                p.wait(10)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
        return self.final


def run(cmd, err_file, out_file=None, poll=None):
    """Runs cmd, stdout and stderr to files, calling poll() every 0.2 s meanwhile; returns (seconds,
    stdout). Raises with its stderr on failure."""
    t0 = time.monotonic()
    with open(err_file, "w") as err, open(out_file or err_file[:-4] + ".out", "w+") as out:
        p = subprocess.Popen(cmd, stdout=out, stderr=err, text=True)
        try:
            while True:
                try:
                    p.wait(0.2)
                    break
                except subprocess.TimeoutExpired:
                    if poll:
                        poll()
        finally:
            if p.poll() is None:
                p.kill()
                p.wait()
        out.seek(0)
        text = out.read()
    if p.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)}: exit {p.returncode}: {open(err_file).read().strip()[-2000:]}")
    return time.monotonic() - t0, text


def identical(bin_dir, a, b):
    """tessera_compare's "identical" (every channel bit for bit); an error (e.g. sizes differ) is False."""
    r = subprocess.run([os.path.join(bin_dir, "tessera_compare"), a, b], stdout=subprocess.PIPE,
                       stderr=subprocess.PIPE, text=True)
    if r.returncode != 0:
        print(f"tessera_compare {a} {b}: {r.stderr.strip()}", file=sys.stderr)
    return r.returncode == 0 and bool(json.loads(r.stdout)["identical"])


def mib(n):
    return f"{n / MB:.1f} MiB" if n is not None else "n/a"


class Bench:
    def __init__(self, a, tmp):
        self.a, self.tmp, self.farms, self.rows, self.results, self.differs = a, tmp, [], [], {}, False
        self.workers, self.threads = 2, max(1, len(os.sched_getaffinity(0)) // 2)
        self.tessera = os.path.join(a.bin, "tessera")

    def row(self, part, key, measure, raw, shown=None):
        self.rows.append((part, measure, shown if shown is not None else mib(raw)))
        if key:
            self.results.setdefault(part, {})[key] = raw

    def farm(self, d):
        f = Farm(self.a.bin, self.workers, self.threads, os.path.join(d, "farm"), self.a.rtt_ms, self.a.mbit)
        self.farms.append(f)
        return f

    def local_and_farm(self, p, d, scene, flags):
        """The frame by `tessera render -t 0` and by a fresh farm: rows for both; returns (startup RSS, peak RSS)."""
        local_exr, farm_exr = os.path.join(d, "local.exr"), os.path.join(d, "farm.exr")
        local_s, _ = run([self.tessera, "render", scene, *flags, "-t", "0", "-q", "-f", local_exr],
                         os.path.join(d, "render.err"))
        farm = self.farm(d)
        start = farm.rss()
        farm_s, _ = run([self.tessera, "submit", scene, *flags, "--coordinator", farm.grpc, "--wait", "-q",
                         "-f", farm_exr], os.path.join(d, "submit.err"))
        final = farm.stop()
        same = identical(self.a.bin, farm_exr, local_exr)
        self.differs |= not same
        self.row(p, "local_seconds", "local render -t 0 (s)", local_s, f"{local_s:.2f}")
        self.row(p, "farm_seconds", f"farm {self.workers}x{self.threads} submit --wait (s)", farm_s, f"{farm_s:.2f}")
        self.row(p, "farm_over_local", "farm / local", farm_s / local_s, f"{farm_s / local_s:.3f}")
        self.row(p, "start_rss", "coordinator RSS after startup", start)
        self.row(p, "peak_rss", "coordinator peak RSS", final["peak_rss"])
        io = final["io"]
        self.row(p, "io", "coordinator read_bytes / write_bytes", io,
                 f"{mib(io.get('read_bytes'))} / {mib(io.get('write_bytes'))}")
        self.row(p, None, "coordinator rchar / wchar", io, f"{mib(io.get('rchar'))} / {mib(io.get('wchar'))}")
        sizes = {"local": os.path.getsize(local_exr), "farm": os.path.getsize(farm_exr)}
        self.row(p, "exr_bytes", "EXR size local / farm", sizes, f"{mib(sizes['local'])} / {mib(sizes['farm'])}")
        self.row(p, "identical", "farm image vs local", same, "identical" if same else "DIFFERS")
        return start or 0, final["peak_rss"]

    def still(self):
        d = os.path.join(self.tmp, "still")
        os.makedirs(d)
        flags = shlex.split(self.a.still_flags)
        i = flags.index("-r") if "-r" in flags else -1
        w, h = (int(flags[i + 1]), int(flags[i + 2])) if i >= 0 else (480, 360)
        film = w * h * 40
        self.row("still", "film_bytes", f"frame {w}x{h}, one film's sums (x40 B)", film)
        start, peak = self.local_and_farm("still", d, self.a.scene, flags)
        self.row("still", "peak_over_film", "peak RSS / film (aim <= 1.5)", peak / film, f"{peak / film:.2f}")
        self.row("still", "peak_above_start_over_film", "(peak - startup) / film", (peak - start) / film,
                 f"{(peak - start) / film:.2f}")

    def sequence(self):
        a, d, p = self.a, os.path.join(self.tmp, "sequence"), "sequence"
        os.makedirs(os.path.join(d, "out"))
        farm = self.farm(d)
        start, seen = farm.rss(), {"at10": None}

        def poll():  # the coordinator's RSS when a tenth of the frames are done
            jobs = farm.status()["jobs"]
            if jobs and seen["at10"] is None and jobs[0].get("frames_done", 0) >= jobs[0].get("frames_total", 1) / 10:
                seen["at10"] = farm.rss()
        secs, out = run([self.tessera, "submit", a.scene, *shlex.split(a.seq_flags), "--frames", a.seq_frames,
                         "--coordinator", farm.grpc, "--wait", "-q", "--json", "-f",
                         os.path.join(d, "out", "f.####.exr")], os.path.join(d, "submit.err"),
                        os.path.join(d, "submit.out"), poll)
        job = json.loads(out)
        total, end, data_end = job.get("frames_total", 0), farm.rss(), disk_usage(farm.data)
        written = len(os.listdir(os.path.join(d, "out")))
        run([self.tessera, "delete", job["id"], "--coordinator", farm.grpc], os.path.join(d, "delete.err"))
        time.sleep(0.5)
        data_del = disk_usage(farm.data)
        db = sum(disk_usage(os.path.join(farm.data, f)) for f in os.listdir(farm.data)
                 if f.startswith("coordinator.db"))
        peak = farm.stop()["peak_rss"]
        self.row(p, "frames", f"frames ({a.seq_frames}), EXRs written", total, f"{total}, {written}")
        self.row(p, "seconds", f"farm {self.workers}x{self.threads} submit --wait (s)", secs, f"{secs:.2f}")
        self.row(p, "start_rss", "coordinator RSS after startup", start)
        self.row(p, "rss_at_10_percent", "coordinator RSS at 10% of frames", seen["at10"])
        self.row(p, "end_rss", "coordinator RSS at the end", end)
        self.row(p, "peak_rss", "coordinator peak RSS", peak)
        self.row(p, "data_bytes_end", "data folder at the end", data_end)
        self.row(p, "data_bytes_after_delete", "data folder after delete", data_del)
        self.row(p, "database_bytes", "  of which the database", db)
        if written != total:
            raise RuntimeError(f"sequence: {written} EXRs written of {total} frames")

    def scene(self):
        a, d = self.a, os.path.join(self.tmp, "scene")
        os.makedirs(d)
        gltf, binf = os.path.join(d, "big.gltf"), os.path.join(d, "big.bin")
        try:
            write_big_gltf(gltf, binf, a.scene_mb * MB)
            bundle = os.path.getsize(binf) + os.path.getsize(gltf)
            self.row("scene", "bundle_bytes", "bundle (.gltf + .bin)", bundle)
            start, peak = self.local_and_farm("scene", d, gltf, ["-r", "64", "48", "-s", "1"])
        finally:
            for f in (gltf, binf) if not a.keep else ():
                if os.path.exists(f):
                    os.remove(f)
        self.row("scene", "peak_over_bundle", "peak RSS / bundle", peak / bundle, f"{peak / bundle:.3f}")
        self.row("scene", "peak_above_start_over_bundle", "(peak - startup) / bundle", (peak - start) / bundle,
                 f"{(peak - start) / bundle:.3f}")


def write_big_gltf(gltf, binf, total):
    """A box (24 vertices with normals, 36 indices) at the start of one buffer of `total` bytes, the
    rest random filler that no accessor reads; the buffer's byteLength is the whole file."""
    pos, nrm, idx = [], [], []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            u, v, base = (axis + 1) % 3, (axis + 2) % 3, len(pos)
            for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                p, n = [0.0] * 3, [0.0] * 3
                p[axis], p[u], p[v], n[axis] = sign * 0.5, a * 0.5, b * 0.5, sign
                pos.append(p)
                nrm.append(n)
            idx += [base + q for q in ([0, 1, 2, 0, 2, 3] if sign > 0 else [0, 2, 1, 0, 3, 2])]
    head = b"".join(struct.pack("<3f", *x) for x in pos + nrm) + struct.pack(f"<{len(idx)}H", *idx)
    head += b"\0" * (-len(head) % 4)
    if total < len(head):
        raise SystemExit(f"--scene-mb: at least {len(head)} bytes")
    with open(binf, "wb") as f:
        f.write(head)
        for left in range(total - len(head), 0, -MB):
            f.write(os.urandom(min(left, MB)))
    nv = len(pos)
    views = [(0, 12 * nv, 34962), (12 * nv, 12 * nv, 34962), (24 * nv, 2 * len(idx), 34963)]
    doc = {
        "asset": {"version": "2.0", "generator": "bench/big_frame.py"},
        "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0, "rotation": [0.2, 0.3, 0.0, 0.9327]}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1}, "indices": 2, "material": 0}]}],
        "materials": [{"pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.5, 0.3, 1], "metallicFactor": 0,
                                                "roughnessFactor": 0.7}}],
        "buffers": [{"uri": os.path.basename(binf), "byteLength": total}],
        "bufferViews": [{"buffer": 0, "byteOffset": o, "byteLength": n, "target": t} for o, n, t in views],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": nv, "type": "VEC3",
                       "min": [-0.5] * 3, "max": [0.5] * 3},
                      {"bufferView": 1, "componentType": 5126, "count": nv, "type": "VEC3"},
                      {"bufferView": 2, "componentType": 5123, "count": len(idx), "type": "SCALAR"}]}
    with open(gltf, "w") as f:
        json.dump(doc, f)


def machine():
    mem = int(re.search(r"MemTotal:\s+(\d+)", open("/proc/meminfo").read())[1]) * 1024
    commit = subprocess.run(["git", "-C", ROOT, "rev-parse", "--short", "HEAD"], stdout=subprocess.PIPE,
                            stderr=subprocess.DEVNULL, text=True).stdout.strip() or "unknown"
    return {"nproc": len(os.sched_getaffinity(0)), "memory_bytes": mem, "commit": commit}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    ap.add_argument("--bin", default=os.path.join(ROOT, "build", "bin"))
    ap.add_argument("--parts", default="still,sequence,scene", help="comma-separated: still,sequence,scene")
    ap.add_argument("--scene", default=os.path.join(ROOT, "scenes", "cornell-spheres.dae"),
                    help="the scene of the still and sequence parts")
    ap.add_argument("--still-flags", default="-r 7680 4320 -s 2")
    ap.add_argument("--seq-flags", default="-r 64 48 -s 1 --pass-spp 1")
    ap.add_argument("--seq-frames", default="1-1000")
    ap.add_argument("--scene-mb", type=int, default=1024, help="the scene part's .bin in MiB (at most 1024)")
    ap.add_argument("--rtt-ms", type=float, default=0,
                    help="workers reach the coordinator through tessera-wan-proxy with this round trip")
    ap.add_argument("--mbit", type=float, default=0, help="... and this rate each way (0: unlimited)")
    ap.add_argument("--json", help="write the results here")
    ap.add_argument("--markdown", action="store_true", help="print the table as Markdown")
    ap.add_argument("--keep", action="store_true", help="keep the temporary folder (printed)")
    a = ap.parse_args()
    a.bin, a.scene = os.path.abspath(a.bin), os.path.abspath(a.scene)
    parts = [p.strip() for p in a.parts.split(",") if p.strip()]
    if set(parts) - {"still", "sequence", "scene"}:
        ap.error(f"--parts: unknown part in '{a.parts}'")
    if not 1 <= a.scene_mb <= 1024:
        ap.error("--scene-mb: 1 to 1024 (a glTF buffer is at most 1 GiB)")
    m = machine()
    print(f"machine: {m['nproc']} cores, {m['memory_bytes'] / (1 << 30):.1f} GiB memory; commit {m['commit']}; "
          f"binaries {a.bin}", flush=True)
    tmp = tempfile.mkdtemp(prefix="tessera_big_frame_")
    bench, failed = Bench(a, tmp), False
    try:
        for p in parts:
            getattr(bench, p)()
    except Exception as e:  # the error, then every process's stderr
        failed = True
        print(f"error: {e}", file=sys.stderr)
        for d, _, files in os.walk(tmp):
            for f in sorted(files):
                if f.endswith(".err") and os.path.getsize(os.path.join(d, f)):
                    print(f"--- {os.path.relpath(os.path.join(d, f), tmp)}:\n"
                          f"{open(os.path.join(d, f), errors='replace').read()[-3000:]}", file=sys.stderr)
    finally:
        for f in bench.farms:
            f.stop()
        if a.keep:
            print(f"kept {tmp}")
        else:
            shutil.rmtree(tmp, ignore_errors=True)

    if bench.rows:
        line = "| {} | {} | {} |" if a.markdown else "{:<10}{:<44}{}"
        print("\n" + line.format("part", "measure", "value") + ("\n|---|---|---|" if a.markdown else ""))
        for r in bench.rows:
            print(line.format(*r))
    if a.json:
        with open(a.json, "w") as f:
            json.dump({"machine": m, "args": vars(a), "workers": bench.workers, "threads": bench.threads,
                       "results": bench.results, "failed": failed}, f, indent=2)
    return 2 if failed else 1 if bench.differs else 0


if __name__ == "__main__":
    sys.exit(main())
