#!/usr/bin/python3
"""A screenshot of a light-field viewer page (the index.html that reconstruct and evaluate
write), taken in headless Chromium once every view is decoded and drawn: for docs and notes.

    scripts/viewer-screenshot.py PAGE.html OUT.png [WIDTH HEIGHT]

Drives the browser as tests/viewer/browser_test.py does (its DevTools class, over a pipe).
"""
import os
import sys
import tempfile

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests", "viewer"))
import browser_test  # noqa: E402


def main(argv):
    if len(argv) < 3:
        print(__doc__)
        return 2
    page, out = argv[1], argv[2]
    width, height = (int(argv[3]), int(argv[4])) if len(argv) > 4 else (1400, 1100)
    chromium = browser_test.find_chromium()
    if not chromium:
        print("viewer-screenshot.py: no Chromium (scripts/install-deps.sh installs it)", file=sys.stderr)
        return 1
    if not os.path.isfile(page):
        print(f"viewer-screenshot.py: {page} is not a file", file=sys.stderr)
        return 1
    browser = browser_test.DevTools(chromium, tempfile.mkdtemp(prefix="lfnet-chromium-"))
    try:
        target = browser.send("Target.createTarget", {"url": "about:blank"})["targetId"]
        browser.session = browser.send("Target.attachToTarget",
                                       {"targetId": target, "flatten": True})["sessionId"]
        browser.send("Page.enable")
        browser.send("Runtime.enable")
        browser.send("Emulation.setDeviceMetricsOverride",
                     {"width": width, "height": height, "deviceScaleFactor": 1, "mobile": False})
        browser.send("Page.navigate", {"url": "file://" + os.path.abspath(page)})
        browser.evaluate("new Promise(r => { const t = setInterval(() => { if (window.lfnetViewer)"
                         " { clearInterval(t); r(); } }, 10); })")
        browser.evaluate("window.lfnetViewer.ready")
        browser.screenshot(out)
    finally:
        browser.close()
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
