"""The README's pictures taken by a real browser on rerun's web viewer: each demo recorded by
`hil up ROBOT --demo --lock-step`, served by `rerun --serve-web` (its web viewer over HTTP,
the recording over gRPC, both on 127.0.0.1), opened by headless Chromium (WebGL on its
software rasteriser) through the DevTools protocol, and captured once the viewer has
streamed the recording and laid out its blueprint.

    .venv/bin/python tools/web_screenshot.py pigot docs/viewer.png ur3 docs/viewer-ur3.png

Needs Debian's `chromium` (apt) and the `websockets` package (pip; mujoco's studio brings
it). Run from the repository root with hil installed. The browser reaches nothing but
127.0.0.1; its profile is a temporary folder."""

from __future__ import annotations

import asyncio
import base64
import json
import shutil
import socket
import subprocess
import sys
import tempfile
import time
import urllib.parse
import urllib.request
from pathlib import Path

import websockets

#: how long the viewer gets to load its wasm, stream the recording and lay out its views (s)
SETTLE = 35.0
WIDTH, HEIGHT = 1600, 900


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def wait_for(port: int, timeout: float = 30.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        with socket.socket() as probe:
            if probe.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.2)
    raise SystemExit(f"nothing listens on 127.0.0.1:{port} after {timeout:g} s")


def record(robot: str, folder: Path, bin_dir: Path) -> Path:
    recording = folder / f"{robot}.rrd"
    subprocess.run([str(bin_dir / "hil"), "up", robot, "--demo", "--lock-step", "--no-viewer",
                    "--save", str(recording)], cwd=folder, check=True)
    return recording


async def capture(browser: str, url: str, picture: Path) -> None:
    """Open ``url`` in headless Chromium, wait SETTLE seconds, save the page as PNG."""
    port = free_port()
    with tempfile.TemporaryDirectory() as profile:
        process = subprocess.Popen(
            [browser, "--headless=new", "--no-sandbox", "--use-angle=swiftshader",
             "--enable-unsafe-swiftshader", "--no-first-run", f"--user-data-dir={profile}",
             f"--window-size={WIDTH},{HEIGHT}", "--hide-scrollbars",
             "--remote-debugging-address=127.0.0.1", f"--remote-debugging-port={port}",
             "about:blank"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            wait_for(port)
            with urllib.request.urlopen(f"http://127.0.0.1:{port}/json") as answer:
                page = next(t for t in json.load(answer) if t["type"] == "page")
            async with websockets.connect(page["webSocketDebuggerUrl"],
                                          max_size=2 ** 28) as devtools:
                calls = iter(range(1, 1_000_000))

                async def call(method: str, **params) -> dict:
                    number = next(calls)
                    await devtools.send(json.dumps({"id": number, "method": method,
                                                    "params": params}))
                    while True:              # events arrive between the answers
                        answer = json.loads(await devtools.recv())
                        if answer.get("id") == number:
                            return answer.get("result", {})

                await call("Emulation.setDeviceMetricsOverride", width=WIDTH, height=HEIGHT,
                           deviceScaleFactor=1, mobile=False)
                await call("Page.navigate", url=url)
                await asyncio.sleep(SETTLE)
                shot = await call("Page.captureScreenshot", format="png")
                picture.write_bytes(base64.b64decode(shot["data"]))
        finally:
            process.terminate()
            process.wait(10)


def shoot(recording: Path, picture: Path, bin_dir: Path, browser: str) -> None:
    web, grpc = free_port(), free_port()
    server = subprocess.Popen([str(bin_dir / "rerun"), "--serve-web", "--bind", "127.0.0.1",
                               "--web-viewer-port", str(web), "--port", str(grpc),
                               "--renderer", "webgl", str(recording)],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        wait_for(web)
        wait_for(grpc)
        source = urllib.parse.quote(f"rerun+http://127.0.0.1:{grpc}/proxy", safe="")
        asyncio.run(capture(browser, f"http://127.0.0.1:{web}/?url={source}&renderer=webgl",
                            picture))
    finally:
        server.terminate()
        server.wait(10)


def main(arguments: list[str]) -> int:
    if not arguments or len(arguments) % 2:
        raise SystemExit("give ROBOT PICTURE pairs, e.g. pigot docs/viewer.png")
    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    if browser is None:
        raise SystemExit("no chromium on PATH: apt install chromium")
    bin_dir = Path(sys.executable).parent
    with tempfile.TemporaryDirectory() as work:
        for robot, picture in zip(arguments[::2], arguments[1::2]):
            shoot(record(robot, Path(work), bin_dir), Path(picture).resolve(), bin_dir,
                  browser)
            print(f"screenshot: {picture}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
