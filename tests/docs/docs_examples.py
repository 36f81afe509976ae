#!/usr/bin/env python3
"""CTest entry (Docs.ExamplesRun): the shell examples of README.md and docs/*.md (```sh
blocks) stay true (issue 24).
  1. Every command of ours in them (tessera, tessera-worker, tessera-coordinator) uses only
     options that command's --help lists.
  2. The local ones run, shrunk (2 samples a pixel, 32x24, two frames of a sequence), in a
     scratch folder that sees the repository's build/, scenes/ and ../shared; `submit
     --wait` against a coordinator and a worker this script starts on loopback. Lines that
     need what a test machine has not (a remote HOST, systemd, kubectl, sbatch, podman,
     apt-get, Blender, a placeholder JOB or scene) are skipped, each saying why.
Usage: docs_examples.py SOURCE_DIR BIN_DIR"""
import os
import re
import shlex
import subprocess
import sys
import tempfile

SRC, BIN = os.path.abspath(sys.argv[1]), os.path.abspath(sys.argv[2])
OURS = {"tessera", "tessera-worker", "tessera-coordinator"}
SKIP = [  # (pattern, why): lines that cannot run on a test machine, or are tested elsewhere
    (r"\bHOST\b|head:7878|render-head|0\.0\.0\.0", "needs a remote coordinator host (deploy tests cover the recipes)"),
    (r"\b(systemctl|kubectl|sbatch|podman|apt-get|sudo)\b|\$EDITOR", "a system tool this test does not drive"),
    (r"deploy/(demo|test|build)\.sh|build-image\.sh", "the README's own commands: CI runs them"),
    (r"\bJOB\b|scene\.dae|shot\.dae|\$M/|--models|\.\.\. ", "a placeholder for the reader's own job or files"),
    (r"bench/", "benchmarks: bench/ and its CTests run them"),
]
failures = []


def blocks():
    files = [os.path.join(SRC, "README.md")] + sorted(
        os.path.join(SRC, "docs", f) for f in os.listdir(os.path.join(SRC, "docs")) if f.endswith(".md"))
    for path in files:
        text = open(path, encoding="utf-8").read()
        for m in re.finditer(r"^```sh\n(.*?)^```", text, re.S | re.M):
            body = re.sub(r"\\\n\s*", " ", m.group(1))  # continuation lines joined
            yield os.path.relpath(path, SRC), [l for l in body.splitlines() if l.strip() and not l.lstrip().startswith("#")]


def help_options(cmd):
    out = subprocess.run(cmd + ["--help"], capture_output=True, text=True).stdout
    return set(re.findall(r"(?<![\w-])(--?[A-Za-z][-A-Za-z0-9]*)", out))


def our_commands(line):
    """Each command of ours in the line: (binary, words)."""
    for part in re.split(r"&&|\|\||;|\|", line):
        part = part.split(" #")[0]
        try:
            words = shlex.split(part)
        except ValueError:
            continue
        while words and re.match(r"^[A-Z_]+=", words[0]):
            words = words[1:]
        if words and os.path.basename(words[0]) in OURS:
            yield os.path.basename(words[0]), words[1:]


def check_flags(where, binary, words):
    cmd = [os.path.join(BIN, binary)]
    if binary == "tessera" and words and not words[0].startswith("-"):
        cmd.append(words[0])
    known = help_options(cmd)
    for w in words:
        flag = w.split("=")[0]
        if re.match(r"^--?[A-Za-z]", flag) and flag not in known:
            failures.append(f"{where}: `{' '.join(cmd[1:] or [binary])}` has no option {flag}")


def shrink(line):
    line = re.sub(r"(\s-s)\s+\d+", r"\1 2", line)
    line = re.sub(r"(\s-r)\s+\d+\s+\d+", r"\1 32 24", line)
    line = re.sub(r"(\s-a)\s+\d+", r"\1 1", line)
    line = re.sub(r"--frames\s+(\d+)-\d+", lambda m: f"--frames {m.group(1)}-{int(m.group(1)) + 1}", line)
    if re.search(r"\btessera (render|submit)\b", line) and " -r " not in line:
        line = re.sub(r"\btessera (render|submit) (\S+)", r"tessera \1 \2 -r 32 24", line)
    return line


def main():
    scratch = tempfile.mkdtemp(prefix="tessera-docs-")
    work = os.path.join(scratch, "work")
    os.makedirs(work)
    os.symlink(os.path.dirname(BIN), os.path.join(work, "build"))  # build/bin/...
    for d in ["scenes", "deploy"]:
        os.symlink(os.path.join(SRC, d), os.path.join(work, d))
    shared = os.path.join(os.path.dirname(SRC), "shared")
    if os.path.isdir(shared):
        os.symlink(shared, os.path.join(scratch, "shared"))
    os.makedirs(os.path.join(work, "out"))
    coord = subprocess.Popen([os.path.join(BIN, "tessera-coordinator"), "--listen", "127.0.0.1:0", "--http",
                              "127.0.0.1:0", "--data", os.path.join(scratch, "data")],
                             stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    grpc = re.search(r"grpc listening on (\S+)", coord.stdout.readline()).group(1)
    worker = subprocess.Popen([os.path.join(BIN, "tessera-worker"), "--coordinator", grpc, "--threads", "2",
                               "--cache", os.path.join(scratch, "cache")], stderr=subprocess.DEVNULL)
    env = dict(os.environ, TESSERA_COORDINATOR=grpc)
    for var in ["TESSERA_TOKEN", "TESSERA_TOKEN_FILE", "TESSERA_TLS_CA"]:
        env.pop(var, None)
    ran = skipped = 0
    try:
        for where, lines in blocks():
            for line in lines:
                for binary, words in our_commands(line):
                    check_flags(where, binary, words)
                why = next((w for p, w in SKIP if re.search(p, line)), None)
                if why is None and "../shared" in line and not os.path.isdir(shared):
                    why = "needs ../shared (absent here)"
                if why is None and re.search(r"\b(umask|openssl|printf .*tokens|export)\b", line):
                    why = "the secure farm's set-up (tests/integration/access_test.cc runs it)"
                if why:
                    print(f"skip  {where}: {line.strip()[:90]}  ({why})")
                    skipped += 1
                    continue
                run = shrink(line.strip().replace("python3 ", "/usr/bin/python3 "))
                r = subprocess.run(["bash", "-c", run], cwd=work, env=env, capture_output=True, text=True, timeout=300)
                ran += 1
                if r.returncode != 0:
                    failures.append(f"{where}: `{run}` exited {r.returncode}: {r.stderr.strip()[-400:]}")
                else:
                    print(f"ok    {where}: {run[:100]}")
    finally:
        worker.terminate()
        coord.terminate()
        worker.wait()
        coord.wait()
        subprocess.run(["rm", "-rf", scratch])
    print(f"{ran} example lines run, {skipped} skipped")
    for f in failures:
        print("FAIL:", f)
    return 1 if failures or ran == 0 else 0


sys.exit(main())
