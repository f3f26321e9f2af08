"""The README's pictures taken by a real browser on rerun's web viewer: each demo recorded by
`hil up NAME --demo --lock-step`, served by `rerun --serve-web` (its web viewer over HTTP
and the recording over gRPC, on loopback), opened by headless Chromium (WebGL on its
software rasteriser) and captured once the viewer has laid out the recording's blueprint.

    .venv/bin/python tools/web_screenshot.py pigot docs/viewer.png ur3 docs/viewer-ur3.png

Needs Debian's `chromium` (apt). Run from the repository root with hil installed; the
browser reaches nothing but 127.0.0.1."""

from __future__ import annotations

import shutil
import socket
import subprocess
import sys
import tempfile
import time
import urllib.parse
from pathlib import Path

#: how long the viewer gets to load the wasm, stream the recording and lay out its views (s)
SETTLE = 25
SIZE = (1600, 900)


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
        with tempfile.TemporaryDirectory() as profile:
            subprocess.run([browser, "--headless=new", "--no-sandbox", "--disable-gpu-sandbox",
                            "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
                            "--no-first-run", f"--user-data-dir={profile}",
                            f"--window-size={SIZE[0]},{SIZE[1]}", "--hide-scrollbars",
                            f"--timeout={SETTLE * 1000}", f"--screenshot={picture}",
                            f"http://127.0.0.1:{web}/?url={source}"],
                           check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                           timeout=SETTLE + 120)
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
