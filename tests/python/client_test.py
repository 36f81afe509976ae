#!/usr/bin/python3
"""CTest entry (Python.ClientAgainstALocalFarm): the Python client (build/python/tessera)
against real farms on loopback: a still and a sequence bit-identical to `tessera render`,
a glTF with external files and an environment map, typed statuses and events, id prefixes,
cancel / requeue / priority / delete, errors carrying the coordinator's message, and a farm
with tokens and TLS. Usage: client_test.py BIN_DIR PYTHON_DIR SOURCE_DIR"""
import base64
import datetime
import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import threading
import time
import unittest

BIN, PYDIR, SRC = (os.path.abspath(a) for a in sys.argv[1:4])
del sys.argv[1:4]
sys.path.insert(0, PYDIR)
sys.path.insert(0, os.path.dirname(__file__))
import tessera  # noqa: E402
from local_farm import LocalFarm, identical, render_local  # noqa: E402

SPHERES = os.path.join(SRC, "scenes", "cornell-spheres.dae")
SPHERES_GLTF = os.path.join(SRC, "scenes", "cornell-spheres.gltf")
SKY = os.path.join(SRC, "scenes", "sky.hdr")
SMALL = dict(samples=4, resolution=(32, 24), pass_spp=2, tile=16)
SMALL_FLAGS = ["-s", "4", "-r", "32", "24", "--pass-spp", "2", "--tile", "16"]


class Plain(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.farm_procs = LocalFarm(BIN, workers=1, threads=2)
        cls.farm = tessera.Farm(cls.farm_procs.address)
        cls.tmp = tempfile.mkdtemp(prefix="tessera-pyclient-")

    @classmethod
    def tearDownClass(cls):
        cls.farm.close()
        cls.farm_procs.stop()
        subprocess.run(["rm", "-rf", cls.tmp])

    def out(self, name):
        return os.path.join(self.tmp, name)

    def test_a_still_is_the_local_render_bit_for_bit(self):
        job = self.farm.submit(SPHERES, name="still", **SMALL, max_depth=3, seed=7)
        self.assertRegex(job.id, r"^[0-9a-f]{16}$")
        final = job.wait()
        self.assertEqual(final.state, "DONE")
        self.assertEqual(final.progress, 1.0)
        self.assertIsInstance(final.samples_done, int)
        self.assertEqual(final.samples_done, 32 * 24 * 4)
        self.assertIsInstance(final.elapsed_seconds, float)
        for t in (final.submitted_at, final.started_at, final.ended_at):
            self.assertIsInstance(t, datetime.datetime)
            self.assertEqual(t.utcoffset(), datetime.timedelta(0))
        self.assertLessEqual(final.submitted_at, final.ended_at)
        self.assertEqual(final.settings["spp"], 4)
        self.assertEqual(final.settings["max_depth"], 3)
        self.assertEqual(final.name, "still")
        got = job.fetch(self.out("new/folder/still.exr")) + job.fetch(self.out("still.png"))
        self.assertEqual([f.path for f in got], [self.out("new/folder/still.exr"), self.out("still.png")])
        self.assertTrue(all(f.final for f in got))
        with open(self.out("still.png"), "rb") as f:
            self.assertEqual(f.read(8), b"\x89PNG\r\n\x1a\n")
        render_local(BIN, SPHERES, self.out("local.exr"), *SMALL_FLAGS, "-m", "3", "--seed", "7")
        self.assertTrue(identical(BIN, self.out("new/folder/still.exr"), self.out("local.exr")))
        # The CLI sees the same job.
        cli = json.loads(self.farm_procs.cli("status", job.id, "--json").stdout)
        self.assertEqual(cli["samples_done"], final.samples_done)

    def test_a_cut_download_resumes_where_it_was_cut(self):
        # Through a narrow relay (tessera-wan-proxy) cut midway: the fetch goes on, within
        # reconnect_seconds of the last piece that came, and the file is the whole image.
        job = self.farm.submit(SPHERES, samples=1, resolution=(320, 240), pass_spp=1, tile=64, seed=3)
        self.assertEqual(job.wait().state, "DONE")
        job.fetch(self.out("direct.exr"))
        relay = subprocess.Popen([os.path.join(BIN, "tessera-wan-proxy"), "--to", self.farm_procs.address,
                                  "--mbit", "4"], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
        try:
            port = re.search(r"listening on 127\.0\.0\.1:(\d+)", relay.stdout.readline()).group(1)
            far = tessera.Farm("127.0.0.1:" + port, reconnect_seconds=30)
            job_far = far.job(job.id)
            cutter = threading.Timer(0.5, lambda: relay.send_signal(signal.SIGUSR1))  # mid-download (about 2 s)
            cutter.start()
            try:
                started = time.monotonic()
                job_far.fetch(self.out("relayed.exr"))
                self.assertGreater(time.monotonic() - started, 0.5)  # (the cut came while it ran)
            finally:
                cutter.join()
                far.close()
        finally:
            relay.terminate()
            relay.wait()
        with open(self.out("direct.exr"), "rb") as a, open(self.out("relayed.exr"), "rb") as b:
            self.assertEqual(a.read(), b.read())

    def test_a_sequence_is_watched_and_its_frames_fetched(self):
        job = self.farm.submit(SPHERES, frames="3-5x2", **SMALL)
        seen = list(job.watch())
        self.assertTrue(seen[-1].ended)
        self.assertFalse(any(s.ended for s in seen[:-1]))
        self.assertEqual(seen[-1].state, "DONE")
        self.assertEqual([f.frame for f in seen[-1].frames], [3, 5])
        self.assertEqual(seen[-1].frames_total, 2)
        self.assertTrue(all(f.state == "DONE" for f in seen[-1].frames))
        got = job.fetch(self.out("seq/shot.####.exr"))
        self.assertEqual(sorted(os.path.basename(f.path) for f in got), ["shot.0003.exr", "shot.0005.exr"])
        one = job.fetch(self.out("one.exr"), frame=5)
        self.assertEqual(one[0].frame, 5)
        render_local(BIN, SPHERES, self.out("local5.exr"), *SMALL_FLAGS, "--frame", "5")
        self.assertTrue(identical(BIN, self.out("seq/shot.0005.exr"), self.out("local5.exr")))
        self.assertTrue(identical(BIN, self.out("one.exr"), self.out("local5.exr")))
        with self.assertRaisesRegex(tessera.TesseraError, "give frame=N, or a path with ####"):
            job.fetch(self.out("seq.exr"))

    def test_a_gltf_with_external_files_and_an_environment_map(self):
        # cornell-spheres.gltf with its buffer moved out to "buffers/scene data.bin" (a
        # percent-encoded URI), lit by sky.hdr too.
        with open(SPHERES_GLTF) as f:
            doc = json.load(f)
        uri = doc["buffers"][0]["uri"]
        os.makedirs(self.out("ext/buffers"), exist_ok=True)
        with open(self.out("ext/buffers/scene data.bin"), "wb") as f:
            f.write(base64.b64decode(uri.split(",", 1)[1]))
        doc["buffers"][0]["uri"] = "buffers/scene%20data.bin"
        with open(self.out("ext/scene.gltf"), "w") as f:
            json.dump(doc, f)
        job = self.farm.submit(self.out("ext/scene.gltf"), env=SKY, env_strength=0.5, **SMALL)
        job.wait()
        job.fetch(self.out("ext.exr"))
        render_local(BIN, self.out("ext/scene.gltf"), self.out("ext-local.exr"), *SMALL_FLAGS, "-e", SKY,
                     "--env-strength", "0.5")
        self.assertTrue(identical(BIN, self.out("ext.exr"), self.out("ext-local.exr")))
        os.unlink(self.out("ext/buffers/scene data.bin"))
        with self.assertRaisesRegex(tessera.TesseraError, "scene data.bin"):
            self.farm.submit(self.out("ext/scene.gltf"), **SMALL)

    def test_aov_layers_through_the_farm_are_the_local_ones(self):
        job = self.farm.submit(SPHERES_GLTF, aov=["albedo", "normal", "depth"], **SMALL)
        self.assertEqual(job.wait().settings["aovs"], 2 | 4 | 8)
        job.fetch(self.out("aov.exr"))
        render_local(BIN, SPHERES_GLTF, self.out("aov-local.exr"), *SMALL_FLAGS, "--aov", "albedo,normal,depth")
        self.assertTrue(identical(BIN, self.out("aov.exr"), self.out("aov-local.exr")))
        with self.assertRaisesRegex(ValueError, "'zdepth' is not an AOV"):
            self.farm.submit(SPHERES, aov="zdepth")

    def test_denoise_through_the_farm_is_the_local_one(self):
        job = self.farm.submit(SPHERES_GLTF, denoise=True, **SMALL)
        settings = job.wait().settings
        self.assertTrue(settings["denoise"])
        self.assertEqual(settings["aovs"], 2 | 4 | 8 | 32)  # the denoising layers come with it
        job.fetch(self.out("denoised.exr"))
        render_local(BIN, SPHERES_GLTF, self.out("denoised-local.exr"), *SMALL_FLAGS, "--denoise")
        self.assertTrue(identical(BIN, self.out("denoised.exr"), self.out("denoised-local.exr")))

    def test_watch_rides_out_a_coordinator_killed_and_started_again(self):
        job = self.farm.submit(SPHERES, samples=512, resolution=(64, 48), seed=3)
        seen = []
        for s in job.watch():
            seen.append(s)
            if len(seen) == 2:
                self.farm_procs.restart_coordinator()  # mid-render: the stream breaks
        self.assertEqual(seen[-1].state, "DONE")
        self.assertGreater(len(seen), 2)  # statuses came after the restart too
        job.fetch(self.out("restarted.exr"))
        render_local(BIN, SPHERES, self.out("restarted-local.exr"), "-s", "512", "-r", "64", "48", "--seed", "3")
        self.assertTrue(identical(BIN, self.out("restarted.exr"), self.out("restarted-local.exr")))

    def test_jobs_prefixes_events_and_control(self):
        job = self.farm.submit(SPHERES, samples=4096, resolution=(64, 48), priority=2, name="long")
        self.assertEqual(self.farm.job(job.id[:7]).id, job.id)
        listed = {j.id: j for j in self.farm.jobs()}
        self.assertIn(job.id, listed)
        self.assertEqual(listed[job.id].priority, 2)
        self.assertEqual(job.set_priority(5).priority, 5)
        self.assertEqual(job.cancel().id, job.id)
        with self.assertRaises(tessera.JobFailed) as e:
            job.wait()
        self.assertEqual(e.exception.status.state, "CANCELLED")
        self.assertEqual(job.wait(check=False).state, "CANCELLED")
        self.assertIn(job.requeue().state, ("QUEUED", "RUNNING"))
        job.cancel()
        kinds = [e.kind for e in job.events()]
        for k in ("job.submitted", "job.priority", "job.cancelled", "job.requeued"):
            self.assertIn(k, kinds)
        self.assertTrue(all(isinstance(e.time, datetime.datetime) for e in job.events()))
        self.assertGreaterEqual(job.delete(), 0)
        with self.assertRaises(tessera.TesseraError) as e:
            job.status()
        self.assertEqual(e.exception.code, "NOT_FOUND")
        self.assertIn(job.id, e.exception.message)

    def test_a_scene_that_changes_while_it_is_sent_is_named(self):
        # Found by audit: the bundle's own error, raised inside the stream gRPC reads, came
        # back as gRPC's "Exception iterating requests!".
        from unittest import mock
        from tessera.bundle import Bundle, SceneError

        original = Bundle.chunks

        def changing(bundle):
            yield next(original(bundle))  # the manifest
            raise SceneError("scene.dae: changed while it was sent")
        with mock.patch.object(Bundle, "chunks", changing):
            with self.assertRaisesRegex(tessera.TesseraError, "scene.dae: changed while it was sent"):
                self.farm.submit(SPHERES, **SMALL)

    def test_errors_name_the_problem(self):
        with self.assertRaisesRegex(TypeError, "unknown render setting: sampels"):
            self.farm.submit(SPHERES, sampels=4)
        with self.assertRaises(tessera.TesseraError) as e:
            self.farm.submit(SPHERES, samples=0, resolution=(32, 24))
        self.assertEqual(e.exception.code, "INVALID_ARGUMENT")
        self.assertRegex(e.exception.message, r"-s|spp|samples")
        with self.assertRaisesRegex(tessera.TesseraError, "no-such.dae"):
            self.farm.submit(self.out("no-such.dae"))
        with self.assertRaisesRegex(ValueError, "runs backwards"):
            self.farm.submit(SPHERES, frames="5-3")
        with self.assertRaisesRegex(tessera.TesseraError, "no job id starts with 'abcdef'"):
            self.farm.job("abcdef")
        job = self.farm.submit(SPHERES, **SMALL)
        with self.assertRaisesRegex(tessera.TesseraError, r"\.exr or \.png"):
            job.fetch(self.out("x.jpg"))
        job.wait()
        gone = tessera.Farm("127.0.0.1:1", timeout=2)
        with self.assertRaises(tessera.TesseraError) as e:
            gone.jobs()
        self.assertIn(e.exception.code, ("UNAVAILABLE", "DEADLINE_EXCEEDED"))

    def test_defaults_are_the_clis(self):
        # Every default that `tessera submit --help` prints is the Python client's.
        help_text = subprocess.run([os.path.join(BIN, "tessera"), "submit", "--help"], capture_output=True,
                                   text=True).stdout
        names = {"-s": "samples", "-l": "light_samples", "-m": "max_depth", "-b": "lens_radius",
                 "-d": "focal_distance", "--seed": "seed", "--pass-spp": "pass_spp", "--tile": "tile",
                 "--noise-target": "noise_target", "--fps": "fps", "--env-strength": "env_strength",
                 "--env-rotate": "env_rotate", "--exposure": "exposure", "--camera": "camera"}
        checked = 0
        for line in help_text.splitlines():
            m = re.match(r"^\s+(?:-\w,)?(--?[\w-]+) \S+?=(\S+)", line)
            if m and m.group(1) in names:
                want = tessera.DEFAULTS[names[m.group(1)]]
                self.assertEqual(str(want) if isinstance(want, str) else float(m.group(2)),
                                 m.group(2) if isinstance(want, str) else float(want), m.group(1))
                checked += 1
            m = re.match(r"^\s+-r \S+=\[(\d+),(\d+)\]", line)
            if m:
                self.assertEqual(tessera.DEFAULTS["resolution"], (int(m.group(1)), int(m.group(2))))
                checked += 1
        self.assertGreaterEqual(checked, len(names))


class Units(unittest.TestCase):
    """The client's pieces without a farm."""

    def test_frames_as_the_cli_reads_them(self):
        self.assertEqual(tessera.parse_frames("1-5x2,9,-3--1"), [1, 3, 5, 9, -3, -2, -1])
        self.assertEqual(tessera.parse_frames([4, 2]), [4, 2])
        for bad, why in (("3-1", "runs backwards"), ("1,1", "given twice"), ("a", "is not N"), ("1-4x0", "step"),
                         ("1-200000", "more than 100000"), ("2000000", "beyond")):
            with self.assertRaisesRegex(ValueError, why):
                tessera.parse_frames(bad)

    def test_values_the_cli_refuses_are_refused_naming_them(self):
        from tessera import settings
        # Found by audit: 2.7 samples became 2, True became 1, fps=0 rendered at 24, a window
        # outside the image and a seed past 64 bits raised protobuf's "Value out of range".
        for kw, why in ((dict(samples=2.9), "samples: must be a whole number"),
                        (dict(samples=True), "samples: must be a whole number"),
                        (dict(adaptive=(2.7, 0.05)), "adaptive batch: must be a whole number"),
                        (dict(fps=0), "fps: must be > 0"),
                        (dict(resolution=(16.9, 12)), "resolution: must be a whole number"),
                        (dict(resolution=(16, 12), window=(0, 10, 4, 4)), "window: .* is not a cell of the 16 x 12"),
                        (dict(seed=-1), "seed: -1 is beyond"), (dict(seed=2 ** 64), "seed: .* is beyond"),
                        (dict(frame=2 ** 40), "frame: .* is beyond"), (dict(aov=["albedo", 3]), "aov: .* names")):
            with self.assertRaisesRegex(ValueError, why):
                settings.to_proto("x.dae", **kw)
        self.assertEqual(settings.to_proto("x.dae", samples=4.0, seed=2 ** 64 - 1)[0].spp, 4)
        self.assertEqual(settings.to_proto("x.dae", turntable=0)[0].camera_path, "")  # as --turntable 0
        for bad in ([1.9, 2.2], 5):
            with self.assertRaises(ValueError):
                tessera.parse_frames(bad)

    def test_frame_paths_as_the_cli_writes_them(self):
        self.assertEqual(tessera.frame_path("out/shot.####.exr", 7), "out/shot.0007.exr")
        self.assertEqual(tessera.frame_path("a#b.##.png", 123), "a#b.123.png")
        self.assertEqual(tessera.frame_path("s.####.exr", -7), "s.-007.exr")
        self.assertEqual(tessera.frame_path("still.exr", 3), "still.exr")

    def test_a_long_scene_path_names_the_job_by_its_file_within_the_bound(self):
        from tessera.farm import _default_name
        from tessera._build import MAX_JOB_NAME_BYTES
        self.assertEqual(MAX_JOB_NAME_BYTES, 256)  # proto/wire.h, read at build time
        self.assertEqual(_default_name("scenes/a.gltf"), "scenes/a.gltf")
        self.assertEqual(_default_name("/" + "d" * 300 + "/sc\u00e9ne.gltf"), "sc\u00e9ne.gltf")
        # A file name past the bound is cut on a character boundary, never inside one.
        cut = _default_name("/x/" + "a" * 255 + "\u00e9")
        self.assertEqual(cut, "a" * 255)

    def test_cli_flags_round_trip_the_settings(self):
        from tessera import settings
        self.assertEqual(settings.cli_flags(samples=8, resolution=(64, 48), env_color=(0.5, 1, 0.25), no_mis=True,
                                            max_depth=16),
                         ["-s", "8", "-r", "64", "48", "--env-color", "0.5", "1", "0.25", "--no-mis"])
        with self.assertRaisesRegex(TypeError, "sampels"):
            settings.cli_flags(sampels=1)
        p, env = settings.to_proto("x.gltf", window=(1, 2, 3, 4), resolution=(10, 20), adaptive=(8, 0.1))
        self.assertEqual((p.window.x, p.window.y, p.window.w, p.window.h), (1, 20 - (2 + 4), 3, 4))
        self.assertEqual(p.framing, p.FILE)
        self.assertTrue(p.adaptive)
        self.assertEqual(settings.to_proto("x.dae")[0].framing, p.CS184)
        # --light-tracer: auto by default (2 on the wire, as the CLI sends it), a flag otherwise.
        self.assertEqual(settings.to_proto("x.dae")[0].light_tracer, 2)
        self.assertEqual(settings.to_proto("x.dae", light_tracer="off")[0].light_tracer, 0)
        self.assertEqual(settings.cli_flags(light_tracer="on"), ["--light-tracer", "on"])
        with self.assertRaisesRegex(ValueError, "light_tracer: 'maybe' is not auto, on or off"):
            settings.to_proto("x.dae", light_tracer="maybe")

    def test_a_bundle_names_what_a_gltf_needs_and_refuses_paths_outside(self):
        from tessera.bundle import Bundle, SceneError, scene_files
        d = tempfile.mkdtemp(prefix="tessera-pybundle-")
        try:
            with open(os.path.join(d, "a.gltf"), "w") as f:
                json.dump({"buffers": [{"uri": "b%20c.bin"}, {"uri": "data:application/octet-stream;base64,AA=="}],
                           "images": [{"uri": "t/i.png"}, {"uri": "b%20c.bin"}]}, f)
            self.assertEqual([r for r, _ in scene_files(os.path.join(d, "a.gltf"))], ["a.gltf", "b c.bin", "t/i.png"])
            os.makedirs(os.path.join(d, "t"))
            for name in ("b c.bin", "t/i.png"):
                with open(os.path.join(d, name), "wb") as f:
                    f.write(b"x" * 3)
            b = Bundle(os.path.join(d, "a.gltf"))
            self.assertRegex(b.hash, r"^[0-9a-f]{32}$")
            self.assertEqual(b.sizes[1:], [3, 3])
            with open(os.path.join(d, "bad.gltf"), "w") as f:
                json.dump({"images": [{"uri": "../secret.png"}]}, f)
            with self.assertRaisesRegex(SceneError, "not a path inside the scene's folder"):
                scene_files(os.path.join(d, "bad.gltf"))
        finally:
            subprocess.run(["rm", "-rf", d])


class Secure(unittest.TestCase):
    """Tokens and TLS: the client's token and CA as the CLI takes them."""

    @classmethod
    def setUpClass(cls):
        cls.farm_procs = LocalFarm(BIN, tokens=["client me", "viewer eye", "worker w"], tls=True)

    @classmethod
    def tearDownClass(cls):
        cls.farm_procs.stop()

    def test_token_and_tls(self):
        f = self.farm_procs
        with tessera.Farm(f.address, token_file=f.tokens["me"], tls_ca=f.ca) as farm:
            job = farm.submit(SPHERES, **SMALL)
            self.assertEqual(job.wait().owner, "me")
        os.environ.update(TESSERA_COORDINATOR=f.address, TESSERA_TOKEN_FILE=f.tokens["eye"], TESSERA_TLS_CA=f.ca)
        try:
            with tessera.Farm() as viewer:  # everything from the environment
                self.assertEqual(viewer.job(job.id).status().state, "DONE")
                with self.assertRaises(tessera.TesseraError) as e:
                    viewer.job(job.id).cancel()
                self.assertEqual(e.exception.code, "PERMISSION_DENIED")
        finally:
            for k in ("TESSERA_COORDINATOR", "TESSERA_TOKEN_FILE", "TESSERA_TLS_CA"):
                del os.environ[k]
        with self.assertRaises(tessera.TesseraError) as e:
            tessera.Farm(f.address, tls_ca=f.ca).jobs()
        self.assertEqual(e.exception.code, "UNAUTHENTICATED")
        with self.assertRaisesRegex(tessera.TesseraError, "serves TLS closes plaintext connections"):
            tessera.Farm(f.address, token_file=f.tokens["me"], timeout=5).jobs()


if __name__ == "__main__":
    unittest.main(verbosity=2)
