#!/usr/bin/python3
"""CTest entry (Docs.ExamplesRun): the shell examples of README.md and docs/*.md stay true
(issue 24). Standard library only.

  1. Flags: every command of ours (tessera SUBCOMMAND, tessera-coordinator,
     tessera-worker) in any ```sh block, run here or not, uses only options that
     command's --help lists; the bench scripts the blocks name, only options their
     --help lists. README's `tessera render` synopsis and flag table list exactly the
     options `tessera render --help` has.
  2. Runs: each ```sh block runs in one bash, its lines in order (comments dropped,
     continuation lines joined), in a scratch folder laid out like the repository
     (build/bin, scenes/, deploy/, bench/, and ../shared as the CS184 scenes'
     <source>/../shared), with HOME and TMPDIR in the scratch folder too. A line that
     exits non-zero fails the test, with the line as run, its exit code and its output.
     Files a command is told to write (-f, with #### as its frames) must exist after it.
     The repository's files a line names (deploy/..., bench/..., build/bin/...) exist,
     whether the line runs here or not.
  3. Shrunk: our render and submit commands get -s 1, -r 32 x (32 x H / W), -a 1 T, and a
     --frames range becomes two frames (the first, and a frame the block later fetches
     with --frame N if it has one); benchmark scripts get their own small settings
     (SHRINK_SCRIPTS). The shrunk command is printed.
  4. A farm: this script starts a coordinator (--listen 127.0.0.1:0 --http 127.0.0.1:0,
     addresses read from its "grpc listening on" line) and a worker on loopback, and
     gives the blocks TESSERA_COORDINATOR. A block that starts its own coordinator gets it
     in the background on 127.0.0.1:0 with a scratch --data, and its HOST:7878 /
     head:7878 become that coordinator's address; the block's workers run in the
     background and must still be running when the block ends. Certificates for HOST
     name 127.0.0.1 instead (SUBSTITUTIONS). Nothing but 127.0.0.1 is contacted.
  5. Placeholders: JOB is the newest job of the block's coordinator; scene.dae and
     shot.dae are copies of scenes/cornell-spheres.dae; a block that assumes files made
     elsewhere (the Slurm example's tokens and certificate) gets them from FIXTURES,
     printed; `sbatch` is a stand-in that runs the batch script here as a one-node,
     one-CPU allocation (with `srun` running its command). ```json camera paths are
     rendered with --camera-path. ```python blocks that import tessera run with
     build/python on the path against the same farm, shrunk (samples=1, 32 pixels wide,
     two frames of a range).
  6. Skips: lines and blocks that cannot run on a test machine are in ALLOW, each with
     its reason, printed when skipped; an ALLOW entry that matches nothing fails (the
     list stays exact). A line that needs ../shared is skipped, saying so, where it is
     absent.

Usage: docs_examples.py --source SOURCE_DIR --bin BIN_DIR [--keep] [--only FILE]
(or docs_examples.py SOURCE_DIR BIN_DIR)."""
import argparse
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time

from docs_parse import (check_flags, check_paths, check_render_reference, check_script_flags, doc_files,
                        expected_files, fail, failures, fenced, logical_lines, our_commands, rewrite,
                        shrink_python)
from docs_tables import ALLOW, FAKE_SBATCH, FAKE_SRUN, FIXTURES, PLACEHOLDERS, PRELUDE

# Commands whose default scenes are the CS184 ones under ../shared (no path on the line).
SHARED_BY_DEFAULT = (r"bench/cycles/caustics_report\.py",)

# ---- running ----------------------------------------------------------------------------

def start_farm(bin_dir, scratch):
    out = os.path.join(scratch, "farm-coordinator.out")
    coord = subprocess.Popen([os.path.join(bin_dir, "tessera-coordinator"), "--listen", "127.0.0.1:0", "--http",
                              "127.0.0.1:0", "--data", os.path.join(scratch, "farm-data")],
                             stdout=open(out, "w"), stderr=open(os.path.join(scratch, "farm-coordinator.err"), "w"),
                             stdin=subprocess.DEVNULL)
    grpc = None
    for _ in range(400):
        text = open(out).read()
        m = re.search(r"^grpc listening on (\S+)", text, re.M)
        if m and "http listening on" in text:
            grpc = m.group(1)
            break
        if coord.poll() is not None:
            break
        time.sleep(0.05)
    if not grpc:
        raise RuntimeError("the test's coordinator did not start: " + open(out.replace(".out", ".err")).read()[-500:])
    worker = subprocess.Popen([os.path.join(bin_dir, "tessera-worker"), "--coordinator", grpc, "--threads", "2",
                               "--cache", os.path.join(scratch, "farm-cache")],
                              stdout=subprocess.DEVNULL, stderr=open(os.path.join(scratch, "farm-worker.err"), "w"),
                              stdin=subprocess.DEVNULL)
    return grpc, [worker, coord]


def make_tree(src, bin_dir, scratch, n):
    """A folder laid out like the repository, for block n."""
    d = os.path.join(scratch, "blocks", f"{n:02d}")
    os.makedirs(os.path.join(d, "build"))
    os.symlink(bin_dir, os.path.join(d, "build", "bin"))
    for sub in ("scenes", "deploy", "bench", "docs", "tests"):
        os.symlink(os.path.join(src, sub), os.path.join(d, sub))
    for built in ("python", "blender"):  # the Python client and the Blender add-on
        if os.path.isdir(os.path.join(os.path.dirname(bin_dir), built)):
            os.symlink(os.path.join(os.path.dirname(bin_dir), built), os.path.join(d, "build", built))
    return d


def background(logs):
    """(pid, log prefix) of each coordinator and worker a block started in the background."""
    path = os.path.join(logs, "background")
    if not os.path.exists(path):
        return []
    return [(int(l.split()[0]), l.split()[1]) for l in open(path).read().splitlines() if len(l.split()) == 2]


def alive(pid):
    """Running, not a zombie waiting for its parent."""
    try:
        return open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()[0] != "Z"
    except (OSError, IndexError):
        return False


def run_block(rel, first, runs, fixture, env, src, scratch, n, timeout):
    """Runs one block's lines in one bash; returns the number of lines run."""
    d = make_tree(src, env["DOCS_BIN"], scratch, n)
    logs = os.path.join(scratch, "logs", f"{n:02d}")
    os.makedirs(logs)
    text = " ".join(l for _, l, _ in runs)
    for name, source in PLACEHOLDERS.items():
        if re.search(rf"(?<![\w/.-]){re.escape(name)}\b", text):
            shutil.copy(os.path.join(src, source), os.path.join(d, name))
    script = [PRELUDE]
    if fixture:
        print(f"      fixture ({fixture[0]}):\n        " + fixture[1].replace("\n", "\n        "))
        script += ["__docs_begin fixture", fixture[1], "__docs_end"]
    for lineno, _, run in runs:
        script += [f"__docs_begin {lineno}", run, "__docs_end"]
    script.append("__docs_finish")
    path = os.path.join(logs, "block.sh")
    open(path, "w").write("\n".join(script) + "\n")
    out_path = os.path.join(logs, "output")
    benv = dict(env, DOCS_LOGS=logs, DOCS_SCRATCH=os.path.join(scratch, "blocks", f"{n:02d}.data"))
    t0 = time.time()
    p = subprocess.Popen(["bash", path], cwd=d, env=benv, stdout=open(out_path, "w"), stderr=subprocess.STDOUT,
                         stdin=subprocess.DEVNULL, start_new_session=True)
    rc, died = None, None
    try:  # until the block ends, a coordinator or worker it started exits, or the time is up
        while rc is None and died is None and time.time() - t0 < timeout:
            time.sleep(0.1)
            rc = p.poll()
            if rc is None:
                died = next((log for pid, log in background(logs) if not alive(pid)), None)
    finally:
        try:  # the block's bash and everything it left running (one process group: its own)
            os.killpg(p.pid, signal.SIGTERM)
            time.sleep(0.2)
            os.killpg(p.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        p.wait()
    output = open(out_path, errors="replace").read()
    chunks = re.split(r"^@@docs-line (\S+)\n", output, flags=re.M)
    per_line = dict(zip(chunks[1::2], chunks[2::2]))
    last = chunks[-2] if len(chunks) > 1 else "?"
    by_no = {str(no): (orig, run) for no, orig, run in runs}
    orig, run = by_no.get(last, ("(the fixture)", fixture[1] if fixture else ""))
    tail = "\n".join("        " + l for l in per_line.get(last, "").strip().splitlines()[-25:]
                     if not l.startswith("@@docs-"))
    if died:
        err = open(died + ".err", errors="replace").read().strip().splitlines()[-15:]
        fail(f"{rel}:{last}: `{open(died + '.cmd').read().strip() if os.path.exists(died + '.cmd') else died}` "
             f"started in the background exited early; while running:\n      as run: {run}\n{tail}\n"
             "      its stderr:\n" + "\n".join("        " + l for l in err))
        return
    if rc is None:
        fail(f"{rel}:{last}: timed out after {timeout} s:\n      as run: {run}\n{tail}")
        return
    m = re.search(r"^@@docs-failed (\d+)$", output, re.M)
    if rc == 111 and m:
        fail(f"{rel}:{last}: exited {m.group(1)}:\n      line:   {orig}\n      as run: {run}\n{tail}")
        return
    m = re.search(r"^@@docs-died (\S+)$", output, re.M)
    if rc == 112 and m:
        fail(f"{rel}:{first}: a process the block started in the background exited early ({m.group(1)}):\n{tail}")
        return
    if rc != 0:
        fail(f"{rel}:{last}: the block's bash exited {rc}:\n{tail}")
        return
    for lineno, orig, run in runs:
        for f in expected_files(run):
            if not os.path.exists(os.path.join(d, f)):
                fail(f"{rel}:{lineno}: `{orig}` should have written {f}; it did not")
    print(f"      block ran in {time.time() - t0:.1f} s")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--source")
    ap.add_argument("--bin")
    ap.add_argument("dirs", nargs="*", help="SOURCE_DIR BIN_DIR (instead of --source and --bin)")
    ap.add_argument("--keep", action="store_true", help="keep the scratch folder")
    ap.add_argument("--only", action="append", help="only this file (README.md, docs/x.md); repeatable")
    ap.add_argument("--timeout", type=float, default=120, help="seconds a block may take")
    a = ap.parse_args()
    src = os.path.abspath(a.source or (a.dirs[0] if a.dirs else ""))
    bin_dir = os.path.abspath(a.bin or (a.dirs[1] if len(a.dirs) > 1 else ""))
    if not os.path.isfile(os.path.join(src, "README.md")) or not os.path.isfile(os.path.join(bin_dir, "tessera")):
        sys.exit("usage: docs_examples.py --source SOURCE_DIR --bin BIN_DIR")
    t_start = time.time()
    shared = os.path.join(os.path.dirname(src), "shared")
    have_shared = os.path.isdir(os.path.join(shared, "scenes"))
    scratch = tempfile.mkdtemp(prefix="tessera-docs-")
    for sub in ("blocks", "logs", "home", "tmp", "fakebin"):
        os.makedirs(os.path.join(scratch, sub))
    if have_shared:
        os.symlink(shared, os.path.join(scratch, "blocks", "shared"))
    for name, body in (("sbatch", FAKE_SBATCH), ("srun", FAKE_SRUN)):
        path = os.path.join(scratch, "fakebin", name)
        open(path, "w").write(body)
        os.chmod(path, 0o755)
    used_allow, ran, skipped, blocks = set(), 0, 0, 0
    procs = []
    try:
        grpc, procs = start_farm(bin_dir, scratch)
        env = {k: v for k, v in os.environ.items() if not k.startswith("TESSERA_")}
        env.update(TESSERA_COORDINATOR=grpc, DOCS_COORD=grpc, DOCS_BIN=bin_dir, HOME=os.path.join(scratch, "home"),
                   TMPDIR=os.path.join(scratch, "tmp"),
                   PATH=os.pathsep.join([os.path.join(scratch, "fakebin"), bin_dir, env.get("PATH", "/usr/bin:/bin")]))
        print(f"the test's farm: coordinator {grpc}, one worker; scratch {scratch}")
        files = doc_files(src, a.only)
        for rel in files:
            for first, body in fenced(src, rel, "sh"):
                blocks += 1
                lines = logical_lines(first, body)
                print(f"\n{rel}:{first}: ```sh block, {len(lines)} command lines")
                for lineno, line in lines:
                    for binary, words in our_commands(line):
                        check_flags(f"{rel}:{lineno}", binary, words, bin_dir)
                    check_script_flags(f"{rel}:{lineno}", line, src)
                    check_paths(f"{rel}:{lineno}", line, src, bin_dir, have_shared)
                block_skip = None
                for i, (f, pat, scope, why) in enumerate(ALLOW):
                    if f == rel and scope == "block" and any(re.search(pat, l) for _, l in lines):
                        block_skip = why
                        used_allow.add(i)
                if block_skip:
                    print(f"skip  the whole block: {block_skip}")
                    skipped += len(lines)
                    continue
                wanted = [int(x) for _, l in lines for x in re.findall(r"--frame\s+(\d+)", l)]
                runs = []
                for lineno, line in lines:
                    why = None
                    for i, (f, pat, scope, reason) in enumerate(ALLOW):
                        if f == rel and scope == "line" and re.search(pat, line):
                            why = reason
                            used_allow.add(i)
                    if why is None and not have_shared and \
                            ("../shared" in line or any(re.search(p, line) for p in SHARED_BY_DEFAULT)):
                        why = f"needs the CS184 scenes in {shared}, absent here"
                    if why is None and re.search(r"(^|[\s;&|])(blender|bench/blender/)", line) \
                            and not shutil.which("blender"):
                        why = "needs Blender (deploy/install-deps.sh installs it), absent here"
                    if why:
                        print(f"skip  {rel}:{lineno}: {line[:100]}\n        ({why})")
                        skipped += 1
                        continue
                    run = rewrite(line, wanted)
                    print(f"run   {rel}:{lineno}: {line[:110]}")
                    if run != line:
                        print(f"        as: {run[:160]}")
                    runs.append((lineno, line, run))
                if not runs:
                    continue
                fixture = next(((why, sh) for f, pat, why, sh in FIXTURES
                                if f == rel and any(re.search(pat, l) for _, l in lines)), None)
                run_block(rel, first, runs, fixture, env, src, scratch, blocks, a.timeout)
                ran += len(runs)
            # Camera paths in ```json blocks: rendered with --camera-path (two frames).
            for first, body in fenced(src, rel, "json"):
                text = "\n".join(body)
                if not re.search(r'"(keys|turntable)"', text):
                    continue
                blocks += 1
                d = make_tree(src, bin_dir, scratch, blocks)
                open(os.path.join(d, "path.json"), "w").write(text)
                cmd = [os.path.join(bin_dir, "tessera"), "render", "scenes/cornell-spheres.dae", "--frames", "1,24",
                       "--camera-path", "path.json", "-s", "1", "-r", "32", "24", "-q", "-f", "out/path.####.png"]
                print(f"\n{rel}:{first}: ```json camera path\nrun   {' '.join(cmd[1:])}")
                r = subprocess.run(cmd, cwd=d, capture_output=True, text=True, timeout=a.timeout, env=env)
                ran += 1
                if r.returncode != 0:
                    fail(f"{rel}:{first}: the camera path example, `{' '.join(cmd[1:])}`, exited {r.returncode}: "
                         f"{r.stderr.strip()[-400:]}")
            # The Python client's examples: run shrunk with build/python on the path.
            for first, body in fenced(src, rel, "python"):
                text = "\n".join(body)
                if "import tessera" not in text:
                    continue
                blocks += 1
                d = make_tree(src, bin_dir, scratch, blocks)
                run = shrink_python(text)
                open(os.path.join(d, "example.py"), "w").write(run)
                print(f"\n{rel}:{first}: ```python block, run shrunk:\n" + "\n".join("      " + x for x in run.splitlines()))
                py_env = dict(env, PYTHONPATH=os.path.join(os.path.dirname(bin_dir), "python"))
                r = subprocess.run(["/usr/bin/python3", "example.py"], cwd=d, capture_output=True, text=True,
                                   timeout=a.timeout, env=py_env)
                ran += 1
                if r.returncode != 0:
                    fail(f"{rel}:{first}: the Python example exited {r.returncode}:\n{r.stderr.strip()[-600:]}")
        if not a.only or "README.md" in a.only:
            check_render_reference(src, bin_dir)
        for i, (f, pat, scope, why) in enumerate(ALLOW):
            if i not in used_allow and f in files:
                fail(f"ALLOW entry ({f}, {pat!r}) matches no line: remove it or fix it")
        for p in procs:
            if p.poll() is not None:
                fail(f"the test's own {'worker' if p is procs[0] else 'coordinator'} exited early ({p.returncode})")
    finally:
        for p in procs:
            p.terminate()
        for p in procs:
            try:
                p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
        if a.keep:
            print(f"kept {scratch}")
        else:
            shutil.rmtree(scratch, ignore_errors=True)
    print(f"\n{blocks} blocks: {ran} lines run, {skipped} skipped, {time.time() - t_start:.1f} s")
    if ran == 0:
        fail("no example ran")
    for f in failures:
        print("\nFAIL: " + f)
    print("FAILED" if failures else "OK")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
