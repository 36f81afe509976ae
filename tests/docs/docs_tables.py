"""The docs examples test's tables (docs_examples.py): which lines and blocks are skipped
and why, how lines are rewritten and shrunk, the fixtures some blocks assume, and the shell
prelude and stand-ins (sbatch, srun) every block runs with."""

OURS = {"tessera", "tessera-worker", "tessera-coordinator"}
LAUNCHERS = {"podman", "docker", "sudo", "srun", "exec", "nohup", "env", "timeout", "kubectl"}

# (file, regex over a logical line, "line" or "block", why). A "block" entry skips the
# whole block when any of its lines matches.
ALLOW = [
    ("README.md", r"^bash deploy/demo\.sh\b", "line",
     "installs packages with apt-get (root), builds the tree (minutes), then runs a loopback farm "
     "as the blocks below do"),
    ("README.md", r"^bash deploy/test\.sh\b", "line",
     "installs packages, builds and runs every test: it is what runs this test"),
    ("docs/deploy.md", r"\bsystemctl enable\b", "block",
     "systemd: installs units as root and enables services (sudo, /etc/systemd); SystemdUnitsVerify checks the units"),
    ("docs/deploy.md", r"^kubectl apply\b", "block",
     "kubectl: needs a Kubernetes cluster (K8sManifestsValidate checks the manifests offline)"),
    ("docs/deploy.md", r"^podman run\b", "block",
     "podman: builds and runs an OCI image (ContainerImage runs its executables from it)"),
    ("docs/gallery.md", r"sample_models\.py", "block",
     "needs Blender 3.4 and a checkout of the glTF sample models ($M); renders for minutes"),
    ("docs/performance.md", r"^apt-get install\b", "line", "apt-get: installs a package (root)"),
    ("docs/performance.md", r"compare_cycles\.py", "line",
     "needs Blender 3.4 (the apt-get line above), not on test machines"),
]
# Applied, in order, to every line that runs (our commands and shell set-up alike).
SUBSTITUTIONS = [
    (r"\b(HOST|head):7878\b", "$DOCS_COORD", "a remote coordinator: the block's own, or the test's farm"),
    (r"/CN=HOST\b", "/CN=127.0.0.1", "a certificate for HOST: for 127.0.0.1"),
    (r"\bDNS:HOST\b", "IP:127.0.0.1", "a certificate for HOST: for 127.0.0.1"),
]
# Benchmark scripts: extra arguments that shrink them (argparse takes the last).
SHRINK_SCRIPTS = {
    "bench/error_report.py": ["--spp", "1", "--seeds", "1", "--ref-spp", "2", "--flags", "-r 32 24 -m 16 -l 1"],
    "bench/features.py": ["--spp", "1", "--ref-spp", "2"],
    # (Tessera's two variants only: Blender is not on test machines; regions that do not fit
    # a 32x24 image are left out)
    "bench/cycles/caustics_report.py": ["--no-cycles", "--spp", "1", "--seeds", "1", "--ref-spp", "2", "--flags",
                                        "-r 32 24 -m 16 -l 1"],
    # (the gallery into the block's folder: docs/ is the repository's own)
    "bench/blender/fidelity.py": ["--scenes", "diffuse-metal", "--spp", "4", "--width", "32", "--height", "24",
                                  "--out", "out/report", "--gallery", "out/gallery"],
}
# Placeholder files the examples name: made from a scene we ship.
PLACEHOLDERS = {"scene.dae": "scenes/cornell-spheres.dae", "shot.dae": "scenes/cornell-spheres.dae"}
# (file, regex of a line in the block, why, shell run before the block).
FIXTURES = [
    ("docs/blender.md", r"blender -b shot\.blend",
     "a shot.blend (the factory scene, 32 x 18, frames 1-2, 1 sample, output //out/shot_) and the add-on "
     "installed and enabled in this home, as the page's install steps leave them",
     """blender -b --factory-startup --python-expr "import bpy
bpy.ops.preferences.addon_install(filepath='$DOCS_BIN/../blender/tessera_blender.zip')
bpy.ops.preferences.addon_enable(module='tessera_blender')
bpy.ops.wm.save_userpref()
s = bpy.context.scene
s.render.resolution_x, s.render.resolution_y, s.frame_end, s.tessera.samples = 32, 18, 2, 1
s.render.filepath = '//out/shot_'
bpy.ops.wm.save_as_mainfile(filepath='$PWD/shot.blend')" >/dev/null"""),
    ("docs/deploy.md", r"deploy/slurm/tessera-workers\.sbatch",
     "the tokens and certificate docs/security.md has the reader make first, the enrolment token in "
     "~/.tessera, and the client's token and CA exported as README's farm section does",
     """umask 077; mkdir -p ~/.tessera
openssl rand -hex 24 > ~/.tessera/enrol.token; openssl rand -hex 24 > me.token
printf 'enrol farm %s\\nclient me %s\\n' "$(cat ~/.tessera/enrol.token)" "$(cat me.token)" > tokens
openssl req -x509 -newkey rsa:2048 -nodes -days 1 -subj /CN=127.0.0.1 -addext subjectAltName=IP:127.0.0.1 \\
  -keyout key.pem -out cert.pem 2>/dev/null
export TESSERA_TOKEN_FILE=$PWD/me.token TESSERA_TLS_CA=$PWD/cert.pem; umask 022"""),
]

# Shell functions every block has. Background processes' output goes to $DOCS_LOGS.
PRELUDE = r"""
set -o pipefail
__docs_n=0
__docs_bg=()
__docs_begin() { echo "@@docs-line $1"; }
__docs_end() {
  local rc=$?
  if [ $rc -ne 0 ]; then echo "@@docs-failed $rc"; exit 111; fi
}
__docs_coordinator() {  # CMD ARGS...: in the background on loopback, then DOCS_COORD is its address
  local args=("$1") n log; shift
  __docs_n=$((__docs_n + 1)); n=$__docs_n; log="$DOCS_LOGS/coordinator-$n"
  while [ $# -gt 0 ]; do
    case "$1" in
      --listen|--http|--health) args+=("$1" 127.0.0.1:0); shift 2 ;;
      --data) args+=(--data "$DOCS_SCRATCH/coordinator-data-$n"); shift 2 ;;
      *) args+=("$1"); shift ;;
    esac
  done
  echo "(background) ${args[*]}"; echo "${args[*]}" >"$log.cmd"
  "${args[@]}" >"$log.out" 2>"$log.err" </dev/null &
  __docs_bg+=("$!:$log"); echo "$! $log" >>"$DOCS_LOGS/background"
  for _ in $(seq 200); do
    grep -q '^http listening on' "$log.out" 2>/dev/null && break
    kill -0 $! 2>/dev/null || break
    sleep 0.05
  done
  DOCS_COORD=$(sed -n 's/^grpc listening on \([^ ]*\).*/\1/p' "$log.out")
  if [ -z "$DOCS_COORD" ]; then echo "the coordinator did not start:"; cat "$log.err"; return 1; fi
  echo "coordinator at $DOCS_COORD"
}
__docs_worker() {  # CMD ARGS...: in the background, its scene cache in the scratch folder
  local args=("$1") n log; shift
  __docs_n=$((__docs_n + 1)); n=$__docs_n; log="$DOCS_LOGS/worker-$n"
  while [ $# -gt 0 ]; do
    case "$1" in
      --cache) shift 2 ;;
      *) args+=("$1"); shift ;;
    esac
  done
  args+=(--cache "$DOCS_SCRATCH/worker-cache-$n")
  echo "(background) ${args[*]}"; echo "${args[*]}" >"$log.cmd"
  "${args[@]}" >"$log.out" 2>"$log.err" </dev/null &
  __docs_bg+=("$!:$log"); echo "$! $log" >>"$DOCS_LOGS/background"
}
__docs_last_job() {
  "$DOCS_BIN/tessera" jobs --no-headers --coordinator "$DOCS_COORD" | tail -n 1 | cut -d' ' -f1
}
__docs_finish() {  # every background process of the block still running
  local p
  for p in "${__docs_bg[@]}"; do
    if ! kill -0 "${p%%:*}" 2>/dev/null; then
      echo "@@docs-died ${p#*:}"; tail -n 20 "${p#*:}.err"; exit 112
    fi
  done
}
"""

FAKE_SBATCH = r"""#!/bin/bash
# The docs test's sbatch: runs the batch script here, in the background, as a one-node,
# one-CPU allocation (its output in tessera-workers-JOBID.out, as Slurm's).
while [ $# -gt 0 ] && [ "${1#-}" != "$1" ]; do shift; done
script=$1; shift
export SLURM_JOB_ID=$$ SLURM_CPUS_ON_NODE=1
bash "$script" "$@" >"tessera-workers-$SLURM_JOB_ID.out" 2>&1 </dev/null &
echo "Submitted batch job $SLURM_JOB_ID"
"""
FAKE_SRUN = r"""#!/bin/bash
# The docs test's srun: its options dropped, the command run.
while [ $# -gt 0 ] && [ "${1#-}" != "$1" ]; do shift; done
exec "$@"
"""
