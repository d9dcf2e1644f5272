#!/usr/bin/env python3
"""Studio drag latency: from a knot drag in the velocity editor to the page showing the server's
new output duration and time map, on 131_01 over loopback (real tempokey-server, real headless
Chromium). Not a test: it prints figures.

  build/server/tempokey-server must exist; run from the checkout:
  /usr/bin/python3 bench/studio_drag_bench.py [--drags 50] [--server build/server/tempokey-server]

Each drag presses a knot, moves it 14 px up or down and releases it. The page stamps the time of
the pointer event whose knots a PlanRetime request carried, and after drawing that answer's
duration and time map it records the difference (document.body.dataset.planLatencyMs): the
figure printed is the median of those over the drags.
"""

import argparse
import math
import os
import statistics
import sys
import tempfile
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests", "studio"))


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--drags", type=int, default=50)
    parser.add_argument("--server", default=os.path.join(here, "..", "build", "server", "tempokey-server"))
    parser.add_argument("--clip", default=os.path.join(here, "..", "..", "shared", "data", "bvh", "cmu", "131_01.bvh"))
    args = parser.parse_args()
    os.environ["TEMPOKEY_SERVER"] = os.path.abspath(args.server)

    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys
    from studio_server import StudioServer

    def wait_for(predicate, what, deadline=60):
        end = time.monotonic() + deadline
        while not predicate():
            if time.monotonic() > end:
                raise SystemExit("timed out waiting for " + what)
            time.sleep(0.01)

    with StudioServer() as server, tempfile.TemporaryDirectory() as profile:
        options = webdriver.ChromeOptions()
        options.binary_location = "/usr/bin/chromium"
        for flag in ["--headless=new", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                     "--disable-component-update", "--disable-sync", "--no-first-run",
                     "--enable-unsafe-swiftshader", "--window-size=1500,1300", "--user-data-dir=" + profile]:
            options.add_argument(flag)
        driver = webdriver.Chrome(service=Service("/usr/bin/chromedriver"), options=options)
        try:
            driver.get(server.http_url)
            body = lambda name: driver.execute_script("return document.body.dataset[arguments[0]] || ''", name)
            wait_for(lambda: body("ready") == "true", "the page")
            driver.find_element(By.ID, "file-input").send_keys(os.path.abspath(args.clip))
            wait_for(lambda: driver.find_element(By.ID, "clip-info").get_attribute("data-state") == "loaded", "the clip")
            text = driver.find_element(By.ID, "speed-text")
            text.send_keys(Keys.CONTROL, "a")
            text.send_keys("0s:1,2s:0.5,4s:1", Keys.ENTER)
            wait_for(lambda: "2s:0.5" in text.get_attribute("value") and body("planPending") == "false", "the curve")
            canvas = driver.find_element(By.ID, "editor")
            w, h = canvas.size["width"], canvas.size["height"]
            duration = 993 * 0.0083333
            x = 48 + 2.0 / duration * (w - 48 - 14) - w / 2
            latencies = []
            for i in range(args.drags):
                # Where the knot at 2 s is now, from the speed the page shows (editor geometry:
                # velocity_editor.js, default view 0.04x..25x on a log axis).
                speed = float(text.get_attribute("value").split(",")[1].split(":")[1])
                lo, hi = 0.05 / 1.25, 20 * 1.25
                f = (math.log(speed) - math.log(lo)) / (math.log(hi) - math.log(lo))
                y_offset = h - 28 - f * (h - 14 - 28) - h / 2
                step = -14 if i % 2 == 0 else 14
                before = int(body("planSeq") or 0)
                shown = driver.find_element(By.ID, "duration").text
                (ActionChains(driver).move_to_element_with_offset(canvas, int(round(x)), int(round(y_offset)))
                 .click_and_hold().move_by_offset(0, step).release().perform())
                wait_for(lambda: int(body("planSeq") or 0) > before and body("planPending") == "false",
                         "the plan after drag %d (knot field %s)" % (i, driver.find_element(By.ID, "knot-time").get_attribute("value")))
                if driver.find_element(By.ID, "duration").text == shown:
                    raise SystemExit("drag %d did not change the duration" % i)
                latencies.append(float(body("planLatencyMs")))
            latencies.sort()
            print("studio drag -> duration and time map, 131_01, %d drags over loopback:" % len(latencies))
            print("  median %.1f ms, p90 %.1f ms, min %.1f ms, max %.1f ms" % (
                statistics.median(latencies), latencies[int(0.9 * (len(latencies) - 1))],
                latencies[0], latencies[-1]))
        finally:
            driver.quit()


if __name__ == "__main__":
    main()
