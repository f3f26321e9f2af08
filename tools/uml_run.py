#!/usr/bin/env python3
"""Run a command inside User-Mode Linux, where SocketCAN vcan exists.

This machine's kernel has no AF_CAN. Debian's ``user-mode-linux`` package
ships a Linux kernel that runs as an ordinary process and has the CAN
modules, so real SocketCAN can be tested without root on the host kernel:

    tools/uml_run.py [--vcan vcan0 ...] [--timeout S] -- COMMAND [ARGS...]

UML boots with the host's own filesystem as its root (hostfs), runs an init
script that mounts /proc, /sys and a tmpfs on /dev/shm (Zenoh needs POSIX
shared memory), brings up ``lo``, loads can, can-raw, can-bcm, can-dev and
vcan, creates the vcan interfaces, and runs COMMAND in the current folder
with the current environment. UML's own exit status does not carry the
command's, so the script writes it to a file on the shared filesystem; this
runner exits with it. Needs the Debian packages user-mode-linux and kmod.
"""

from __future__ import annotations

import argparse
import os
import shlex
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

KERNEL = "linux.uml"
MODULES = Path("/usr/lib/uml/modules")
CAN_MODULES = ("net/can/can.ko", "net/can/can-raw.ko", "net/can/can-bcm.ko",
               "drivers/net/can/dev/can-dev.ko", "drivers/net/can/vcan.ko")
# The environment inside UML is empty; these host variables are passed in.
_SKIP_ENV = {"PWD", "OLDPWD", "SHLVL", "_", "TERM", "DISPLAY"}


def available() -> str | None:
    """None if UML can run here, else what is missing."""
    if shutil.which(KERNEL) is None:
        return f"'{KERNEL}' not found (apt-get install user-mode-linux kmod)"
    if shutil.which("insmod") is None and not Path("/usr/sbin/insmod").exists():
        return "'insmod' not found (apt-get install kmod)"
    if not MODULES.is_dir() or not any(MODULES.iterdir()):
        return f"no UML kernel modules under {MODULES}"
    return None


def init_script(command: list[str], vcans: list[str], status_file: Path, cwd: Path) -> str:
    modules = next(p for p in sorted(MODULES.iterdir()) if p.is_dir()) / "kernel"
    exports = "\n".join(f"export {k}={shlex.quote(v)}" for k, v in os.environ.items()
                        if k not in _SKIP_ENV and k.isidentifier())
    links = "\n".join(f"ip link add dev {v} type vcan && ip link set up {v}" for v in vcans)
    loads = "\n".join(f"insmod {modules / m}" for m in CAN_MODULES)
    return f"""#!/bin/sh
{exports}
export PATH="$PATH:/usr/sbin:/sbin:/usr/bin:/bin"
mount -t proc proc /proc
mount -t sysfs sysfs /sys
mkdir -p /dev/shm && mount -t tmpfs -o size=512m tmpfs /dev/shm
ip link set lo up
{loads}
{links}
cd {shlex.quote(str(cwd))}
{" ".join(shlex.quote(c) for c in command)}
echo $? > {shlex.quote(str(status_file))}
poweroff -f
"""


def run(command: list[str], vcans: list[str], timeout: float, memory: str = "2G") -> int:
    missing = available()
    if missing:
        print(f"uml_run: cannot run User-Mode Linux: {missing}", file=sys.stderr)
        return 3
    with tempfile.TemporaryDirectory(prefix="hil-uml-", dir=Path.cwd()) as folder:
        folder = Path(folder)
        status_file = folder / "status"
        script = folder / "init.sh"
        script.write_text(init_script(command, vcans, status_file, Path.cwd()))
        script.chmod(0o755)
        uml_home = folder / "uml"      # UML keeps its per-instance files under $HOME/.uml
        uml_home.mkdir()
        kernel = [KERNEL, f"mem={memory}", "root=/dev/root", "rootfstype=hostfs", "rootflags=/",
                  "rw", f"init={script}", "con=null", "con0=fd:0,fd:1", "quiet"]
        try:
            subprocess.run(kernel, stdin=subprocess.DEVNULL, timeout=timeout,
                           env={**os.environ, "HOME": str(uml_home), "TMPDIR": str(folder)})
        except subprocess.TimeoutExpired:
            print(f"uml_run: the command did not finish within {timeout:g} s", file=sys.stderr)
            return 124
        if not status_file.exists():
            print("uml_run: the command left no exit status (UML crashed?)", file=sys.stderr)
            return 125
        return int(status_file.read_text().strip() or 125)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--vcan", action="append", default=[],
                        help="vcan interface to create (repeatable; default vcan0)")
    parser.add_argument("--timeout", type=float, default=600, help="seconds (default 600)")
    parser.add_argument("--memory", default="2G", help="UML memory (default 2G)")
    parser.add_argument("command", nargs=argparse.REMAINDER)
    args = parser.parse_args()
    command = args.command[1:] if args.command[:1] == ["--"] else args.command
    if not command:
        parser.error("give a command after --")
    return run(command, args.vcan or ["vcan0"], args.timeout, args.memory)


if __name__ == "__main__":
    sys.exit(main())
