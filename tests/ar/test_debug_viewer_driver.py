#!/usr/bin/env python3
"""Drives the arreg debug viewer in headless Chromium through ChromeDriver (W3C WebDriver over
HTTP on 127.0.0.1, standard library only) and writes what it saw as JSON for
test_debug_chromium.cc: frame shown before and after three Right-arrow presses, two layer
checkboxes before and after clicking them, a click on a feature, the screenshot and the
browser console log."""
import argparse
import base64
import json
import socket
import subprocess
import sys
import time
import urllib.request

KEY_RIGHT = "\ue014"


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def call(base, method, path, body=None, timeout=30):
    data = None if body is None else json.dumps(body).encode()
    req = urllib.request.Request(base + path, data=data, method=method,
                                 headers={"Content-Type": "application/json"})
    with urllib.request.urlopen(req, timeout=timeout) as r:
        return json.loads(r.read().decode() or "{}").get("value")


def wait_for(predicate, what, timeout=20.0):
    end = time.time() + timeout
    while time.time() < end:
        value = predicate()
        if value:
            return value
        time.sleep(0.05)
    raise RuntimeError("timed out waiting for " + what)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--chromium", required=True)
    ap.add_argument("--chromedriver", required=True)
    ap.add_argument("--url", required=True)
    ap.add_argument("--profile", required=True)
    ap.add_argument("--screenshot", required=True)
    ap.add_argument("--result", required=True)
    ap.add_argument("--click", default="", help="ID,X,Y: feature to click at image pixel X,Y")
    ap.add_argument("--page-only", action="store_true", help="load the page and read the log only")
    a = ap.parse_args()

    port = free_port()
    driver = subprocess.Popen([a.chromedriver, "--port=%d" % port, "--allowed-ips=127.0.0.1"],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    base = "http://127.0.0.1:%d" % port
    result = {}
    session = None
    try:
        wait_for(lambda: _ready(base), "chromedriver")
        caps = {"capabilities": {"alwaysMatch": {
            "browserName": "chrome",
            "goog:loggingPrefs": {"browser": "ALL"},
            "goog:chromeOptions": {
                "binary": a.chromium,
                "args": ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                         "--no-first-run", "--disable-background-networking",
                         "--disable-component-update", "--disable-sync",
                         "--disable-dev-shm-usage", "--allow-file-access-from-files",
                         "--window-size=1280,900", "--user-data-dir=" + a.profile]}}}}
        session = call(base, "POST", "/session", caps, timeout=60)["sessionId"]
        s = "/session/" + session
        call(base, "POST", s + "/url", {"url": a.url})
        script = lambda js: call(base, "POST", s + "/execute/sync", {"script": js, "args": []})
        if not a.page_only:
            frames = script("return window.ARREG_META.frames;")
            result["frames"] = frames
            wait_for(lambda: script("return document.getElementById('view').dataset.frame;") ==
                     str(frames[0]), "first frame drawn")
            result["shown_before"] = int(script("return document.getElementById('view').dataset.frame;"))
            result["label_before"] = script("return document.getElementById('frame-index').textContent;")
            keys = []
            for _ in range(3):
                keys += [{"type": "keyDown", "value": KEY_RIGHT}, {"type": "keyUp", "value": KEY_RIGHT}]
            call(base, "POST", s + "/actions",
                 {"actions": [{"type": "key", "id": "keyboard", "actions": keys}]})
            target = str(frames[min(3, len(frames) - 1)])
            wait_for(lambda: script("return document.getElementById('view').dataset.frame;") == target,
                     "frame " + target + " drawn")
            result["shown_after"] = int(script("return document.getElementById('view').dataset.frame;"))
            result["label_after"] = script("return document.getElementById('frame-index').textContent;")
            # The numbers panel's row of this frame's rejected clusters (six counts).
            result["rejected_row"] = script(
                "const r = [...document.querySelectorAll('#numbers tr')].find("
                "(tr) => tr.cells[0].textContent.startsWith('clusters rejected'));"
                "return r ? r.cells[1].textContent : '';")
            toggles = {}
            for name in ("pairs", "mesh"):
                before = script("return document.getElementById('layer-%s').checked;" % name)
                el = call(base, "POST", s + "/element",
                          {"using": "css selector", "value": "#layer-" + name})
                eid = list(el.values())[0]
                call(base, "POST", s + "/element/%s/click" % eid, {})
                after = script("return document.getElementById('layer-%s').checked;" % name)
                toggles[name] = [before, after]
            result["toggles"] = toggles
            # Click the first feature: its track and mu history appear.
            px = [float(v) for v in a.click.split(",")] if a.click else None
            if px:
                canvas = call(base, "POST", s + "/element", {"using": "css selector", "value": "#view"})
                cid = list(canvas.values())[0]
                rect = call(base, "GET", s + "/element/%s/rect" % cid)
                scale = rect["width"] / script("return document.getElementById('view').width;")
                x = int(round(px[1] * scale - rect["width"] / 2))
                y = int(round(px[2] * scale - rect["height"] / 2))
                call(base, "POST", s + "/actions", {"actions": [{
                    "type": "pointer", "id": "mouse", "parameters": {"pointerType": "mouse"},
                    "actions": [{"type": "pointerMove", "origin": {"element-6066-11e4-a52e-4f735466cecf": cid},
                                 "x": x, "y": y},
                                {"type": "pointerDown", "button": 0},
                                {"type": "pointerUp", "button": 0}]}]})
                result["clicked_feature"] = int(px[0])
                result["selected"] = wait_for(
                    lambda: script("return document.getElementById('view').dataset.selected;"),
                    "feature selection")
                result["mu_plot_paths"] = script(
                    "return document.querySelectorAll('#mu-plot path').length;")
            time.sleep(0.2)
        with open(a.screenshot, "wb") as f:
            f.write(base64.b64decode(call(base, "GET", s + "/screenshot")))
        result["log"] = call(base, "POST", s + "/se/log", {"type": "browser"})
    finally:
        if session:
            try:
                call(base, "DELETE", "/session/" + session)
            except Exception:  # the browser may already be gone; the driver is stopped below
                pass
        driver.terminate()
        try:
            driver.wait(10)
        except subprocess.TimeoutExpired:
            driver.kill()
    with open(a.result, "w") as f:
        json.dump(result, f)
    return 0


def _ready(base):
    try:
        return call(base, "GET", "/status", timeout=2).get("ready")
    except OSError:
        return False


if __name__ == "__main__":
    sys.exit(main())
