#!/usr/bin/python3
"""CTest entry (Cli.OneSpellingPerOption): one spelling per option across every binary and
`tessera` subcommand, as operators expect of one tool (issue 24). Read from their --help
(CLI11's format), each option's names, value type, default, environment variable and
description, then:

  short/long  a long option has the same short form wherever it appears (or none anywhere),
              and a short letter stands for the same option everywhere;
  same-opt    an option that appears in several commands takes the same value type there
              and the same environment variable;
  concepts    the table CONCEPTS below: an option whose description says it is one of
              these concepts (threads, coordinator address, token file, TLS CA, JSON
              output, quiet, ...) is spelled as the table says, and none of the refused
              second names exists anywhere;
  env         an option read from the environment too names the variable after itself:
              --tls-ca <-> $TESSERA_TLS_CA;
  units       an option that takes seconds ends in -seconds (milliseconds: -ms), as
              --lease-seconds and --reconnect-seconds do;
  defaults    the client's default --coordinator is the coordinator's default --listen;
  version     every binary answers --version: exit 0, "<binary> <commit>", one commit;
  usage       a usage error exits 2: an unknown option (every command), a missing
              required argument, an option's value missing, a value out of its range.
It also prints notes (not failures): one option described differently in two commands,
defaults that differ, descriptions of one command in two styles.

Usage: option_spellings.py [--bin] BIN_DIR"""
import argparse
import os
import re
import subprocess
import sys
import tempfile

ap = argparse.ArgumentParser()
ap.add_argument("--bin", dest="bin_opt")
ap.add_argument("bin_pos", nargs="?")
args = ap.parse_args()
BIN = args.bin_opt or args.bin_pos
if not BIN:
    sys.exit("usage: option_spellings.py --bin BIN_DIR")
BINARIES = ["tessera", "tessera-coordinator", "tessera-worker", "tessera-wan-proxy"]
failures, notes = [], []
ENV = {k: v for k, v in os.environ.items() if not k.startswith("TESSERA_")}
ENV["TESSERA_COORDINATOR"] = "127.0.0.1:1"  # a usage error that slips through reaches nothing


def run(cmd, timeout=20):
    try:
        return subprocess.run([os.path.join(BIN, cmd[0])] + cmd[1:], capture_output=True, text=True,
                              timeout=timeout, env=ENV, stdin=subprocess.DEVNULL)
    except subprocess.TimeoutExpired:
        return subprocess.CompletedProcess(cmd, "timeout", "", "")


class Option:
    def __init__(self, command, names, spec):
        self.command = command
        self.shorts = [n for n in names if not n.startswith("--")]
        self.longs = [n for n in names if n.startswith("--")]
        self.spec = spec.strip()
        words = self.spec.split()
        self.type = re.split(r"[:=]", words[0])[0] if words and words[0][:1].isupper() else "FLAG"
        m = re.search(r" x (\d+)", self.spec)
        self.arity = int(m.group(1)) if m else (0 if self.type == "FLAG" else 1)
        m = re.search(r"=(\S+)", self.spec)
        self.default = m.group(1) if m else None
        m = re.search(r" in \[(\S+) - (\S+)\]", self.spec)
        self.range = (m.group(1), m.group(2)) if m else None
        self.required = "REQUIRED" in self.spec
        self.desc = ""
        self.envs = set(re.findall(r"\(Env:(\w+)\)", self.spec))

    @property
    def key(self):
        return self.longs[0] if self.longs else self.shorts[0]

    @property
    def spelling(self):
        return ",".join(self.shorts + self.longs)

    def finish(self):
        self.envs |= set(re.findall(r"\$(TESSERA_\w+)", self.desc))


def parse_help(command, text):
    """The options and positionals of a CLI11 help text."""
    options, positionals, section, last = [], [], None, None
    for line in text.splitlines():
        if re.match(r"^\S.*:$", line):
            section, last = line[:-1], None
            continue
        if re.match(r"^ {20,}\S", line) and last is not None:  # a description on its own line
            last.desc = (last.desc + " " + line.strip()).strip()
            continue
        m = re.match(r"^  (\S+)(?: (.*?))?(?:\s{2,}(\S.*))?$", line)
        if not m:
            continue
        if section == "Options" and m.group(1).startswith("-"):
            last = Option(command, m.group(1).split(","), m.group(2) or "")
            last.desc = m.group(3) or ""
            options.append(last)
        elif section == "Positionals":
            positionals.append((m.group(1), "REQUIRED" in (m.group(2) or "")))
            last = None
    for o in options:
        o.finish()
    return options, positionals


# Every command: the binaries, then `tessera`'s subcommands as its --help lists them.
top = run(["tessera", "--help"])
if top.returncode != 0 or "Subcommands:" not in top.stdout:
    failures.append(f"tessera --help: exit {top.returncode}, no Subcommands section")
    subs = []
else:
    subs = re.findall(r"^  ([a-z][-a-z]*)\s", top.stdout.split("Subcommands:")[1], re.M)
if len(subs) < 10:
    failures.append(f"tessera --help lists {len(subs)} subcommands: {subs}")
commands = [[b] for b in BINARIES] + [["tessera", s] for s in subs]
parsed = {}
for cmd in commands:
    h = run(cmd + ["--help"])
    name = " ".join(cmd)
    if h.returncode != 0:
        failures.append(f"usage: `{name} --help` exited {h.returncode}")
    opts, pos = parse_help(name, h.stdout)
    if not opts:
        failures.append(f"parse: `{name} --help`: no options found")
    parsed[name] = (cmd, opts, pos)
all_opts = [o for _, opts, _ in parsed.values() for o in opts]

# short/long: a long option has one short form, a short letter one meaning.
by_long, by_short = {}, {}
for o in all_opts:
    for lg in o.longs:
        by_long.setdefault(lg, []).append(o)
    for s in o.shorts:
        by_short.setdefault(s, []).append(o)
for lg, os_ in sorted(by_long.items()):
    forms = {tuple(o.shorts): o.command for o in os_}
    if len(forms) > 1:
        failures.append(f"short/long: {lg} has short forms " +
                        ", ".join(f"{list(s) or 'none'} in `{c}`" for s, c in forms.items()))
for s, os_ in sorted(by_short.items()):
    meanings = {tuple(o.longs): o.command for o in os_}
    if len(meanings) > 1:
        failures.append(f"short/long: {s} means " +
                        ", ".join(f"{list(l) or 'only itself'} in `{c}`" for l, c in meanings.items()))

# same-opt: one option, one value type and one environment variable wherever it is.
for key, os_ in sorted({**by_long, **{s: v for s, v in by_short.items() if not any(o.longs for o in v)}}.items()):
    if len(os_) < 2:
        continue
    types = {(o.type, o.arity): o.command for o in os_}
    if len(types) > 1:
        failures.append(f"same-opt: {key} takes " + ", ".join(f"{t}x{a} in `{c}`" for (t, a), c in types.items()))
    envs = {tuple(sorted(o.envs)): o.command for o in os_}
    if len(envs) > 1:
        failures.append(f"same-opt: {key} reads " + ", ".join(f"{list(e) or 'no variable'} in `{c}`" for e, c in envs.items()))
    defaults = {o.default: o.command for o in os_ if not o.required}
    required = [o.command for o in os_ if o.required]
    if len(defaults) > 1 or (defaults and required):
        notes.append(f"{key}: default " + ", ".join(f"{d or 'none'} in `{c}`" for d, c in defaults.items()) +
                     "".join(f", required in `{c}`" for c in required))
    descs = {}
    for o in os_:
        descs.setdefault(o.desc, []).append(o.command)
    if len(descs) > 1:
        notes.append(f"{key} is described " + "; ".join(f"{d!r} in {', '.join(f'`{c}`' for c in cs)}"
                                                        for d, cs in descs.items()))

# concepts: a meaning (recognised by its description), the one spelling it has, and names
# that would be a second spelling of it. `spelling` is a regex over "SHORTS,LONGS"; where it
# has a group named `word`, every option of the concept uses the same word there.
CONCEPTS = [
    ("help", r"^Print this help message", r"-h,--help", []),
    ("version", r"^Display program version", r"--version", ["-V", "--ver"]),
    ("render threads", r"^(render )?threads\b", r"-t,--threads", ["--thread", "--jobs", "-j", "--cores", "--nthreads", "--workers"]),
    ("coordinator address (client, worker)", r"^coordinator gRPC address", r"--coordinator",
     ["--server", "--address", "--addr", "--host", "--connect", "--coordinator-address"]),
    ("token file (client, worker)", r"^file holding (a|an|the) .*\baccess token", r"--token-file",
     ["--token", "--auth", "--auth-file", "--credentials"]),
    ("enrolment token file", r"^file holding an enrolment token", r"--enrol-token-file",
     ["--enroll-token-file", "--enrol-token", "--enrollment-token-file"]),
    ("the coordinator's access list", r"^access tokens, one", r"--tokens(-file)?", ["--token-db", "--access", "--acl"]),
    ("TLS certificate authority", r"^PEM certificate authority", r"--tls-ca",
     ["--ca", "--cacert", "--ca-file", "--tls-ca-file", "--tls-cacert", "--ca-cert"]),
    ("TLS certificate", r"^PEM certificate chain", r"--tls-cert", ["--cert", "--tls-certificate"]),
    ("TLS key", r"^PEM private key", r"--tls-key", ["--key", "--tls-private-key"]),
    ("JSON on stdout", r"^machine-readable output", r"--json", ["--output-json", "--format", "-o", "--machine"]),
    ("no progress output", r"^no progress output", r"-q,--quiet", ["--silent", "-s,--silent"]),
    ("more log output", r"^log ", r"-v,--verbose", ["--debug", "--log-level"]),
    ("output image", r"^output (image|\.exr)", r"-f", ["--output", "--out", "-o"]),
    ("rows without header", r"^rows only", r"--no-headers", ["--no-header", "--noheaders", "--no-heading"]),
    ("frame of a sequence", r"^(the )?frame (number )?of a sequence", r"--frame", ["--frame-number"]),
    ("a name shown in listings", r"^(job )?name shown", r"--name", ["--worker-name", "--job-name", "--label"]),
    ("leases one worker holds at once", r"^leases (held at once|one worker may hold at once)",
     r"--max-(?P<word>leases|tasks)(-per-worker)?", ["--max-in-flight", "--window"]),
    ("random seed", r"^random seed", r"--seed", []),
    ("environment map", r"^environment map", r"-e,--env", ["--environment", "--envmap"]),
    ("frames per second", r"^frames per second", r"--fps", ["--frame-rate"]),
    ("the coordinator's data folder", r"^data directory", r"--data", ["--data-dir", "--db"]),
    ("the worker's scene cache", r"^scene cache directory", r"--cache", ["--cache-dir"]),
]
for concept, desc_re, spelling, refused in CONCEPTS:
    seen = [o for o in all_opts if re.search(desc_re, o.desc, re.I)]
    if not seen:
        failures.append(f"concepts: no option is described as {concept!r} ({desc_re}): the table is out of date")
    words = {}  # (?P<word>...): one word for the concept, whichever
    for o in seen:
        m = re.fullmatch(spelling, o.spelling)
        if not m:
            failures.append(f"concepts: {concept}: `{o.command}` spells it {o.spelling}, the others {spelling}")
        elif "word" in m.groupdict():
            words.setdefault(m.group("word"), []).append(f"{o.spelling} in `{o.command}`")
    if len(words) > 1:
        failures.append(f"concepts: {concept} has two words for one thing, " +
                        " and ".join(f"{w!r} ({', '.join(ws)})" for w, ws in words.items()) + ": pick one")
    for other in refused:
        for o in by_long.get(other, []) + by_short.get(other, []):
            failures.append(f"concepts: {other} in `{o.command}` is a second name for {concept} ({spelling})")

# env: --some-option <-> $TESSERA_SOME_OPTION. ($TESSERA_TOKEN holds a token itself, the
# one other way of giving --token-file's.)
EXTRA_ENVS = {"--token-file": {"TESSERA_TOKEN"}}
for o in all_opts:
    if not o.envs or not o.longs:
        continue
    want = "TESSERA_" + o.longs[0][2:].upper().replace("-", "_")
    if want not in o.envs:
        failures.append(f"env: {o.longs[0]} in `{o.command}` reads ${', $'.join(sorted(o.envs))}: "
                        f"the option and the variable should have one name ({o.longs[0]} <-> ${want}; "
                        f"or rename the option after the variable)")
    stray = o.envs - {want} - EXTRA_ENVS.get(o.longs[0], set())
    if stray and want in o.envs:
        failures.append(f"env: {o.longs[0]} in `{o.command}` also reads ${', $'.join(sorted(stray))}")

# units: seconds end in -seconds, milliseconds in -ms.
for o in all_opts:
    if not o.longs or o.type not in ("FLOAT", "INT", "UINT"):
        continue
    name = o.longs[0]
    if re.search(r"\bmilliseconds\b|\(ms\)", o.desc) and not name.endswith("-ms"):
        failures.append(f"units: {name} in `{o.command}` takes milliseconds: spell it {name}-ms")
    elif re.search(r"\bseconds\b|\(s\)", o.desc) and not name.endswith("-seconds"):
        failures.append(f"units: {name} in `{o.command}` takes seconds ({o.desc[:60]!r}): "
                        f"spell it {name}-seconds, as --lease-seconds and --reconnect-seconds")

# defaults: the client finds a default coordinator where a default coordinator listens.
listen = [o.default for o in by_long.get("--listen", []) if o.command == "tessera-coordinator"]
for o in by_long.get("--coordinator", []):
    if o.default and listen and o.default != listen[0]:
        failures.append(f"defaults: `{o.command}` --coordinator defaults to {o.default}, "
                        f"tessera-coordinator --listen to {listen[0]}")

# style: one command's descriptions in one style (notes only).
for name, (cmd, opts, _) in parsed.items():
    own = [o for o in opts if o.desc and o.key not in ("-h", "--help", "--version")]
    first = {o.key: o.desc.split()[0] for o in own}  # an acronym or a name (PEM, glTF, cs184) has no style
    upper = sorted(k for k, w in first.items() if re.fullmatch(r"[A-Z][a-z]*", w))
    lower = sorted(k for k, w in first.items() if re.fullmatch(r"[a-z]+", w))
    if upper and lower:
        notes.append(f"`{name}`: {len(upper)} descriptions start upper-case ({', '.join(upper[:4])}...), "
                     f"{len(lower)} lower-case ({', '.join(lower[:4])}...)")

# version: exit 0, "<binary> <commit>", the same commit everywhere.
commits = {}
for b in BINARIES:
    v = run([b, "--version"])
    m = re.match(rf"^{re.escape(b)} (\S+)\s*$", v.stdout)  # git describe: COMMIT or TAG-N-gCOMMIT, -dirty
    c = m and re.search(r"(?:^|-g)([0-9a-f]{7,40})(?:-dirty)?$", m.group(1))
    if v.returncode != 0 or not c:
        failures.append(f"version: `{b} --version` exited {v.returncode} with {v.stdout.strip()!r} "
                        f"(want '{b} <commit>')")
    else:
        commits[b] = c.group(1)
if len(set(commits.values())) > 1:
    failures.append(f"version: the binaries name different commits: {commits}")

# usage: exit 2 for an unknown option, a missing required argument, an option's value
# missing, a value out of range.
scratch = tempfile.mkdtemp(prefix="tessera-spellings-")
a_file = os.path.join(scratch, "scene.dae")  # exists, so a file argument passes its check
open(a_file, "w").close()


def usage_error(cmd, extra, why):
    r = run(cmd + extra)
    if r.returncode != 2:
        failures.append(f"usage: `{' '.join(cmd + extra)}` ({why}) exited {r.returncode}, not 2: "
                        f"{(r.stderr or r.stdout).strip()[-200:]!r}")


usages = 0
for name, (cmd, opts, pos) in parsed.items():
    fill = []  # the required positionals, so only the error under test is one
    for p, req in pos:
        if req:
            fill.append(a_file if p == "scene" else "1")
    usage_error(cmd, fill + ["--no-such-option"], "an unknown option")
    usages += 1
    if fill:
        usage_error(cmd, [], "required arguments missing")
        usages += 1
    valued = [o for o in opts if o.type != "FLAG" and o.key not in ("-h", "--help")]
    if valued:
        usage_error(cmd, fill + [valued[-1].key], "the option's value missing")
        usages += 1
    for o in opts:
        if o.range and o.arity == 1:
            hi = float(o.range[1])
            bad = str(int(hi) + 1) if o.type in ("INT", "UINT") and hi < 1e15 else "1e300"
            usage_error(cmd, fill + [o.key, bad], f"above its range {o.range}")
            usages += 1
required_worker = [o for o in by_long.get("--coordinator", []) if o.command == "tessera-worker" and o.required]
if required_worker:  # required, unless $TESSERA_COORDINATOR
    r = subprocess.run([os.path.join(BIN, "tessera-worker")], capture_output=True, text=True, timeout=20,
                       env={k: v for k, v in ENV.items() if k != "TESSERA_COORDINATOR"})
    if r.returncode != 2:
        failures.append(f"usage: tessera-worker without --coordinator exited {r.returncode}, not 2")
subprocess.run(["rm", "-rf", scratch])

print(f"{len(commands)} commands, {len(by_long)} long and {len(by_short)} short option names, "
      f"{len(CONCEPTS)} concepts, {usages} usage errors tried")
for n in notes:
    print("note:", n)
for f in failures:
    print("FAIL:", f)
print("FAILED" if failures else "OK")
sys.exit(1 if failures else 0)
