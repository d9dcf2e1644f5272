"""The studio page in a real headless Chromium against a real tempokey-server.

Run by CTest (label `browser`); tests/studio/CMakeLists.txt sets the environment:
  TEMPOKEY_SERVER, TEMPOKEY_CLI    the built binaries
  TEMPOKEY_SHARED_DIR              ../shared (131_01 under data/bvh/cmu)
  TEMPOKEY_ARTEFACTS_DIR           where the screenshots go (the build tree)
  TEMPOKEY_CHROMIUM, TEMPOKEY_CHROMEDRIVER

The tests run in order (unittest sorts them by name: the numbers are that order) on one page, by
design, as a person would use it: open 131_01, build a speed curve with the mouse and the keyboard,
check the duration against the closed form, play the preview and check the frame shown, reduce and
compare the key count with the CLI's, download every format and compare the bytes with the CLI's
files, then open a malformed file, and so on. Each test starts from the page the one before left,
so they are not meant to run alone; where one uses what another made (9b the busy server and the
queued job of 9a) it says so. Every wait polls the page for a state with a deadline that only bounds
a hang; nothing asserts a time.
"""

import base64
import json
import os
import random
import re
import shutil
import shlex
import subprocess
import sys
import tempfile
import time
import unittest
import urllib.error
import urllib.request

from selenium import webdriver
from selenium.webdriver.chrome.service import Service
from selenium.webdriver.common.action_chains import ActionChains
from selenium.webdriver.common.actions.wheel_input import ScrollOrigin
from selenium.webdriver.common.by import By
from selenium.webdriver.common.keys import Keys
from selenium.webdriver.support.ui import Select

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import closed_form  # noqa: E402
from studio_server import StudioServer, env_path  # noqa: E402

CLI = env_path("TEMPOKEY_CLI")
SHARED_DIR = env_path("TEMPOKEY_SHARED_DIR")
ARTEFACTS = env_path("TEMPOKEY_ARTEFACTS_DIR")
CHROMIUM = os.environ.get("TEMPOKEY_CHROMIUM", "/usr/bin/chromium")
CHROMEDRIVER = os.environ.get("TEMPOKEY_CHROMEDRIVER", "/usr/bin/chromedriver")
CMU = os.path.join(SHARED_DIR, "data", "bvh", "cmu", "131_01.bvh")
# The Khronos glTF validator under node (tests/export, pinned there; deploy/install-deps.sh).
GLTF_VALIDATE = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "export", "validate.mjs")

# Bounds on waits: generous for a loaded 2-core machine, never a performance claim.
DEADLINE_SECONDS = 90
# The page shows the server's doubles; the closed form is evaluated independently in Python.
CLOSED_FORM_REL = 1e-9
# three.js keeps keyframe values in Float32Array.
FLOAT32_REL = 2e-6
# The page's editor geometry (velocity_editor.js PAD and its default speed view).
EDITOR_PAD_LEFT, EDITOR_PAD_RIGHT, EDITOR_PAD_TOP, EDITOR_PAD_BOTTOM = 48, 14, 14, 28
VIEW_LO, VIEW_HI = 0.05 / 1.25, 20 * 1.25


def wait_for(predicate, what, deadline=DEADLINE_SECONDS):
    end = time.monotonic() + deadline
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > end:
            raise AssertionError("timed out waiting for " + what)
        time.sleep(0.05)


def read_bvh(path):
    """(frame time, rows) of a BVH file: a plain reading of the text."""
    with open(path) as f:
        text = f.read()
    motion = text.split("MOTION", 1)[1]
    lines = [line for line in motion.strip().splitlines() if line.strip()]
    frame_time = float(lines[1].split(":")[1])
    rows = [[float(v) for v in line.split()] for line in lines[2:]]
    return frame_time, rows


def bvh_local_translations(path, frame):
    """Each joint's and end site's (parent index, local translation) at `frame` of a BVH file, in
    the file's order: the OFFSET, each position channel replacing it on its axis (README "File
    formats"), as Blender's BVH import reads them."""
    with open(path) as f:
        head, motion = f.read().split("MOTION", 1)
    row = [float(v) for v in [line for line in motion.strip().splitlines() if line.strip()][2 + frame].split()]
    words = head.split()
    nodes, stack, column, at = [], [], 0, 0
    while at < len(words):
        word = words[at]
        if word in ("ROOT", "JOINT") or word == "End":
            nodes.append([stack[-1] if stack else -1, None, []])
            stack.append(len(nodes) - 1)
            at += 3  # name (or "Site") and "{"
        elif word == "OFFSET":
            nodes[stack[-1]][1] = [float(v) for v in words[at + 1:at + 4]]
            at += 4
        elif word == "CHANNELS":
            count = int(words[at + 1])
            nodes[stack[-1]][2] = [(name, column + i) for i, name in enumerate(words[at + 2:at + 2 + count])]
            column += count
            at += 2 + count
        elif word == "}":
            stack.pop()
            at += 1
        else:
            at += 1
    result = []
    for parent, offset, channels in nodes:
        translation = list(offset)
        for name, c in channels:
            if name.endswith("position"):
                translation["XYZ".index(name[0])] = row[c]
        result.append((parent, translation))
    return result


def api_call(server, method, request):
    """One unary call of the HTTP/JSON API (README "HTTP API")."""
    http = urllib.request.Request(server.http_url + "tempokey.v1.MotionService/" + method,
                                  data=json.dumps(request).encode(),
                                  headers={"Content-Type": "application/json"})
    with urllib.request.urlopen(http, timeout=DEADLINE_SECONDS) as answer:
        return json.loads(answer.read())


def job_logged_cancelled(server, job_id):
    """The server's log line of the job, if it ended cancelled (info level logs one per job)."""
    return re.search(r"job id=%s .*outcome=cancelled" % re.escape(job_id), server.server_log())


def close(a, b, rel):
    return abs(a - b) <= rel * max(1.0, abs(a), abs(b))


class StudioBrowserTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        os.makedirs(ARTEFACTS, exist_ok=True)
        cls.work = tempfile.TemporaryDirectory()
        cls.downloads = os.path.join(cls.work.name, "downloads")
        os.makedirs(cls.downloads)
        cls.server = StudioServer().__enter__()
        options = webdriver.ChromeOptions()
        options.binary_location = CHROMIUM
        for flag in ["--headless=new", "--no-sandbox", "--disable-gpu",
                     "--disable-background-networking", "--disable-component-update",
                     "--disable-sync", "--no-first-run", "--window-size=1500,1300",
                     # WebGL on the software rasterizer: headless CI machines have no GPU.
                     "--enable-unsafe-swiftshader",
                     "--user-data-dir=" + os.path.join(cls.work.name, "profile")]:
            options.add_argument(flag)
        cls.driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=options)
        cls.driver.set_page_load_timeout(DEADLINE_SECONDS)
        cls.driver.execute_cdp_cmd("Browser.setDownloadBehavior",
                                   {"behavior": "allow", "downloadPath": cls.downloads})
        cls.driver.get(cls.server.http_url)
        wait_for(lambda: cls.driver.execute_script("return document.body.dataset.ready") == "true",
                 "the page to reach the server")

    @classmethod
    def tearDownClass(cls):
        try:
            logs = cls.driver.get_log("browser")
            with open(os.path.join(ARTEFACTS, "browser-console.txt"), "w") as f:
                for entry in logs:
                    f.write("%s %s\n" % (entry["level"], entry["message"]))
        finally:
            cls.driver.quit()
            cls.server.__exit__(None, None, None)
            busy = getattr(cls, "busy", None)
            if busy:
                for job in cls.blockers:
                    try:
                        api_call(busy, "CancelJob", {"jobId": job})
                    except (OSError, urllib.error.URLError):
                        pass
                busy.__exit__(None, None, None)
            cls.work.cleanup()
        assert cls.server.exit_code == 0, "the server did not drain cleanly:\n" + cls.server.server_log()

    # ---- helpers ---------------------------------------------------------------------------------
    def el(self, element_id):
        return self.driver.find_element(By.ID, element_id)

    def data(self, element_id, name):
        return self.el(element_id).get_attribute("data-" + name)

    def body(self, name):
        return self.driver.execute_script("return document.body.dataset[arguments[0]] || ''", name)

    def settled_plan(self, before):
        """Waits for a plan newer than `before` with none pending; returns its sequence number."""
        def ready():
            seq = int(self.body("planSeq") or 0)
            return seq > before and self.body("planPending") == "false" and seq
        return wait_for(ready, "the server's plan")

    def plan_seq(self):
        return int(self.body("planSeq") or 0)

    def editor_point(self, seconds, speed, duration):
        """Offsets from the editor canvas's centre for (seconds, speed)."""
        canvas = self.el("editor")
        w, h = canvas.size["width"], canvas.size["height"]
        x = EDITOR_PAD_LEFT + seconds / duration * (w - EDITOR_PAD_LEFT - EDITOR_PAD_RIGHT)
        f = (closed_form.math.log(speed) - closed_form.math.log(VIEW_LO)) / (
            closed_form.math.log(VIEW_HI) - closed_form.math.log(VIEW_LO))
        y = h - EDITOR_PAD_BOTTOM - f * (h - EDITOR_PAD_TOP - EDITOR_PAD_BOTTOM)
        return int(round(x - w / 2)), int(round(y - h / 2))

    def wait_for_knots(self, predicate, what):
        """The knots the page shows once `predicate` holds for them and no plan is pending."""
        def ready():
            if self.body("planPending") != "false":
                return None
            knots = self.shown_knots()
            return knots if predicate(knots) else None
        try:
            return wait_for(ready, what)
        except AssertionError:
            self.driver.save_screenshot(os.path.join(ARTEFACTS, "failure-%s.png" % self._testMethodName))
            raise AssertionError("timed out waiting for %s; the page shows %s" % (
                what, self.el("speed-text").get_attribute("value")))

    def shown_knots(self):
        return closed_form.parse_speed_text(self.el("speed-text").get_attribute("value"), self.frame_time)

    def run_cli(self, command, output):
        """Runs the command line the page shows, on the real file, writing `output`."""
        args = shlex.split(command)
        self.assertEqual(args[0], "tempokey")
        args = [CLI, "--server", self.server.grpc_target] + args[1:]
        args[args.index("-o") + 1] = output
        args = [CMU if a == "131_01.bvh" else a for a in args]
        done = subprocess.run(args, capture_output=True, text=True, timeout=DEADLINE_SECONDS)
        self.assertEqual(done.returncode, 0, done.stderr)
        return done.stdout

    def type_over(self, element_id, text, end=Keys.ENTER):
        """Types `text` over a field's value as a person does (select all, type), then `end`.
        Not clear(): that sends a change event of an empty field, which the knot fields refuse."""
        field = self.el(element_id)
        field.click()
        field.send_keys(Keys.CONTROL, "a")
        field.send_keys(Keys.DELETE)
        field.send_keys(text, end)

    def speed_up_first_knot(self):
        """A click on an empty corner of the editor focuses it; Arrow Up raises the selected knot."""
        canvas = self.el("editor")
        (ActionChains(self.driver).move_to_element_with_offset(canvas, canvas.size["width"] // 2 - 30,
                                                               -canvas.size["height"] // 2 + 20)
         .click().send_keys(Keys.ARROW_UP).perform())

    def shown(self, element_id):
        """An element's text if it is shown, else ''."""
        element = self.el(element_id)
        return element.text if element.is_displayed() else ""

    def open_clip(self, path):
        """Opens a file through the picker; waits for its retime and reduction."""
        self.el("file-input").send_keys(path)
        name = os.path.basename(path)
        wait_for(lambda: self.el("clip-info").text.startswith(name + ":"), "the clip " + name)
        for kind in ("retime", "reduce"):
            wait_for(lambda: self.data(kind + "-status", "state") == "done", "the %s of %s" % (kind, name))

    def run_shown_command(self, command, cwd):
        """Runs a command line the page shows as a person pastes it: through /bin/sh, in the
        folder of the file, with `tempokey` on the PATH (the CLI on this test's server)."""
        bin_dir = os.path.join(self.work.name, "bin")
        os.makedirs(bin_dir, exist_ok=True)
        with open(os.path.join(bin_dir, "tempokey"), "w") as f:
            f.write('#!/bin/sh\nexec %s --server %s "$@"\n' % (shlex.quote(CLI), self.server.grpc_target))
        os.chmod(os.path.join(bin_dir, "tempokey"), 0o755)
        env = dict(os.environ, PATH=bin_dir + os.pathsep + os.environ.get("PATH", ""))
        return subprocess.run(["/bin/sh", "-c", command], cwd=cwd, env=env, capture_output=True,
                              text=True, timeout=DEADLINE_SECONDS)

    def studio_jobs(self, server):
        """The jobs stored on `server` that the page submitted (its label source=studio)."""
        return api_call(server, "ListJobs", {"labels": {"source": "studio"}, "pageSize": 1000}).get("jobs", [])

    def screenshot(self, element_id, name):
        element = self.el(element_id)
        self.driver.execute_script("arguments[0].scrollIntoView(true)", element)
        element.screenshot(os.path.join(ARTEFACTS, name))

    # ---- the tests, in order -----------------------------------------------------------------------
    def test_1_opens_a_clip_through_the_file_picker(self):
        self.el("file-input").send_keys(CMU)

        wait_for(lambda: self.data("clip-info", "state") == "loaded", "the clip to load")
        self.settled_plan(0)
        self.assertIn("131_01.bvh: 994 frames at 120 fps", self.el("clip-info").text)
        self.assertEqual(self.el("speed-text").get_attribute("value"), "0s:1")
        type(self).frame_time = 0.0083333
        type(self).source_duration = 993 * 0.0083333
        self.assertTrue(close(float(self.data("duration", "seconds")), self.source_duration, 1e-12))

    def test_2_speed_curve_built_with_mouse_and_keys_lasts_the_closed_form(self):
        duration = self.source_duration
        canvas = self.el("editor")
        # Mouse: Ctrl+click adds a knot (snapped to 0.01 s and 0.01x), as a double-click does. A
        # double-click is not used here: chromedriver counts it as one only if its second press
        # comes within the double-click time, which a loaded machine can miss.
        for count, (seconds, speed) in enumerate([(2.0, 1.0), (2.5, 0.25), (3.5, 0.25), (4.0, 1.0)], start=2):
            dx, dy = self.editor_point(seconds, speed, duration)
            (ActionChains(self.driver).move_to_element_with_offset(canvas, dx, dy).key_down(Keys.CONTROL)
             .click().key_up(Keys.CONTROL).perform())
            self.wait_for_knots(lambda knots: len(knots) == count, "knot %d" % count)
        # Drag the knot near (3.5 s, 0.25x) to about (3.6 s, 0.3x).
        before = self.plan_seq()
        x0, y0 = self.editor_point(self.shown_knots()[3][0], self.shown_knots()[3][1], duration)
        x1, y1 = self.editor_point(3.6, 0.3, duration)
        (ActionChains(self.driver).move_to_element_with_offset(canvas, x0, y0).click_and_hold()
         .move_by_offset((x1 - x0) // 2, (y1 - y0) // 2).move_by_offset(x1 - x0 - (x1 - x0) // 2, y1 - y0 - (y1 - y0) // 2)
         .release().perform())
        dragged = self.wait_for_knots(lambda knots: abs(knots[3][0] - 3.6) < 0.03, "the dragged knot")[3]
        # Keyboard: two steps up, then S doubles the knot into a step whose second half goes up 0.3.
        ActionChains(self.driver).send_keys(Keys.ARROW_UP, Keys.ARROW_UP, "s").perform()
        ActionChains(self.driver).key_down(Keys.SHIFT).send_keys(Keys.ARROW_UP * 3).key_up(Keys.SHIFT).perform()
        knots = self.wait_for_knots(lambda knots: len(knots) == 6 and knots[4][1] > knots[3][1] + 0.25,
                                    "the step")
        self.assertEqual(knots[3][0], knots[4][0], "a step is two knots at one time")
        self.assertAlmostEqual(knots[3][1], round(dragged[1] + 0.02, 2), places=12)
        self.assertAlmostEqual(knots[4][1], round(dragged[1] + 0.02, 2) + 0.3, places=9)
        # Numeric entry: select the last knot (Tab) and type its time and speed.
        ActionChains(self.driver).send_keys(Keys.TAB).perform()
        last = self.shown_knots()[-1][0]
        wait_for(lambda: float(self.el("knot-time").get_attribute("value")) == last, "the last knot selected")
        for element_id, value in [("knot-time", "5"), ("knot-speed", "1.5")]:
            self.type_over(element_id, value, Keys.TAB)
        knots = self.wait_for_knots(lambda knots: knots[-1] == (5.0, 1.5), "the typed knot")
        # A hold, from its fields.
        before = self.plan_seq()
        for element_id, value in [("hold-at", "1"), ("hold-duration", "0.5")]:
            field = self.el(element_id)
            field.clear()
            field.send_keys(value)
        self.el("add-hold").click()
        wait_for(lambda: "--hold 1s:0.5" in self.el("retime-command").text, "the hold")
        self.settled_plan(before)

        # Fit to grid (default): whole output frames, the frame count of the closed form.
        c, frames = closed_form.grid_fit(knots, duration, self.frame_time, hold_seconds=0.5)
        self.assertEqual(int(self.el("frame-count").text), frames)
        self.assertTrue(close(float(self.data("duration", "seconds")), (frames - 1) * self.frame_time, 1e-12))
        self.assertTrue(close(float(self.el("fit-factor").text), c, 1e-6))
        # Without it: exactly the closed form, sum of h / logmean(v0, v1) plus the hold.
        before = self.plan_seq()
        self.el("fit-to-grid").click()
        self.settled_plan(before)
        expected = closed_form.output_duration(knots, duration) + 0.5
        shown = float(self.data("duration", "seconds"))
        self.assertTrue(close(shown, expected, CLOSED_FORM_REL), (shown, expected))
        self.assertEqual(self.el("duration").text, "%.6f s" % expected)
        before = self.plan_seq()
        self.el("fit-to-grid").click()
        self.settled_plan(before)
        type(self).knots = knots
        type(self).grid = (c, frames)
        self.screenshot("retime", "studio-editor.png")

    def test_3_preview_plays_and_shows_the_frames_the_cli_writes(self):
        command = self.el("retime-command").text
        wait_for(lambda: self.data("retime-status", "state") == "done"
                 and self.data("retime-status", "command") == command, "the retimed result")
        cli_bvh = os.path.join(self.work.name, "cli-retimed.bvh")
        self.run_cli(command, cli_bvh)
        frame_time, rows = read_bvh(cli_bvh)
        c, frames = self.grid
        self.assertEqual(len(rows), frames)

        self.el("play").click()
        wait_for(lambda: int(self.data("preview", "output-frame") or 0) >= 60, "playback to pass frame 60")
        self.el("play").click()
        wait_for(lambda: self.data("preview", "playing") == "false", "playback to pause")
        self.el("step-forward").click()
        j = int(self.data("preview", "output-frame"))
        self.assertGreater(j, 60)

        shown = [float(v) for v in self.data("preview", "result-root").split(",")]
        expected = rows[j][:3]  # the root's position channels, replacing its OFFSET
        for a, b in zip(shown, expected):
            self.assertTrue(close(a, b, FLOAT32_REL), (j, shown, expected))
        tau = float(self.data("preview", "source-seconds"))
        expected_tau = closed_form.source_time(self.knots, self.source_duration, j * frame_time, c,
                                               hold=(1.0, 0.5))
        self.assertTrue(abs(tau - expected_tau) <= 1e-9, (j, tau, expected_tau))
        self.assertIn("output frame %d / %d" % (j, frames - 1), self.el("frame-readout").text)
        self.screenshot("preview-section", "studio-preview.png")

    def test_4_reduction_keeps_as_many_keys_as_the_cli(self):
        field = self.el("tolerance")
        field.clear()
        field.send_keys("0.3", Keys.TAB)
        wait_for(lambda: self.data("reduce-status", "state") == "done"
                 and "--tolerance 0.3 " in self.data("reduce-status", "command") + " ", "the reduction")
        Select(self.el("joint")).select_by_visible_text("RightHip")
        Select(self.el("channel")).select_by_visible_text("Xrotation")
        shown = int(self.el("key-count").text)

        out = self.run_cli(self.data("reduce-status", "command"), os.path.join(self.work.name, "cli.anim"))

        keys = int(re.search(r"keys:\s+(\d+) of", out).group(1))
        self.assertEqual(shown, keys)
        self.assertIn("RightHip.Xrotation", self.el("reduce-report").text)
        # Zoom the time axis (wheel) so keys, handles and the ±0.3° band are apart in the picture.
        for _ in range(2):
            ActionChains(self.driver).scroll_from_origin(ScrollOrigin.from_element(self.el("curves")), 0, -600).perform()
        self.screenshot("reduce", "studio-reduction.png")

    def test_5_downloads_are_the_bytes_the_cli_writes(self):
        retime_command = self.data("retime-status", "command")
        reduce_command = self.data("reduce-status", "command")
        cases = [("download-retime-bvh", "131_01-retimed.bvh", retime_command),
                 ("download-retime-csv", "131_01-retimed.csv", retime_command),
                 ("download-reduce-json", "131_01-keys.json", reduce_command),
                 ("download-reduce-anim", "131_01-keys.anim", reduce_command),
                 ("download-reduce-bvh", "131_01-keys.bvh", reduce_command),
                 ("download-reduce-csv", "131_01-keys.csv", reduce_command),
                 ("download-retime-gltf", "131_01-retimed.gltf", retime_command),
                 ("download-reduce-glb", "131_01-keys.glb", reduce_command)]
        for button, name, command in cases:
            with self.subTest(file=name):
                self.el(button).click()
                path = os.path.join(self.downloads, name)
                wait_for(lambda: os.path.exists(path) and not os.path.exists(path + ".crdownload"),
                         "the download of " + name)
                cli_file = os.path.join(self.work.name, "cli-" + name)
                self.run_cli(command, cli_file)
                with open(path, "rb") as a, open(cli_file, "rb") as b:
                    downloaded, written = a.read(), b.read()
                self.assertGreater(len(written), 1000)
                self.assertEqual(downloaded, written)
        # Equal to the CLI's is not yet right: the glTF downloads also pass Khronos's validator.
        gltf_files = [os.path.join(self.downloads, name) for name in ("131_01-retimed.gltf", "131_01-keys.glb")]
        done = subprocess.run(["node", GLTF_VALIDATE] + gltf_files, capture_output=True, text=True,
                              cwd=os.path.dirname(GLTF_VALIDATE), timeout=DEADLINE_SECONDS)
        self.assertEqual(done.returncode, 0, done.stderr)
        reports = [json.loads(line) for line in done.stdout.splitlines()]
        self.assertEqual(len(reports), 2)
        for report in reports:
            self.assertEqual((report["errors"], report["warnings"]), (0, 0), report)


    def test_5b_speed_over_output_time_means_what_the_cli_means(self):
        source_text = self.el("speed-text").get_attribute("value")
        before = self.plan_seq()

        Select(self.el("domain")).select_by_value("output")

        self.settled_plan(before)
        wait_for(lambda: "--speed-over output" in self.el("retime-command").text, "the output-domain command")
        command = self.el("retime-command").text
        self.assertNotEqual(self.el("speed-text").get_attribute("value"), source_text)
        wait_for(lambda: self.data("retime-status", "state") == "done"
                 and self.data("retime-status", "command") == command, "the output-domain result")
        out = self.run_cli(command, os.path.join(self.work.name, "cli-output-domain.bvh"))
        frames = int(re.search(r"output frames:\s+(\d+)", out).group(1))
        self.assertEqual(int(self.el("frame-count").text), frames)
        _, rows = read_bvh(os.path.join(self.work.name, "cli-output-domain.bvh"))
        self.assertEqual(len(rows), frames)

    def test_5c_joint_and_noise_methods_keep_the_clis_keys_and_show_world_error(self):
        # Per-joint bound in percent of the figure's height, then the noise-aware method: the page
        # sends each to the server and shows the command; the CLI run of that command must keep
        # exactly as many keys, and the report shows the world-space error of the joints.
        Select(self.el("reduce-method")).select_by_visible_text("joint")
        self.assertTrue(self.el("joint-tolerance").is_displayed())
        self.assertFalse(self.el("tolerance").is_displayed())
        field = self.el("joint-tolerance")
        field.clear()
        field.send_keys("1", Keys.TAB)
        for flag in ("--joint-tolerance 1%", "--method noise"):
            with self.subTest(flag=flag):
                if flag == "--method noise":
                    Select(self.el("reduce-method")).select_by_visible_text("noise")
                wait_for(lambda: self.data("reduce-status", "state") == "done"
                         and flag in self.data("reduce-status", "command"), "the reduction " + flag)
                shown = int(self.el("key-count").text)
                out = self.run_cli(self.data("reduce-status", "command"),
                                   os.path.join(self.work.name, "cli-method.anim"))
                keys = int(re.search(r"keys:\s+(\d+) of", out).group(1))
                self.assertEqual(shown, keys)
                report = self.el("reduce-report").text
                self.assertIn("joints (world space)", report)
                self.assertIn("worstPoint", report)
        self.screenshot("reduce", "studio-reduction-noise.png")
        Select(self.el("reduce-method")).select_by_visible_text("tolerance")
        wait_for(lambda: self.data("reduce-status", "state") == "done"
                 and "--tolerance " in self.data("reduce-status", "command"), "the tolerance reduction")

    def test_6_malformed_file_shows_the_located_message_and_breaks_nothing(self):
        with open(CMU) as f:
            lines = f.read().split("\n")
        lines[4] = lines[4].replace("Yposition", "Ypozition")
        broken = os.path.join(self.work.name, "broken.bvh")
        with open(broken, "w") as f:
            f.write("\n".join(lines))
        cli = subprocess.run([CLI, "info", "broken.bvh"], cwd=self.work.name, capture_output=True,
                             text=True, timeout=DEADLINE_SECONDS)
        self.assertEqual(cli.returncode, 1)
        clip_id = self.data("clip-info", "clip-id")

        self.el("file-input").send_keys(broken)

        message = wait_for(lambda: self.el("message").text, "the error message")
        self.assertEqual("error: " + message, cli.stderr.strip())
        self.assertTrue(message.startswith("broken.bvh:5:"), message)
        self.assertEqual(self.data("clip-info", "clip-id"), clip_id)
        self.assertIn("131_01.bvh", self.el("clip-info").text)
        before = self.plan_seq()
        self.el("editor").send_keys(Keys.ARROW_DOWN)
        self.settled_plan(before)
        self.driver.save_screenshot(os.path.join(ARTEFACTS, "studio-page.png"))

    def test_7_a_dropped_csv_opens_at_the_rate_given(self):
        _, rows = read_bvh(CMU)
        text = "Hips.Xposition,Hips.Yposition,Hips.Zrotation\n" + "".join(
            "%r,%r,%r\n" % (row[0], row[1], row[3]) for row in rows[:120])
        field = self.el("csv-fps")
        field.clear()
        field.send_keys("24")

        # A drop as the browser delivers it: a DragEvent carrying the file.
        self.driver.execute_script(
            "const transfer = new DataTransfer();"
            "transfer.items.add(new File([arguments[0]], 'walk.csv', {type: 'text/csv'}));"
            "window.dispatchEvent(new DragEvent('drop', {dataTransfer: transfer, bubbles: true, cancelable: true}));",
            text)

        wait_for(lambda: "walk.csv" in self.el("clip-info").text, "the dropped clip")
        self.assertIn("walk.csv: 120 frames at 24 fps", self.el("clip-info").text)
        self.assertEqual([o.text for o in Select(self.el("joint")).options], ["Hips"])
        self.assertEqual([o.text for o in Select(self.el("channel")).options],
                         ["Xposition", "Yposition", "Zrotation"])
        wait_for(lambda: close(float(self.data("duration", "seconds")), 119 / 24, 1e-12),
                 "the plan of the dropped clip: 119 frame times at 24 fps")

    def test_8a_typed_speed_text_is_held_to_the_editors_limits_and_order(self):
        good = "0s:1,2s:0.5"
        self.type_over("speed-text", good)
        self.wait_for_knots(lambda knots: knots == [(0.0, 1.0), (2.0, 0.5)], "the typed curve")
        # The server's parser takes each of these but the last; the editor could never make them.
        previous = ""
        for text, knot in [("0s:1,2s:0", 2), ("0s:1,2s:-1", 2), ("0s:1,2s:1e300", 2), ("0s:1e-9", 1),
                           ("0s:1,2s:0.5,1s:1", 3), ("0s:1,2x", 2)]:
            with self.subTest(text=text):
                self.type_over("speed-text", text)
                error = wait_for(lambda: self.shown("speed-text-error") not in ("", previous)
                                 and self.shown("speed-text-error"), "the error of " + text)
                self.assertIn("knot %d" % knot, error)
                previous = error
                # The banner shows the same, current error.
                self.assertEqual(self.shown("message"), "--speed: " + error)
        # The knots stayed the good ones; typing their own text again applies (and clears the error).
        self.type_over("speed-text", good)
        wait_for(lambda: not self.shown("speed-text-error") and not self.shown("message"), "the error cleared")
        self.el("editor").send_keys(Keys.ARROW_UP)
        self.wait_for_knots(lambda knots: knots == [(0.0, 1.01), (2.0, 0.5)], "an edit of the good curve")

    def expect_knot_refused(self, field, value, said, time, speed):
        """Types `value` into `field`: the second knot's message says `said`, and both fields
        show the knot as it was (`time`, `speed`)."""
        self.type_over(field, value, Keys.TAB)
        wait_for(lambda: said in self.shown("knot-error"), "the message about " + said)
        self.assertIn("knot 2", self.shown("knot-error"))
        self.assertEqual(self.el("knot-time").get_attribute("value"), time)
        self.assertEqual(self.el("knot-speed").get_attribute("value"), speed)

    def test_8b_knot_fields_refuse_what_the_editor_cannot_take(self):
        self.type_over("speed-text", "0s:1,2s:0.5")
        self.wait_for_knots(lambda knots: knots == [(0.0, 1.0), (2.0, 0.5)], "the typed curve")
        self.el("editor").send_keys(Keys.TAB)
        wait_for(lambda: self.el("knot-time").get_attribute("value") == "2", "the second knot selected")
        for field, value, said in [("knot-speed", "0", 'speed "0"'), ("knot-speed", "-1", 'speed "-1"'),
                                   ("knot-speed", "", "speed a blank"), ("knot-time", "", "time a blank"),
                                   ("knot-time", "-1", 'time "-1"'),
                                   # Text that is no number reads as '' from a number field, as
                                   # a blank does: it is named for what it is, not "a blank".
                                   ("knot-time", "1e", "time: what is typed is not a number"),
                                   ("knot-speed", "--1", "speed: what is typed is not a number")]:
            with self.subTest(field=field, value=value):
                self.expect_knot_refused(field, value, said, "2", "0.5")
        self.type_over("knot-speed", "0.75", Keys.TAB)
        self.wait_for_knots(lambda knots: knots == [(0.0, 1.0), (2.0, 0.75)], "the typed speed")
        self.assertEqual(self.shown("knot-error"), "")
        # Numbers the editor could hold but not there: refused in the --speed text's words, never
        # clamped silently to the limit or the timeline's end (walk.csv lasts 119/24 s).
        for field, value, said in [("knot-speed", "500", "speed 500 is outside the limits [0.01, 100]"),
                                   ("knot-time", "10", "time 10s is after the end of the timeline")]:
            with self.subTest(field=field, value=value):
                self.expect_knot_refused(field, value, said, "2", "0.75")
        # Nor past a neighbour: the first knot cannot go after the second.
        self.el("editor").send_keys(Keys.TAB)
        wait_for(lambda: self.el("knot-time").get_attribute("value") == "0", "the first knot selected")
        self.type_over("knot-time", "3", Keys.TAB)
        wait_for(lambda: "time 3s is after the next knot's" in self.shown("knot-error"), "the neighbour's message")
        self.assertIn("knot 1", self.shown("knot-error"))
        self.assertEqual(self.el("knot-time").get_attribute("value"), "0")
        self.wait_for_knots(lambda knots: knots == [(0.0, 1.0), (2.0, 0.75)], "the knots as they were")
        # A knot in frames takes the whole frames typed, as typed (walk.csv is at 24 fps: 25 frame
        # times divided by the frame time is 25.000000000000004). The first knot stays selected.
        before = self.plan_seq()
        self.type_over("speed-text", "0s:1,50f:0.5")
        self.settled_plan(before)
        self.assertEqual(self.el("speed-text").get_attribute("value"), "0s:1,50f:0.5")
        self.el("editor").send_keys(Keys.TAB)
        wait_for(lambda: self.el("knot-time").get_attribute("value") == "50", "the knot in frames selected")
        self.assertEqual(self.el("knot-unit").text, "f")

        self.type_over("knot-time", "25", Keys.TAB)

        wait_for(lambda: self.el("speed-text").get_attribute("value") != "0s:1,50f:0.5"
                 and self.body("planPending") == "false", "the typed frame")
        self.assertEqual(self.el("speed-text").get_attribute("value"), "0s:1,25f:0.5")
        self.assertEqual(self.el("knot-time").get_attribute("value"), "25")

    def test_8c_speed_limits_never_rewrite_the_knots(self):
        self.type_over("speed-text", "0s:1,2s:0.5")
        self.wait_for_knots(lambda knots: knots == [(0.0, 1.0), (2.0, 0.5)], "the typed curve")
        # A minimum above a knot: the server names the knot; the knot stays.
        self.type_over("min-speed", "0.6", Keys.TAB)
        wait_for(lambda: "speed knot 2" in self.shown("message"), "the knot beyond the limits named")
        # An empty range is refused by the page, the knots kept.
        self.type_over("min-speed", "10", Keys.TAB)
        self.type_over("max-speed", "1", Keys.TAB)
        wait_for(lambda: "empty" in self.shown("message"), "the empty range refused")
        self.type_over("max-speed", "100", Keys.TAB)
        before = self.plan_seq()
        self.type_over("min-speed", "0.01", Keys.TAB)
        self.settled_plan(before)
        self.assertEqual(self.el("speed-text").get_attribute("value"), "0s:1,2s:0.5")
        self.assertEqual(self.shown("message"), "")

    def test_8d_a_refused_reduction_says_so(self):
        self.type_over("tolerance", "0", Keys.TAB)
        wait_for(lambda: self.data("reduce-status", "state") == "failed", "the refused reduction")
        status = self.el("reduce-status").text
        self.assertTrue(status.startswith("failed: INVALID_ARGUMENT"), status)
        self.assertIn("max_rotation_error_degrees must be > 0", status)
        self.type_over("tolerance", "0.5", Keys.TAB)
        wait_for(lambda: self.data("reduce-status", "state") == "done", "the reduction again")

    def test_8e_command_lines_quote_the_file_name_for_the_shell(self):
        folder = os.path.join(self.work.name, "hostile")
        os.makedirs(folder)
        # A name the shell would run, one the command would read as a flag (it gets ./ before
        # it), and one zsh would expand (=cmd: quoted).
        for name, word in [("walk; touch PWNED #it's.bvh", "'walk; touch PWNED #it'\\''s.bvh'"),
                           ("-walk.bvh", "./-walk.bvh"), ("=walk.bvh", "'=walk.bvh'")]:
            stem = name[:-len(".bvh")]
            shutil.copy(CMU, os.path.join(folder, name))
            self.open_clip(os.path.join(folder, name))
            for status, output in (("retime-status", stem + "-retimed.bvh"), ("reduce-status", stem + "-keys.anim")):
                with self.subTest(name=name, command=status):
                    command = self.data(status, "command")
                    self.assertEqual(command.split(" -o ")[0].split(" ", 2)[2], word, command)
                    args = shlex.split(command)
                    self.assertEqual(os.path.normpath(args[2]), name)
                    self.assertEqual(os.path.normpath(args[4]), output)
                    done = self.run_shown_command(command, folder)
                    self.assertEqual(done.returncode, 0, done.stderr)
                    self.assertFalse(os.path.exists(os.path.join(folder, "PWNED")), command)
                    self.assertTrue(os.path.exists(os.path.join(folder, output)), command)

    def test_8f_a_clip_without_a_skeleton_retimes_and_downloads_as_csv(self):
        self.assertTrue(self.el("download-retime-bvh").is_displayed())
        folder = os.path.join(self.work.name, "plain")
        os.makedirs(folder)
        noise = random.Random(7)
        with open(os.path.join(folder, "sensor.csv"), "w") as f:
            f.write("pressure,flow\n" + "".join("%.3f,%.3f\n" % (noise.gauss(0, 1), i * 0.1) for i in range(240)))
        self.type_over("csv-fps", "60", Keys.TAB)

        self.open_clip(os.path.join(folder, "sensor.csv"))

        self.assertIn("sensor.csv: 240 frames at 60 fps", self.el("clip-info").text)
        self.assertTrue(self.el("preview-note").is_displayed())
        self.assertIsNone(self.data("preview", "source-root"), "the previous clip's figure is gone")
        self.assertEqual(self.shown("message"), "")
        buttons = lambda row: [b.get_attribute("id") for b in self.el(row).find_elements(By.TAG_NAME, "button")]
        self.assertEqual(buttons("downloads-retime"), ["download-retime-csv"])
        self.assertEqual(sorted(buttons("downloads-reduce")),
                         ["download-reduce-anim", "download-reduce-csv", "download-reduce-json"])
        # The download is what the command line the page shows writes.
        self.el("download-retime-csv").click()
        path = os.path.join(self.downloads, "sensor-retimed.csv")
        wait_for(lambda: os.path.exists(path) and not os.path.exists(path + ".crdownload"), "the CSV download")
        command = self.data("retime-status", "command")
        self.assertIn("--input-fps 60", command)
        done = self.run_shown_command(command, folder)
        self.assertEqual(done.returncode, 0, done.stderr)
        with open(path, "rb") as a, open(os.path.join(folder, "sensor-retimed.csv"), "rb") as b:
            self.assertEqual(a.read(), b.read())
        # The reduction's command writes keys (.anim needs no skeleton), the bytes of the download.
        self.el("download-reduce-anim").click()
        path = os.path.join(self.downloads, "sensor-keys.anim")
        wait_for(lambda: os.path.exists(path) and not os.path.exists(path + ".crdownload"), "the .anim download")
        command = self.data("reduce-status", "command")
        self.assertEqual(shlex.split(command)[3:5], ["-o", "sensor-keys.anim"], command)
        done = self.run_shown_command(command, folder)
        self.assertEqual(done.returncode, 0, done.stderr)
        with open(path, "rb") as a, open(os.path.join(folder, "sensor-keys.anim"), "rb") as b:
            self.assertEqual(a.read(), b.read())

    def test_8g_the_page_keeps_only_the_jobs_it_shows(self):
        # Every clip opened so far and every edit made its jobs; the page keeps the current clip's
        # retime and reduction and has deleted the rest.
        for _ in range(6):
            self.el("editor").send_keys(Keys.ARROW_UP)
        wait_for(lambda: self.data("retime-status", "state") == "done"
                 and self.data("retime-status", "speed-text") == self.el("speed-text").get_attribute("value")
                 and self.body("planPending") == "false", "the last edit's result")
        kept = {self.data("retime-status", "job-id"), self.data("reduce-status", "job-id")}
        wait_for(lambda: {j["jobId"] for j in self.studio_jobs(self.server)} == kept,
                 "the server to hold only the page's two jobs (it holds %s)" % len(self.studio_jobs(self.server)))

    def test_8h_the_knots_own_text_clears_its_error_everywhere(self):
        good = self.el("speed-text").get_attribute("value")
        self.type_over("speed-text", "0s:1,2s:0")
        wait_for(lambda: "knot 2" in self.shown("speed-text-error"), "the error of the typed text")
        self.assertTrue(self.shown("message").startswith("--speed: "))
        before = self.plan_seq()

        # Another setting: the plan's answer puts the knots' own text back in the field.
        Select(self.el("filter")).select_by_visible_text("linear")

        self.settled_plan(before)
        self.assertEqual(self.el("speed-text").get_attribute("value"), good)
        self.assertEqual(self.shown("speed-text-error"), "")
        self.assertNotIn("invalid", self.el("speed-text").get_attribute("class"))
        self.assertEqual(self.shown("message"), "")
        before = self.plan_seq()
        Select(self.el("filter")).select_by_visible_text("tent")
        self.settled_plan(before)

    def hold_fetches(self, method, body_has):
        """Holds the page's calls of `method` whose request contains `body_has` until
        window.__held.open() (a gate in front of fetch, so a run is caught half-way however fast
        the server is); window.__held counts the calls waiting and answered."""
        self.driver.execute_script("""
            const [method, bodyHas] = arguments;
            const real = window.__realFetch || window.fetch;
            window.__realFetch = real;
            let open;
            const opened = new Promise((resolve) => (open = resolve));
            const held = window.__held = {waiting: 0, answered: 0, open};
            window.fetch = async (url, init) => {
              if (!String(url).endsWith('/' + method) || !String(init && init.body).includes(bodyHas)) {
                return real(url, init);
              }
              held.waiting += 1;
              await opened;
              try {
                return await real(url, init);
              } finally {
                held.answered += 1;
              }
            };""", method, body_has)

    def release_fetches(self):
        self.driver.execute_script("window.__held.open(); window.fetch = window.__realFetch;")

    def held(self, name):
        return self.driver.execute_script("return window.__held[arguments[0]]", name)

    def test_8i_a_retime_ending_after_its_settings_were_refused_changes_nothing(self):
        wait_for(lambda: self.data("retime-status", "state") == "done" and self.body("planPending") == "false",
                 "the current result")
        kept = {self.data("retime-status", "job-id"), self.data("reduce-status", "job-id")}
        wait_for(lambda: {j["jobId"] for j in self.studio_jobs(self.server)} == kept, "only the page's two jobs")
        self.hold_fetches("SubmitJob", '"retime"')
        self.type_over("speed-text", "0s:0.05")
        wait_for(lambda: self.held("waiting") == 1, "the retime of 0s:0.05 submitting its job")
        self.assertEqual(self.data("retime-status", "state"), "running")

        # A minimum above the knot: the server refuses the plan while the retime runs.
        self.type_over("min-speed", "0.1", Keys.TAB)
        wait_for(lambda: "speed knot 1" in self.shown("message"), "the refusal")
        refusal = self.shown("message")
        # The run goes on: its job is made. Then either the page shows it (the bug) or gives the
        # job back, the server holding the two jobs of before.
        self.release_fetches()
        wait_for(lambda: self.held("answered") == 1, "the held SubmitJob answered")
        wait_for(lambda: self.data("retime-status", "state") == "done"
                 or {j["jobId"] for j in self.studio_jobs(self.server)} == kept, "the run's end")

        self.assertNotEqual(self.data("retime-status", "state"), "done")
        self.assertEqual(self.shown("message"), refusal)
        before = self.plan_seq()
        self.type_over("min-speed", "0.01", Keys.TAB)
        self.settled_plan(before)
        self.assertEqual(self.shown("message"), "")
        wait_for(lambda: self.data("retime-status", "state") == "done"
                 and self.data("retime-status", "speed-text") == "0s:0.05", "the retime of 0s:0.05")

    def test_8j_back_from_the_back_forward_cache_the_preview_works_again(self):
        self.open_clip(CMU)
        wait_for(lambda: self.data("preview", "result-root"), "the preview of the result")
        job = self.data("retime-status", "job-id")
        self.driver.execute_script("window.__sameDocument = true")

        self.driver.get(self.server.http_url + "js/api.js")
        self.driver.back()

        # The same document, frozen and restored (not a new load of the page).
        wait_for(lambda: self.driver.execute_script("return window.__sameDocument === true"),
                 "the page restored from the back/forward cache")
        wait_for(lambda: self.data("retime-status", "job-id") not in (None, job)
                 and self.data("retime-status", "state") == "done", "the retime run again")
        wait_for(lambda: self.data("reduce-status", "state") == "done", "the reduction run again")
        self.assertTrue(self.data("preview", "source-root"), "the source figure")
        self.assertTrue(self.data("preview", "result-root"), "the result figure")
        frames = int(self.el("frame-count").text)
        self.assertEqual(self.el("scrub").get_attribute("max"), str(frames - 1))
        self.el("step-forward").click()
        wait_for(lambda: self.data("preview", "output-frame") == "1", "a step of the preview")
        kept = {self.data("retime-status", "job-id"), self.data("reduce-status", "job-id")}
        wait_for(lambda: {j["jobId"] for j in self.studio_jobs(self.server)} == kept,
                 "the server to hold only the page's two jobs (it holds %s)" % len(self.studio_jobs(self.server)))

    def test_8k_a_result_the_preview_cannot_read_is_a_failure_shown(self):
        # The retimed BVH arrives as text BVHLoader cannot read (the server's own files never are;
        # the page's fetch answers for it here).
        self.driver.execute_script(r"""
            const real = window.__realFetch = window.fetch;
            window.fetch = async (url, init) => {
              const body = String(init && init.body);
              if (!String(url).endsWith('/ExportFile') || !body.includes('"jobId"')) return real(url, init);
              const answer = await real(url, init);
              await answer.text();
              const part = {fileName: 'x.bvh', mediaType: 'text/plain', data: btoa('HIERARCHY\nnot a skeleton\n')};
              return new Response(JSON.stringify({result: part}) + '\n', {status: 200});
            };""")
        try:
            self.el("editor").send_keys(Keys.ARROW_UP)
            wait_for(lambda: self.data("retime-status", "state") == "failed", "the failure shown")
        finally:
            self.driver.execute_script("window.fetch = window.__realFetch")
        self.assertIn("the preview cannot show the result", self.el("retime-status").text)
        self.assertIn("the preview cannot show the result", self.shown("message"))
        self.el("editor").send_keys(Keys.ARROW_DOWN)
        wait_for(lambda: self.data("retime-status", "state") == "done", "a result shown again")
        self.assertEqual(self.shown("message"), "")

    def test_8l_a_figure_whose_joints_have_position_channels_keeps_its_bone_lengths(self):
        # three.js's BVHLoader adds a joint's OFFSET to its position channels; the Bandai captures
        # hold each joint's offset in six channels, so their figures were drawn with every bone
        # twice as long. Each bone of both figures must be as long as the joint's translation
        # (whatever its rotations, a joint sits that far from its parent).
        bandai = sorted(n for n in os.listdir(os.path.join(SHARED_DIR, "data", "bvh", "bandai"))
                        if n.endswith(".bvh"))[0]
        path = os.path.join(SHARED_DIR, "data", "bvh", "bandai", bandai)
        self.open_clip(path)
        self.assertEqual(self.data("preview", "output-frame"), "0")
        nodes = bvh_local_translations(path, 0)
        for figure in ("source-points", "result-points"):
            points = [[float(v) for v in p.split(",")] for p in self.data("preview", figure).split(";")]
            self.assertEqual(len(points), len(nodes), figure)
            for i, (parent, translation) in enumerate(nodes):
                if parent < 0:
                    continue
                length = sum(t * t for t in translation) ** 0.5
                shown = sum((a - b) ** 2 for a, b in zip(points[i], points[parent])) ** 0.5
                self.assertLessEqual(abs(shown - length), 1e-3 * max(1.0, length), (figure, i, shown, length))
        self.screenshot("preview-section", "studio-preview-bandai.png")

    def test_8m_a_clip_of_several_root_joints_is_shown(self):
        # tempokey writes one ROOT per root joint (a CSV's joints all come back as roots); three.js's
        # BVHLoader reads one ROOT ("MOTION expected"), so the page showed "no keyframes in track
        # named .bones[Hips].position" and no figure. The roots now hang under one added root
        # without channels: its point first, then the file's joints and end sites in order, each
        # position channel replacing its axis of the OFFSET. Joint names the page's own reading
        # of the text must not mistake for keywords: "ENDSITE" (BVHLoader's end sites' name) and
        # "MOTION".
        path = os.path.join(self.work.name, "roots.bvh")
        with open(path, "w") as f:
            f.write("HIERARCHY\nROOT A\n{\n  OFFSET 1 2 3\n  CHANNELS 2 Xposition Zrotation\n"
                    "  JOINT ENDSITE\n  {\n    OFFSET 0 4 0\n    CHANNELS 1 Zrotation\n"
                    "    End Site\n    {\n      OFFSET 0 1 0\n    }\n  }\n}\n"
                    "ROOT MOTION\n{\n  OFFSET 10 0 0\n  CHANNELS 3 Xposition Yposition Zposition\n"
                    "  End Site\n  {\n    OFFSET 0 2 0\n  }\n}\n"
                    "MOTION\nFrames: 3\nFrame Time: 0.0333333\n"
                    "5 0 0 7 8 9\n5 10 20 7 8 9\n5 20 40 7 8 9\n")
        self.open_clip(path)

        self.assertEqual(self.data("retime-status", "state"), "done", self.el("retime-status").text)
        self.assertEqual(self.shown("message"), "")
        self.assertEqual(self.data("preview", "output-frame"), "0")
        expected = [[0, 0, 0], [5, 2, 3], [5, 6, 3], [5, 7, 3], [7, 8, 9], [7, 10, 9]]
        for figure in ("source-points", "result-points"):
            points = [[float(v) for v in p.split(",")] for p in self.data("preview", figure).split(";")]
            self.assertEqual(len(points), len(expected), figure)
            shift = points[0]  # the result's figure stands beside the source's
            for got, want in zip(points, expected):
                for a, b, s0 in zip(got, want, shift):
                    self.assertLessEqual(abs(a - s0 - b), 1e-4, (figure, points))

    def test_8n_undo_and_redo_step_through_the_knot_edits(self):
        # Runs on the clip 8m opened (its one knot, 0s:1). Each edit waits for the server's plan,
        # whose answer writes the knots' text.
        wait_for(lambda: self.body("planPending") == "false", "no plan pending")
        start = self.el("speed-text").get_attribute("value")
        seconds = float(re.search(r"([0-9.]+) s,", self.el("clip-info").text).group(1))
        canvas = self.el("editor")

        def chain():
            return ActionChains(self.driver)

        def text_after(actions):
            before = self.plan_seq()
            actions.perform()
            self.settled_plan(before)
            return self.el("speed-text").get_attribute("value")

        def undo():
            return chain().key_down(Keys.CONTROL).send_keys("z").key_up(Keys.CONTROL)

        def redo_shift():
            return (chain().key_down(Keys.CONTROL).key_down(Keys.SHIFT).send_keys("z")
                    .key_up(Keys.SHIFT).key_up(Keys.CONTROL))

        def redo_y():
            return chain().key_down(Keys.CONTROL).send_keys("y").key_up(Keys.CONTROL)

        # Three edits: a drag of the knot in three moves, a step (S), Arrow Up.
        x0, y0 = self.editor_point(0, 1, seconds)
        _, y1 = self.editor_point(0, 2, seconds)
        third = (y1 - y0) // 3
        dragged = text_after(chain().move_to_element_with_offset(canvas, x0, y0).click_and_hold()
                             .move_by_offset(0, third).move_by_offset(0, third)
                             .move_by_offset(0, y1 - y0 - 2 * third).release())
        stepped = text_after(chain().send_keys("s"))
        raised = text_after(chain().send_keys(Keys.ARROW_UP))
        self.assertEqual(len({start, dragged, stepped, raised}), 4, (start, dragged, stepped, raised))

        self.assertEqual(text_after(undo()), stepped)
        self.assertEqual(text_after(undo()), dragged)
        self.assertEqual(text_after(undo()), start)  # the whole drag at once
        undo().perform()  # nothing left to undo: changes nothing
        self.assertEqual(text_after(redo_shift()), dragged)
        self.assertEqual(text_after(redo_y()), stepped)
        # A new edit after an undo ends what redo could bring back: Ctrl+Y then changes nothing,
        # and undo returns to the state before that edit.
        lowered = text_after(chain().send_keys(Keys.ARROW_DOWN))
        self.assertNotIn(lowered, (stepped, raised))
        redo_y().perform()
        self.assertEqual(text_after(undo()), stepped)
        # Knots set from typed --speed text are one edit too.
        before = self.plan_seq()
        self.type_over("speed-text", "0s:1,0.03s:2")
        self.settled_plan(before)
        typed = self.el("speed-text").get_attribute("value")
        self.assertNotEqual(typed, stepped)
        x_empty, y_empty = self.editor_point(seconds * 0.75, 10, seconds)
        chain().move_to_element_with_offset(canvas, x_empty, y_empty).click().perform()  # focus only
        self.assertEqual(text_after(undo()), stepped)
        self.assertEqual(text_after(redo_y()), typed)

    def test_8o_typed_text_being_read_when_a_plan_answers_is_still_applied(self):
        # The user types new knots and moves on while an earlier edit's plan is on its way: that
        # plan's answer must neither overwrite the text being read nor void its reading.
        wait_for(lambda: self.body("planPending") == "false", "no plan pending")
        typed = "0s:1,0.02s:3"
        self.hold_fetches("ParseSpeedKnots", "0.02s:3")
        self.type_over("speed-text", typed, Keys.TAB)
        wait_for(lambda: self.held("waiting") >= 1, "the typed text's reading held")
        before = self.plan_seq()
        Select(self.el("filter")).select_by_visible_text("linear")
        self.settled_plan(before)
        self.assertEqual(self.el("speed-text").get_attribute("value"), typed)

        before = self.plan_seq()
        self.release_fetches()
        self.settled_plan(before)
        wait_for(lambda: self.body("planPending") == "false", "no plan pending")
        self.assertEqual(self.el("speed-text").get_attribute("value"), typed)
        self.assertEqual(self.shown("speed-text-error"), "")
        before = self.plan_seq()
        Select(self.el("filter")).select_by_visible_text("tent")
        self.settled_plan(before)

    def test_8p_holds_are_edits_undo_and_redo_reach_and_bad_fields_are_refused(self):
        # Runs on the clip 8m opened, without holds. Each edit waits for the server's plan, whose
        # answer writes the retime command (its --hold words are the holds the page sent) and
        # the output duration, which each set of holds must give back whenever it returns.
        wait_for(lambda: self.body("planPending") == "false", "no plan pending")
        seconds = float(re.search(r"([0-9.]+) s,", self.el("clip-info").text).group(1))
        early, late = round(seconds * 0.2, 2), round(seconds * 0.6, 2)
        durations = {}

        def chain():
            return ActionChains(self.driver)

        def holds_after(action, same_duration_as_before=True):
            before = self.plan_seq()
            action()
            self.settled_plan(before)
            sent = re.findall(r"--hold (\S+)", self.el("retime-command").text)
            listed = [item.text.rstrip("×").strip()
                      for item in self.driver.find_elements(By.CSS_SELECTOR, "#holds > span")]
            self.assertEqual(listed, sent)  # the list beside the fields shows what is sent
            if same_duration_as_before:
                duration = float(self.el("duration").get_attribute("data-seconds"))
                self.assertEqual(durations.setdefault(tuple(sent), duration), duration, sent)
            return sent

        def add(at, duration):
            def action():
                self.type_over("hold-at", str(at), Keys.TAB)
                self.type_over("hold-duration", str(duration), Keys.TAB)
                self.el("add-hold").click()
            return action

        def keys(key, shift=False):  # sent to what has the focus
            def action():
                actions = chain().key_down(Keys.CONTROL)
                if shift:
                    actions = actions.key_down(Keys.SHIFT)
                actions = actions.send_keys(key)
                if shift:
                    actions = actions.key_up(Keys.SHIFT)
                actions.key_up(Keys.CONTROL).perform()
            return action

        def remove_first():
            self.driver.find_elements(By.CSS_SELECTOR, "#holds button")[0].click()

        def select_filter(name):
            return lambda: Select(self.el("filter")).select_by_visible_text(name)

        one = ["%ss:0.25" % late]
        both = ["%ss:0.5" % early, "%ss:0.25" % late]
        self.assertEqual(holds_after(select_filter("linear")), [])  # the duration without holds
        self.assertEqual(holds_after(add(late, 0.25)), one)
        self.assertEqual(holds_after(add(early, 0.5)), both)  # kept in source-time order
        # The server's duration grows with each hold: the holds reach it.
        self.assertLess(durations[()], durations[tuple(one)])
        self.assertLess(durations[tuple(one)], durations[tuple(both)])
        # With the focus on the button just clicked, Ctrl+Z reaches the editor's history.
        self.assertEqual(holds_after(keys("z")), one)
        self.assertEqual(holds_after(keys("y")), both)
        # Removing a hold is an edit too.
        self.assertEqual(holds_after(remove_first), one)
        self.assertEqual(holds_after(keys("z")), both)
        self.assertEqual(holds_after(keys("z", shift=True)), one)
        self.assertEqual(holds_after(keys("z")), both)
        # In a field text is typed into, Ctrl+Z is the field's own: the holds stay (the next
        # plan, asked for by another setting, shows them).
        self.el("hold-duration").click()
        keys("z")()
        self.assertEqual(holds_after(select_filter("tent")), both)
        # On a checkbox it is the editor's.
        self.assertEqual(holds_after(lambda: self.el("reverse").click(), False), both)
        self.assertEqual(holds_after(keys("z"), False), one)
        self.assertEqual(holds_after(keys("y"), False), both)
        self.assertEqual(holds_after(lambda: self.el("reverse").click()), both)
        # Knot edits and hold edits are one history: a knot raised, then undone step by step.
        knots_before = self.el("speed-text").get_attribute("value")
        holds_after(self.speed_up_first_knot, False)
        self.assertNotEqual(self.el("speed-text").get_attribute("value"), knots_before)
        self.assertEqual(holds_after(keys("z")), both)
        self.assertEqual(self.el("speed-text").get_attribute("value"), knots_before)
        self.assertEqual(holds_after(keys("z")), one)
        self.assertEqual(holds_after(keys("z")), [])

        # Fields a hold cannot take are refused with a message, and no hold is added.
        past_end = str(round(seconds + 1, 2))
        for at, duration, said in [("", "0.5", "time a blank is not a number of seconds from 0"),
                                   ("-1", "0.5", 'time "-1" is not a number of seconds from 0'),
                                   ("1e", "0.5", "time: what is typed is not a number"),
                                   (past_end, "0.5", "time %ss is after the end of the clip"
                                    % past_end),
                                   ("0", "0", 'duration "0" is not a number of seconds above 0'),
                                   ("0", "", "duration a blank is not a number of seconds above 0")]:
            with self.subTest(at=at, duration=duration):
                self.type_over("hold-at", at, Keys.TAB)
                self.type_over("hold-duration", duration, Keys.TAB)
                self.el("add-hold").click()
                wait_for(lambda: said in self.shown("hold-error"), "the hold's refusal")
                self.assertTrue(self.shown("hold-error").startswith("hold: "))
                self.assertTrue(self.shown("hold-error").endswith("; no hold added"))
        self.assertEqual(holds_after(add(early, 0.5)), both[:1])  # the early one alone
        self.assertEqual(self.shown("hold-error"), "")
        # Over output time the holds are still sent, and back over source time still listed.
        self.assertEqual(holds_after(lambda: Select(self.el("domain")).select_by_value("output"),
                                     False), both[:1])
        self.assertEqual(holds_after(lambda: Select(self.el("domain")).select_by_value("source"),
                                     False), both[:1])
        self.assertEqual(holds_after(remove_first, False), [])

    # ---- long jobs: a server whose one worker is busy, so the page's jobs wait in its queue ------
    def make_server_busy(self, busy):
        """Keeps the one worker of `busy` busy with the paper's reduction of a noise channel with
        1000 passes at accuracy 1e-300 (tests/server/job_cancellation_test.cc's long job; on 64 000
        frames about half a minute of this 2-core machine's core each), twelve of them, so every job
        the page submits next waits behind about six minutes of work (still a quarter of a minute
        on a machine twenty times faster; a loaded machine only makes it longer): its progress, its
        cancel and its end when the page is left are seen as states. The blockers are cancelled
        when the tests end."""
        noise = random.Random(11)
        text = "noise\n" + "".join("%.4f\n" % noise.gauss(0, 10) for _ in range(64000))
        clip = api_call(busy, "ParseClipFile", {"fileName": "noise.csv", "csvFrameTimeSeconds": 1 / 120,
                                                "content": base64.b64encode(text.encode()).decode()})
        paper = {"reduce": {"method": "REDUCE_METHOD_PAPER", "paper": {"maxIterations": 1000, "accuracy": 1e-300}}}
        type(self).blockers = [api_call(busy, "SubmitJob", {"clipId": clip["clipId"], "operations": [paper]})["jobId"]
                               for _ in range(12)]

    def test_9a_long_jobs_show_progress_cancel_and_leave_no_superseded_job(self):
        # A second server with one worker; the clip is opened while it is idle (parsing a file and
        # planning a retime run on the workers too), then the worker is kept busy: the reductions
        # the page asks for next wait in the queue.
        busy = StudioServer("--workers", "1", "--max_job_cost_seconds", "0", "--log_level", "info").__enter__()
        type(self).busy = busy
        self.driver.get(busy.http_url)
        wait_for(lambda: self.body("ready") == "true", "the page to reach the busy server")
        self.open_clip(CMU)
        kept = {self.data("retime-status", "job-id"), self.data("reduce-status", "job-id")}
        self.make_server_busy(busy)

        self.el("run-reduce").click()

        # Progress: the server's stage of the job, queued behind the busy worker, and a Cancel.
        wait_for(lambda: self.data("reduce-job", "state") == "JOB_STATE_QUEUED", "the queued reduction")
        self.assertIn("queued", self.el("reduce-stage").text)
        self.assertTrue(self.el("reduce-cancel").is_displayed())
        # Quick edits: each supersedes the queued reduction, which the page cancels and deletes.
        for tolerance in ("0.4", "0.3", "0.2", "0.1"):
            job = self.data("reduce-job", "job-id")
            self.type_over("tolerance", tolerance, Keys.TAB)
            wait_for(lambda: self.data("reduce-job", "job-id") not in (None, job)
                     and self.data("reduce-job", "state") == "JOB_STATE_QUEUED", "the next reduction job")
        waiting = self.data("reduce-job", "job-id")
        # The page's kept results (the clip's first retime and reduction) stay until replaced.
        wait_for(lambda: {j["jobId"] for j in self.studio_jobs(busy)} == kept | {waiting},
                 "the superseded jobs deleted (the server holds %s)" % len(self.studio_jobs(busy)))
        # Cancel: the job ends cancelled, and the page works on with its previous result.
        self.el("reduce-cancel").click()
        wait_for(lambda: self.data("reduce-status", "state") == "cancelled", "the page to show the cancel")
        self.assertFalse(self.el("reduce-job").is_displayed())
        wait_for(lambda: job_logged_cancelled(busy, waiting), "the cancelled job in the server's log")
        self.assertTrue(self.el("download-reduce-json").is_displayed())
        self.el("run-reduce").click()
        wait_for(lambda: self.data("reduce-job", "job-id") not in (None, waiting)
                 and self.data("reduce-job", "state") == "JOB_STATE_QUEUED", "a new reduction queued")

    def test_9b_leaving_the_page_cancels_its_jobs_and_its_next_load_deletes_them(self):
        # Runs after 9a, on its page: the busy server (cls.busy) and the reduction 9a left queued.
        busy = self.busy
        jobs = [self.data("reduce-job", "job-id")]
        self.assertNotIn(None, jobs)

        self.driver.get("about:blank")

        for job in jobs:
            wait_for(lambda: job_logged_cancelled(busy, job), "job %s cancelled once the page is left" % job)
        # A cancelled job is deleted only once ended, which the page left could not wait for: the
        # next load of the page in this tab deletes it (the jobs carry the left page's id).
        self.driver.get(busy.http_url)
        wait_for(lambda: self.body("ready") == "true", "the page to reach the busy server again")
        wait_for(lambda: not self.studio_jobs(busy),
                 "the left page's jobs deleted (the server holds %s)" % len(self.studio_jobs(busy)))

    def test_9c_a_file_over_the_servers_limit_is_refused_before_it_is_sent(self):
        # A server taking messages of 1 MiB: files up to (1 MiB - 64 KiB) / 4 * 3 bytes.
        with StudioServer("--max_message_bytes", str(1 << 20)) as small:
            self.driver.get(small.http_url)
            wait_for(lambda: self.body("ready") == "true", "the page to reach the small server")
            big = os.path.join(self.work.name, "big.bvh")
            with open(big, "wb") as f:
                f.truncate(((1 << 20) - (1 << 16)) // 4 * 3 + 1)

            self.el("file-input").send_keys(big)

            message = wait_for(lambda: self.shown("message"), "the refusal")
            self.assertEqual(message, "big.bvh is 0.7 MiB: the server takes files up to 0.7 MiB "
                             "(its limit of 1048576 bytes per request, the file travelling as base64)")
            self.assertEqual(self.data("clip-info", "state"), None)
            # One byte less is sent (and refused by the server's reader: it is no BVH).
            with open(big, "wb") as f:
                f.truncate(((1 << 20) - (1 << 16)) // 4 * 3)
            self.el("file-input").send_keys(big)
            wait_for(lambda: self.shown("message").startswith("big.bvh:"), "the reader's message")

    def test_9d_a_server_that_wants_a_token_first_still_refuses_a_file_too_big(self):
        tokens = os.path.join(self.work.name, "tokens")
        with open(tokens, "w") as f:
            f.write("studio-test-token\n")
        with StudioServer("--auth_token_file", tokens) as guarded:
            self.driver.get(guarded.http_url)
            wait_for(lambda: self.el("token-box").is_displayed(), "the page to ask for the token")
            # Over the default limit of 64 MiB per message, not read: a sparse file.
            big = os.path.join(self.work.name, "huge.bvh")
            with open(big, "wb") as f:
                f.truncate(49 << 20)

            self.el("file-input").send_keys(big)

            message = wait_for(lambda: self.shown("message").startswith("huge.bvh") and self.shown("message"),
                               "the refusal")
            self.assertIn("the server takes files up to 48 MiB", message)
            self.assertIn("the default limit of 64 MiB", message)


if __name__ == "__main__":
    unittest.main()
