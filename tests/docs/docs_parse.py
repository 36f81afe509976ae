"""The docs examples test's reading of the documents (docs_examples.py): fenced blocks and
their logical lines, our commands in them, the flag and path checks, and the rewriting that
shrinks a line before it runs."""
import glob
import os
import re
import shlex
import subprocess

from docs_tables import LAUNCHERS, OURS, SHRINK_SCRIPTS, SUBSTITUTIONS

failures = []


def fail(msg):
    failures.append(msg)
    print("FAIL  " + msg.splitlines()[0])


# ---- the documents ------------------------------------------------------------------------

def doc_files(src, only):
    files = ["README.md"] + sorted("docs/" + f for f in os.listdir(os.path.join(src, "docs")) if f.endswith(".md"))
    return [f for f in files if not only or f in only]


def fenced(src, rel, lang):
    """(first line number, lines) of each ```lang block of a file."""
    lines = open(os.path.join(src, rel), encoding="utf-8").read().splitlines()
    out, i = [], 0
    while i < len(lines):
        if lines[i].strip() == "```" + lang:
            j = i + 1
            while j < len(lines) and lines[j].strip() != "```":
                j += 1
            out.append((i + 2, lines[i + 1:j]))
            i = j
        i += 1
    return out


def logical_lines(first, lines):
    """(line number, command) of a block: comments dropped, `\\` and trailing |, &&, || joined."""
    out, cur, start = [], "", None
    for n, line in enumerate(lines, first):
        s = line.strip()
        if not cur and (not s or s.startswith("#")):
            continue
        if start is None:
            start = n
        if s.endswith("\\"):
            cur += s[:-1].rstrip() + " "
            continue
        cur += s
        if re.search(r"(\||&&)$", cur):
            cur += " "
            continue
        out.append((start, cur))
        cur, start = "", None
    if cur:
        out.append((start, cur.strip()))
    return out


def segments(line):
    """The line split into commands and the operators between them (quotes respected)."""
    parts, cur, quote, i = [], "", None, 0
    while i < len(line):
        c = line[i]
        if quote:
            cur += c
            if c == quote:
                quote = None
        elif c in "'\"":
            quote, cur = c, cur + c
        elif c == "#" and (not cur or cur[-1].isspace()):
            parts.append(cur)
            parts.append(line[i:])  # a trailing comment
            return parts
        elif line.startswith(("&&", "||"), i):
            parts += [cur, line[i:i + 2]]
            cur, i = "", i + 2
            continue
        elif c in ";|":
            parts += [cur, c]
            cur = ""
        else:
            cur += c
        i += 1
    parts.append(cur)
    return parts


def command_words(seg):
    """The words of one command, environment assignments dropped; None if not parseable."""
    try:
        words = shlex.split(seg)
    except ValueError:
        return None
    while words and re.match(r"^[A-Za-z_][A-Za-z0-9_]*=", words[0]):
        words = words[1:]
    return words


def our_commands(line):
    """(binary, words after it) of each command of ours in a line, also inside quoted
    strings (sbatch --wrap "tessera-coordinator ...")."""
    found = []
    for seg in segments(line)[::2]:
        if seg.lstrip().startswith("#"):
            continue
        words = command_words(seg) or []
        if words and os.path.basename(words[0]) in OURS:
            found.append((os.path.basename(words[0]), words[1:]))
        elif words and words[0] in LAUNCHERS:  # podman run IMAGE tessera-coordinator ..., sudo tessera ...
            at = next((i for i, w in enumerate(words) if w in OURS), None)
            if at is not None:
                found.append((words[at], words[at + 1:]))
        for w in words[1:]:
            if " " in w:
                found += our_commands(w)
    return found


# ---- flags ------------------------------------------------------------------------------

_help = {}


def help_options(cmd):
    key = tuple(cmd)
    if key not in _help:
        r = subprocess.run(cmd + ["--help"], capture_output=True, text=True, timeout=30)
        _help[key] = (r.returncode, set(re.findall(r"(?<![\w-])(--?[A-Za-z][-A-Za-z0-9]*)", r.stdout)), r.stdout)
    return _help[key]


def check_flags(where, binary, words, bin_dir):
    cmd = [os.path.join(bin_dir, binary)]
    if binary == "tessera":
        if not words or words[0].startswith("-"):
            return
        rc, _, text = help_options(cmd)
        subs = re.findall(r"^  ([a-z]+)\s", text.split("Subcommands:")[-1], re.M)
        if words[0] not in subs:
            fail(f"{where}: `tessera {words[0]}`: no such subcommand (tessera --help lists {', '.join(subs)})")
            return
        cmd.append(words[0])
    rc, known, _ = help_options(cmd)
    for w in words:
        flag = w.split("=")[0]
        if re.match(r"^--?[A-Za-z]", flag) and flag not in known:
            fail(f"{where}: `{' '.join([binary] + cmd[1:][:1])}` has no option {flag} (its --help)")


def check_script_flags(where, line, src):
    """Options given to a bench/ Python script (argparse) are ones its --help lists."""
    for seg in segments(line)[::2]:
        words = command_words(seg) or []
        if words and words[0] in ("python3", "/usr/bin/python3"):
            words = words[1:]
        if not words or not re.match(r"^bench/.*\.py$", words[0]):
            continue
        path = os.path.join(src, words[0])
        if not os.path.exists(path):
            fail(f"{where}: {words[0]} does not exist")
            continue
        if "argparse" not in open(path, encoding="utf-8").read():
            continue
        r = subprocess.run(["/usr/bin/python3", path, "--help"], capture_output=True, text=True, timeout=30)
        known = set(re.findall(r"(?<![\w-])(--?[A-Za-z][-A-Za-z0-9]*)", r.stdout))
        for w in words[1:]:
            if re.match(r"^--?[A-Za-z]", w) and w.split("=")[0] not in known:
                fail(f"{where}: {words[0]} has no option {w.split('=')[0]} (its --help)")


def check_paths(where, line, src, bin_dir, have_shared):
    """The repository's files a line names (deploy/..., bench/..., build/bin/...) exist."""
    for seg in segments(line)[::2]:
        if seg.lstrip().startswith("#"):
            continue
        for w in command_words(seg) or []:
            w = w.split("=", 1)[-1] if w.startswith("-") else w
            if re.match(r"^build/bin/", w):
                if not glob.glob(os.path.join(bin_dir, w[len("build/bin/"):])):
                    fail(f"{where}: {w}: no such file in {bin_dir}")
            elif re.match(r"^(deploy|bench|scenes|docs|tests)/", w) and "$" not in w:
                if not glob.glob(os.path.join(src, w.rstrip("/"))):
                    fail(f"{where}: {w}: no such file in the repository")
            elif w.startswith("../shared/") and have_shared:
                if not glob.glob(os.path.join(src, w)):
                    fail(f"{where}: {w}: no such file")


def option_names(text):
    return set(re.findall(r"(?<![\w`-])(--?[A-Za-z][-A-Za-z0-9]*)", text))


def check_render_reference(src, bin_dir):
    """README's `tessera render` synopsis and flag table against `tessera render --help`."""
    _, _, text = help_options([os.path.join(bin_dir, "tessera"), "render"])
    groups = []  # each option's names, as --help gives them
    for line in text.split("Options:")[-1].splitlines():
        m = re.match(r"^  (-[^\s]+)", line)
        if m and m.group(1) != "-h,--help":
            groups.append(set(m.group(1).split(",")))
    readme = open(os.path.join(src, "README.md"), encoding="utf-8").read()
    m = re.search(r"^```\n(tessera render SCENE.*?)^```", readme, re.S | re.M)
    if not m:
        fail("README.md: no ``` block with the `tessera render SCENE ...` synopsis")
        return
    rows = re.findall(r"^\| `([^|]*)` \|", readme, re.M)
    table = set()
    for r in rows:
        table |= option_names(r.replace("`", " "))
    for what, names in (("synopsis", option_names(m.group(1))), ("flag table", table)):
        known = set().union(*groups)
        for n in sorted(names - known):
            fail(f"README.md: the `tessera render` {what} lists {n}, which `tessera render --help` does not")
        for g in groups:
            if not g & names:
                fail(f"README.md: the `tessera render` {what} lacks {'/'.join(sorted(g))} (in `tessera render --help`)")


# ---- shrinking and rewriting --------------------------------------------------------------

def frames_of(spec):
    out = []
    for part in spec.split(","):
        m = re.fullmatch(r"(\d+)(?:-(\d+)(?:x(\d+))?)?", part)
        if not m:
            return []
        a, b, step = int(m.group(1)), int(m.group(2) or m.group(1)), int(m.group(3) or 1)
        out += list(range(a, b + 1, step))
    return out


def shrink_frames(spec, wanted):
    frames = frames_of(spec)
    if len(frames) <= 2:
        return spec
    keep = [w for w in wanted if w in frames and w != frames[0]]
    return f"{frames[0]},{keep[0]}" if keep else f"{frames[0]},{frames[1]}"


def shrink_ours(seg, wanted_frames):
    """One command of ours, shrunk: -s 1, -r 32 x H', -a 1 T, two frames."""
    words = command_words(seg) or []
    if len(words) < 2 or os.path.basename(words[0]) != "tessera" or words[1] not in ("render", "submit"):
        return seg
    seg = re.sub(r"(?<=\s)-s\s+\d+", "-s 1", seg)
    seg = re.sub(r"(?<=\s)-a\s+\d+(?=\s)", "-a 1", seg)
    seg = re.sub(r"(?<=\s)-r\s+(\d+)\s+(\d+)",
                 lambda m: f"-r 32 {max(8, round(32 * int(m.group(2)) / int(m.group(1))))}", seg)
    seg = re.sub(r"(?<=\s)--frames\s+(\S+)", lambda m: "--frames " + shrink_frames(m.group(1), wanted_frames), seg)
    add = ([] if re.search(r"(?<=\s)-r\s", seg) else ["-r", "32", "24"]) + \
        ([] if re.search(r"(?<=\s)-s\s", seg) else ["-s", "1"])
    if add:
        seg = re.sub(r"(tessera (?:render|submit) \S+)", lambda m: m.group(1) + " " + " ".join(add), seg, count=1)
    return seg


def rewrite(line, wanted_frames):
    """A line as it runs here: substitutions, our commands shrunk, coordinators and
    workers in the background, bench scripts small."""
    for pat, rep, _ in SUBSTITUTIONS:
        line = re.sub(pat, rep, line)
    parts = segments(line)
    for i in range(0, len(parts), 2):
        seg = parts[i]
        if seg.lstrip().startswith("#"):
            continue
        words = command_words(seg)
        if not words:
            continue
        base = os.path.basename(words[0])
        if base in OURS:
            seg = shrink_ours(seg, wanted_frames)
            seg = re.sub(r"\bJOB\b", '"$(__docs_last_job)"', seg)
            if base in ("tessera-coordinator", "tessera-worker"):
                lead = re.match(r"^\s*((?:[A-Za-z_][A-Za-z0-9_]*=\S*\s+)*)", seg).group(1)
                seg = seg.replace(lead + words[0], lead + "__docs_" + base.split("-")[1] + " " + words[0], 1)
        script = words[1] if words[0] in ("python3", "/usr/bin/python3") and len(words) > 1 else words[0]
        if script in SHRINK_SCRIPTS:
            seg = seg.rstrip() + " " + " ".join(shlex.quote(a) for a in SHRINK_SCRIPTS[script]) + " "
        parts[i] = seg
    return "".join(parts)


def expected_files(line):
    """Files the commands of ours in a (rewritten) line are told to write."""
    out = []
    for seg in segments(line)[::2]:
        words = command_words(seg) or []
        if len(words) < 2 or os.path.basename(words[0]) != "tessera" or words[1] not in ("render", "submit", "fetch"):
            continue
        if words[1] == "submit" and "--wait" not in words or "--all" in words:
            continue
        frames = None
        for i, w in enumerate(words[:-1]):
            if w == "--frames":
                frames = frames_of(words[i + 1])
            elif w == "--frame":
                frames = [int(words[i + 1])]
        for i, w in enumerate(words[:-1]):
            if w == "-f":
                path = words[i + 1]
                m = re.search(r"#+", path)
                if m and frames:
                    out += [path[:m.start()] + str(f).zfill(len(m.group(0))) + path[m.end():] for f in frames]
                elif not m:
                    out.append(path)
    return out


def shrink_python(text):
    """A ```python example of the Python client, shrunk as the shell lines are: samples=1,
    a 32-pixel-wide resolution, two frames of a range."""
    text = re.sub(r"\bsamples=\d+", "samples=1", text)

    def res(m):
        w, h = int(m.group(1)), int(m.group(2))
        return f"resolution=(32, {max(1, round(32 * h / w))})"
    text = re.sub(r"\bresolution=\((\d+),\s*(\d+)\)", res, text)
    return re.sub(r'\bframes="(-?\d+)-(-?\d+)"', lambda m: f'frames="{m.group(1)}-{int(m.group(1)) + 1}"', text)
