"""Headless Chromium driven over its DevTools pipe, for tests that look at what a page draws.

``--screenshot`` alone cannot wait for a page that keeps loading after its ``load`` event (Rerun's web viewer
fetches and compiles 40 MB of wasm, then streams its data): it shot the loading screen after 2 s. So the
browser is started with ``--remote-debugging-pipe`` (DevTools messages as NUL-terminated JSON on its file
descriptors 3 and 4: no websocket client, no Python dependency) and asked for screenshots until the test has
what it waits for. The flags are those that work on this kind of machine (a closed network, root, no GPU:
``--no-sandbox`` and the background-networking ones). With ``--disable-gpu`` Rerun's viewer still gets WebGPU,
on Chromium's CPU rasteriser (it says "Software rasterizer"); ``--use-angle=swiftshader
--enable-unsafe-swiftshader`` were tried and are not needed (Chromium 150: the 3D view drawn 16-20 s after
the page was opened, either way).
"""

from __future__ import annotations

import base64
import io
import json
import os
import shutil
import subprocess
import tempfile

import numpy as np

NAMES = ("chromium", "chromium-browser", "google-chrome")
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync", "--remote-debugging-pipe"]
WINDOW = (1280, 800)


def find_chromium() -> str | None:
    """The Chromium on ``PATH`` (Debian's package ``chromium``), or None."""
    return next((found for name in NAMES if (found := shutil.which(name))), None)


class Chromium:
    """One headless Chromium with a fresh profile; a context manager that ends it (by its own pid)."""

    def __init__(self, executable: str):
        self._profile = tempfile.TemporaryDirectory(prefix="chromium-profile-")
        to_browser, self._out = os.pipe()
        self._in, from_browser = os.pipe()

        def descriptors_3_and_4() -> None:  # in the child: the pipe ends where --remote-debugging-pipe looks
            os.dup2(to_browser, 100)
            os.dup2(from_browser, 101)
            os.dup2(100, 3)
            os.dup2(101, 4)

        self.process = subprocess.Popen(
            [executable, *FLAGS, f"--window-size={WINDOW[0]},{WINDOW[1]}", f"--user-data-dir={self._profile.name}",
             "about:blank"],
            preexec_fn=descriptors_3_and_4, close_fds=False, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        os.close(to_browser)
        os.close(from_browser)
        self._buffer = b""
        self._next_id = 0

    def __enter__(self) -> Chromium:
        return self

    def __exit__(self, *exc) -> None:
        self.process.terminate()
        try:
            self.process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
        os.close(self._out)
        os.close(self._in)
        self._profile.cleanup()

    def call(self, method: str, params: dict | None = None, session: str | None = None) -> dict:
        """Send one DevTools command and return its result (events arriving meanwhile are dropped)."""
        self._next_id += 1
        message = {"id": self._next_id, "method": method, "params": params or {}}
        if session is not None:
            message["sessionId"] = session
        os.write(self._out, json.dumps(message).encode() + b"\0")
        while True:
            while b"\0" not in self._buffer:
                chunk = os.read(self._in, 1 << 16)
                if not chunk:
                    raise RuntimeError(f"Chromium closed its DevTools pipe (exit code {self.process.poll()})")
                self._buffer += chunk
            raw, self._buffer = self._buffer.split(b"\0", 1)
            reply = json.loads(raw)
            if reply.get("id") == self._next_id:
                if "error" in reply:
                    raise RuntimeError(f"{method}: {reply['error']}")
                return reply["result"]

    def open(self, url: str) -> str:
        """A new tab at ``url``; its session id."""
        target = self.call("Target.createTarget", {"url": url})["targetId"]
        return self.call("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]

    def screenshot(self, session: str) -> np.ndarray:
        """What the tab shows now, as an (H, W, 3) uint8 RGB array."""
        from PIL import Image  # matplotlib's own dependency

        png = base64.b64decode(self.call("Page.captureScreenshot", {"format": "png"}, session)["data"])
        return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))
