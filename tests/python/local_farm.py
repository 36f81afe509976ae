"""A farm on loopback for the Python client's and the Blender add-on's tests: a coordinator
(127.0.0.1, ports picked by the kernel) and workers, started and stopped by the test, and
the `tessera` CLI and tessera_compare beside them (BIN)."""
import os
import re
import subprocess
import tempfile
import time


class LocalFarm:
    """`tokens` (a list of "ROLE NAME") makes the coordinator ask for tokens: each token is
    written to DIR/NAME.token, and the workers use the first worker one. `tls` serves TLS
    with a certificate for 127.0.0.1 made here (DIR/cert.pem is its CA)."""

    def __init__(self, bin_dir, workers=1, threads=1, tokens=None, tls=False, extra=()):
        self.bin = bin_dir
        self.dir = tempfile.mkdtemp(prefix="tessera-pyfarm-")
        self.procs = []
        args = ["--listen", "127.0.0.1:0", "--http", "127.0.0.1:0", "--data", self.path("data"), *extra]
        self.tokens = {}
        if tokens:
            lines = []
            for entry in tokens:
                role, name = entry.split()
                token = os.urandom(24).hex()
                self.tokens[name] = self.path(name + ".token")
                with open(self.tokens[name], "w") as f:
                    f.write(token + "\n")
                lines.append(f"{role} {name} {token}")
            with open(self.path("tokens"), "w") as f:
                f.write("\n".join(lines) + "\n")
            os.chmod(self.path("tokens"), 0o600)
            args += ["--tokens-file", self.path("tokens")]
        self.ca = None
        if tls:
            subprocess.run(["openssl", "req", "-x509", "-newkey", "rsa:2048", "-nodes", "-days", "1", "-subj",
                            "/CN=127.0.0.1", "-addext", "subjectAltName=IP:127.0.0.1", "-keyout", self.path("key.pem"),
                            "-out", self.path("cert.pem")], check=True, capture_output=True)
            self.ca = self.path("cert.pem")
            args += ["--tls-cert", self.ca, "--tls-key", self.path("key.pem")]
        self.coordinator_args = args
        self.address = None
        self.address = self._start_coordinator()
        worker_token = next((self.tokens[e.split()[1]] for e in tokens or () if e.startswith("worker ")), None)
        for i in range(workers):
            cmd = [os.path.join(bin_dir, "tessera-worker"), "--coordinator", self.address, "--threads", str(threads),
                   "--cache", self.path(f"cache{i}"), "--name", f"py-worker-{i}"]
            if worker_token:
                cmd += ["--token-file", worker_token]
            if self.ca:
                cmd += ["--tls-ca", self.ca]
            self._start(cmd, os.devnull, self.path(f"worker{i}.err"))

    def _start(self, cmd, out, err):
        with open(out, "w") as o, open(err, "w") as e:
            p = subprocess.Popen(cmd, stdout=o, stderr=e, stdin=subprocess.DEVNULL)
        self.procs.append(p)
        return p

    def _start_coordinator(self):
        """Starts the coordinator (again: on the address it had, and its --data) and returns
        its gRPC address once it listens."""
        args = list(self.coordinator_args)
        if self.address:
            args[args.index("--listen") + 1] = self.address
        out = self.path("coordinator.out")
        if self.address and os.path.exists(out):
            os.unlink(out)
        self.coordinator = self._start([os.path.join(self.bin, "tessera-coordinator")] + args, out,
                                       self.path("coordinator.err"))
        for _ in range(600):
            with open(out) as f:
                text = f.read()
            m = re.search(r"^grpc listening on (\S+)", text, re.M)
            if m and "http listening on" in text:
                return m.group(1)
            if self.coordinator.poll() is not None:
                break
            time.sleep(0.05)
        self.stop()
        raise RuntimeError("the test's coordinator did not start: " + self.log()[-800:])

    def restart_coordinator(self):
        """kill -9, then the same coordinator again on its address and data folder."""
        self.coordinator.kill()
        self.coordinator.wait()
        self.procs.remove(self.coordinator)
        self._start_coordinator()

    def path(self, *parts):
        return os.path.join(self.dir, *parts)

    def log(self):
        with open(self.path("coordinator.err")) as f:
            return f.read()

    def cli(self, *args, token=None, check=True):
        """Runs `tessera ARGS` against this farm."""
        env = {k: v for k, v in os.environ.items() if not k.startswith("TESSERA_")}
        env["TESSERA_COORDINATOR"] = self.address
        if token:
            env["TESSERA_TOKEN_FILE"] = self.tokens[token]
        if self.ca:
            env["TESSERA_TLS_CA"] = self.ca
        r = subprocess.run([os.path.join(self.bin, "tessera")] + list(args), capture_output=True, text=True,
                           env=env, timeout=300)
        if check and r.returncode != 0:
            raise AssertionError(f"tessera {' '.join(args)}: exit {r.returncode}: {r.stderr[-800:]}")
        return r

    def stop(self):
        for p in reversed(self.procs):
            p.terminate()
        for p in self.procs:
            try:
                p.wait(timeout=15)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
        subprocess.run(["rm", "-rf", self.dir])


def render_local(bin_dir, scene, out, *flags):
    """`tessera render SCENE FLAGS -f OUT -q` here, in one process."""
    r = subprocess.run([os.path.join(bin_dir, "tessera"), "render", scene, *flags, "-f", out, "-q"],
                       capture_output=True, text=True, timeout=600)
    if r.returncode != 0:
        raise AssertionError(f"tessera render {scene}: exit {r.returncode}: {r.stderr[-800:]}")


def identical(bin_dir, a, b):
    """Whether two EXRs hold the same bits in every channel (bench/compare.cc)."""
    import json
    r = subprocess.run([os.path.join(bin_dir, "tessera_compare"), a, b], capture_output=True, text=True, timeout=120)
    if r.returncode != 0:
        raise AssertionError(f"tessera_compare {a} {b}: exit {r.returncode}: {r.stderr[-400:]}")
    return json.loads(r.stdout)["identical"]
