#!/usr/bin/env python3
"""CTest entry (Cli.OneSpellingPerOption): every option of every binary and `tessera`
subcommand, read from their --help, has one spelling across them all, as operators expect
of one tool (issue 24):
  - a long option has the same short form wherever it appears (or none anywhere);
  - a short letter stands for the same long option everywhere;
  - no concept has two names (a table of the names we chose and the ones we refuse);
and every binary answers --version (exit 0, naming the commit) and exits 2 on a usage
error, subcommands included.
Usage: option_spellings.py BIN_DIR"""
import re
import subprocess
import sys

BIN = sys.argv[1]
failures = []


def run(args):
    return subprocess.run([f"{BIN}/{args[0]}"] + args[1:], capture_output=True, text=True, timeout=30)


def options(help_text):
    """(short, long) pairs of a CLI11 help text's option lines."""
    found = []
    for line in help_text.splitlines():
        m = re.match(r"^\s{2,}((?:-[A-Za-z0-9],)*)(--?[A-Za-z][-A-Za-z0-9]*)", line)
        if not m:
            continue
        shorts = [s.rstrip(",") for s in m.group(1).split(",") if s]
        name = m.group(2)
        if name.startswith("--"):
            found.append((shorts[0] if shorts else None, name))
        else:  # a short option alone (-s, -f)
            found.append((name, None))
    return found


commands = [["tessera-coordinator"], ["tessera-worker"], ["tessera"]]
top = run(["tessera", "--help"]).stdout
subs = re.findall(r"^  ([a-z]+)\s{2,}", top.split("Subcommands:")[1], re.M)
if len(subs) < 10:
    failures.append(f"tessera --help lists {len(subs)} subcommands: {subs}")
commands += [["tessera", s] for s in subs]

short_of, long_of, where = {}, {}, {}
for cmd in commands:
    text = run(cmd + ["--help"]).stdout
    opts = options(text)
    if not opts:
        failures.append(f"{' '.join(cmd)} --help: no options found")
    for short, long in opts:
        name = " ".join(cmd)
        if long:
            where.setdefault(long, []).append(name)
            if long in short_of and short_of[long] != short:
                failures.append(f"{long}: short form {short_of[long]!r} in {where[long][0]} but {short!r} in {name}")
            short_of.setdefault(long, short)
        if short and long:
            if short in long_of and long_of[short] not in (long, None):
                failures.append(f"{short}: means {long_of[short]} elsewhere but {long} in {name}")
            long_of[short] = long
        elif short:
            if long_of.get(short) not in (None,):
                failures.append(f"{short}: alone in {name} but {long_of[short]} elsewhere")
            long_of.setdefault(short, None)

# One name a concept: what we use, and spellings that would be a second name for it.
SECOND_NAMES = {
    "--threads": ["--thread", "--jobs", "--cores", "--nthreads"],
    "--coordinator": ["--server", "--address", "--addr", "--host", "--connect"],
    "--token-file": ["--token", "--tokens-file", "--auth"],
    "--tls-ca": ["--ca", "--cacert", "--ca-file", "--tls-ca-file"],
    "--json": ["--output-json", "--format", "--output"],
    "--quiet": ["--silent"],
    "--name": ["--worker-name", "--job-name"],
    "--no-headers": ["--no-header", "--noheaders"],
    "--frame": ["--frame-number"],
}
for chosen, others in SECOND_NAMES.items():
    if chosen not in where:
        failures.append(f"{chosen} appears nowhere: the table of names is out of date")
    for other in others:
        if other in where:
            failures.append(f"{other} (in {', '.join(where[other])}) is a second name for {chosen}")

for binary in ["tessera", "tessera-worker", "tessera-coordinator"]:
    v = run([binary, "--version"])
    if v.returncode != 0 or not re.search(r"\b[0-9a-f]{7,}\b", v.stdout):
        failures.append(f"{binary} --version: exit {v.returncode}, {v.stdout.strip()!r} (no commit)")
for cmd in commands:
    u = run(cmd + ["--no-such-option"])
    if u.returncode != 2:
        failures.append(f"{' '.join(cmd)} --no-such-option: exit {u.returncode}, not 2")

print(f"{len(commands)} commands, {len(where)} long options")
for f in failures:
    print("FAIL:", f)
sys.exit(1 if failures else 0)
