#!/usr/bin/env python3
"""Run a command inside User-Mode Linux, where SocketCAN vcan exists.

This machine's kernel has no AF_CAN. Debian's ``user-mode-linux`` package
ships a Linux kernel that runs as an ordinary process and has the CAN
modules, so real SocketCAN can be tested without root on the host kernel:

    tools/uml_run.py [--vcan vcan0 ...] [--vcan can0:hil-can0] [--timeout S] -- COMMAND ...
    tools/uml_run.py --check        # boots a trivial command: can UML run here?

UML boots with the host's own filesystem as its root (hostfs), runs an init
script that mounts /proc, /sys and a tmpfs on /dev/shm (Zenoh needs POSIX
shared memory), brings up ``lo``, loads can, can-raw, can-bcm, can-dev and
vcan, creates the vcan interfaces, and runs COMMAND in the current folder
with the current environment. UML's own exit status does not carry the
command's, so the script writes it to a file on the shared filesystem; this
runner exits with it. Needs the Debian packages user-mode-linux and kmod,
and a C compiler.

On every host linux.uml runs with ``uml_xstate_ptrace.c`` preloaded (built here at
first use, cached by the source's hash): Debian 12's UML hands ptrace an FPU-state
buffer smaller than the XSAVE area of CPUs with AMX, and panics at boot there without
it (the C file says how). Where the buffer is too small, the registers past it are
not saved per process inside UML, so glibc, numpy and OpenBLAS are kept off AVX-512
inside UML, on every host alike (``inner_environment``).

UML runs on one host CPU (``uml_cpu``). Its kernel and each process inside it are host
processes that hand control to each other through ptrace at every system call made
inside; a hand-over between two host CPUs goes through an inter-processor interrupt,
which a virtual machine pays for dearly. Measured on a 2-CPU AMD EPYC VM: a system call
inside UML took 115 us spread over both CPUs and 18 us on one, a thread ping-pong 2.9 ms
and 0.6 ms; the CiA 402 SocketCAN tests failed 5 to 13 of 55 spread and passed on one.
UML 6.1 runs one CPU anyway, so nothing is lost.
"""

from __future__ import annotations

import argparse
import functools
import hashlib
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
               "drivers/net/can/dev/can-dev.ko", "drivers/net/can/vcan.ko",
               "drivers/net/can/vxcan.ko")
XSTATE_WRAPPER_SOURCE = Path(__file__).resolve().with_name("uml_xstate_ptrace.c")
#: a trial boot takes about 2-3 s; this bound is for a heavily loaded machine
TRIAL_BOOT_TIMEOUT = 60.0
# The environment inside UML is empty; these host variables are passed in.
_SKIP_ENV = {"PWD", "OLDPWD", "SHLVL", "_", "TERM", "DISPLAY", "LD_PRELOAD"}
# glibc's names for the CPU features to turn off (ld.so --list-diagnostics shows the effect)
_GLIBC_OFF = ("AVX512F", "AVX512VL", "AVX512BW", "AVX512DQ", "AVX512CD", "AVX512_FP16",
              "AMX_BF16", "AMX_TILE", "AMX_INT8")


def uml_cpu() -> int:
    """The host CPU linux.uml and everything inside it run on: the last this process may use
    (the first is where a shell's other work lands first)."""
    return max(os.sched_getaffinity(0))


class UmlUnavailable(RuntimeError):
    """User-Mode Linux cannot run here; the message says what is missing."""


def _cache_dir() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "hil" / "uml"


def _missing_tools() -> str | None:
    if shutil.which(KERNEL) is None:
        return f"'{KERNEL}' not found (apt-get install user-mode-linux kmod)"
    if shutil.which("insmod") is None and not Path("/usr/sbin/insmod").exists():
        return "'insmod' not found (apt-get install kmod)"
    if not MODULES.is_dir() or not any(p.is_dir() for p in MODULES.iterdir()):
        return f"no UML kernel modules under {MODULES}"
    return None


def xstate_wrapper() -> Path:
    """The ptrace wrapper preloaded into linux.uml, compiled at first use.

    Cached under ``$XDG_CACHE_HOME/hil/uml`` by the SHA-256 of its source, so an edit
    rebuilds it. Raises UmlUnavailable when no C compiler can build it.
    """
    source = XSTATE_WRAPPER_SOURCE.read_bytes()
    digest = hashlib.sha256(source).hexdigest()[:16]
    library = _cache_dir() / f"uml_xstate_ptrace-{digest}.so"
    if library.exists():
        return library
    compiler = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    if not compiler:
        raise UmlUnavailable("no C compiler to build tools/uml_xstate_ptrace.c "
                             "(apt-get install gcc)")
    library.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=library.parent) as folder:
        built = Path(folder) / library.name
        result = subprocess.run([compiler, "-O2", "-Wall", "-shared", "-fPIC", "-o", str(built),
                                 str(XSTATE_WRAPPER_SOURCE), "-ldl"],
                                capture_output=True, text=True)
        if result.returncode != 0:
            raise UmlUnavailable(f"building {XSTATE_WRAPPER_SOURCE.name} failed: "
                                 f"{result.stderr.strip()[-2000:]}")
        built.replace(library)       # atomic: a concurrent run sees all of it or none
    return library


def _numpy_avx512_features() -> list[str]:
    """numpy's dispatched optimisations that use AVX-512 (it refuses to disable others)."""
    try:
        from numpy._core._multiarray_umath import __cpu_dispatch__
    except ImportError:
        return []
    return [name for name in __cpu_dispatch__ if "AVX512" in name or name == "X86_V4"]


def inner_environment() -> dict[str, str]:
    """The host's environment as the command inside UML gets it: AVX-512 off.

    Where UML's FPU buffer is smaller than the host's XSAVE area (AMX hosts), the
    wrapper keeps UML running, but registers past the buffer are shared between the
    processes inside UML; code using AVX-512 crashes there. The same settings are used
    on every host, so a run on a host without AMX checks what an AMX host runs.
    """
    env = {k: v for k, v in os.environ.items() if k not in _SKIP_ENV and k.isidentifier()}
    env["GLIBC_TUNABLES"] = "glibc.cpu.hwcaps=" + ",".join(f"-{f}" for f in _GLIBC_OFF)
    env["OPENBLAS_CORETYPE"] = "Haswell"
    features = _numpy_avx512_features()
    if features:
        env["NPY_DISABLE_CPU_FEATURES"] = " ".join(features)
    return env


def init_script(command: list[str], vcans: list[str], status_file: Path, cwd: Path) -> str:
    modules = next(p for p in sorted(MODULES.iterdir()) if p.is_dir()) / "kernel"
    exports = "\n".join(f"export {k}={shlex.quote(v)}" for k, v in inner_environment().items())
    links = "\n".join(_link(v) for v in vcans)
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


#: the suffix of a ``--vcan`` that carries classical frames only
CLASSICAL_SUFFIX = "+classic"


def _link(name: str) -> str:
    """``NAME``: a vcan; ``NAME:PEER``: a vxcan pair, whose frames cross from one end to the
    other as a wire's do (a vcan's reach its other sockets as this host's own: python-can
    marks them ``is_rx=False``, and a client that drops its own frames drops them too).
    A vcan comes with CAN FD's MTU (72, ``struct canfd_frame``: 6.1's vcan.c, measured in
    this UML); ``+classic`` after either gives it the classical 16, where the kernel refuses
    an FD frame with EINVAL, as an interface without CAN FD does (Linux's
    Documentation/networking/can.rst, "CAN FD (Flexible Data Rate) Driver Support")."""
    classical = name.endswith(CLASSICAL_SUFFIX)
    name, _, peer = name.removesuffix(CLASSICAL_SUFFIX).partition(":")
    ends = [name, peer] if peer else [name]
    mtu = "".join(f" && ip link set {end} mtu 16" for end in ends) if classical else ""
    up = "".join(f" && ip link set up {end}" for end in ends)
    kind = f"vxcan peer name {peer}" if peer else "vcan"
    return f"ip link add dev {name} type {kind}{mtu}{up}"


def _boot(command: list[str], vcans: list[str], timeout: float, memory: str,
          capture: bool, xstate_log: Path | None = None) -> tuple[int, str]:
    """Boots UML to run ``command``; returns its exit status and, if captured, UML's output."""
    missing = _missing_tools()
    if missing:
        raise UmlUnavailable(missing)
    wrapper = xstate_wrapper()
    with tempfile.TemporaryDirectory(prefix="hil-uml-", dir=Path.cwd()) as folder, \
            tempfile.TemporaryDirectory(prefix="hil-uml-mem-", dir="/dev/shm") as memory_folder:
        folder = Path(folder)
        status_file = folder / "status"
        script = folder / "init.sh"
        script.write_text(init_script(command, vcans, status_file, Path.cwd()))
        script.chmod(0o755)
        uml_home = folder / "uml"      # UML keeps its per-instance files under $HOME/.uml
        uml_home.mkdir()
        kernel = [KERNEL, f"mem={memory}", "root=/dev/root", "rootfstype=hostfs", "rootflags=/",
                  "rw", f"init={script}", "con=null", "con0=fd:0,fd:1", "quiet"]
        env = {**os.environ, "HOME": str(uml_home), "TMPDIR": memory_folder,
               "LD_PRELOAD": str(wrapper)}
        if xstate_log is not None:
            env["HIL_UML_XSTATE_LOG"] = str(xstate_log)
        try:
            result = subprocess.run(kernel, stdin=subprocess.DEVNULL, timeout=timeout, env=env,
                                    capture_output=capture, text=True, errors="replace",
                                    preexec_fn=functools.partial(os.sched_setaffinity, 0,
                                                                 {uml_cpu()}))
        except subprocess.TimeoutExpired as timed_out:
            output = timed_out.stdout or ""
            return 124, output if isinstance(output, str) else output.decode(errors="replace")
        output = result.stdout or ""
        if not status_file.exists():
            return 125, output
        return int(status_file.read_text().strip() or 125), output


@functools.cache
def trial_boot() -> tuple[str | None, str]:
    """Boots ``ip link show vcan0`` for real (about 2-3 s, once per process): whether UML
    runs here (None, or why not) and what the ptrace wrapper saw (UML's FPU buffer size,
    the host's XSAVE size, whether requests were bounced through a full-size buffer)."""
    try:
        with tempfile.TemporaryDirectory() as folder:
            log = Path(folder) / "xstate"
            status, output = _boot(["ip", "link", "show", "vcan0"], ["vcan0"],
                                   TRIAL_BOOT_TIMEOUT, "256M", capture=True, xstate_log=log)
            xstate = log.read_text().strip() if log.exists() else "the wrapper saw no request"
    except UmlUnavailable as missing:
        return str(missing), ""
    if status == 0 and "vcan0" in output:
        return None, xstate
    tail = "\n".join(output.strip().splitlines()[-8:])
    what = {124: f"did not finish within {TRIAL_BOOT_TIMEOUT:g} s",
            125: "crashed before its init script ended"}.get(status, f"exited with {status}")
    return f"a trial boot of User-Mode Linux {what}; its last lines:\n{tail}", xstate


def available() -> str | None:
    """None if UML boots here with vcan, else why not. Finding the programs is not
    enough: a UML that panics at boot is unavailable too (``trial_boot``)."""
    return trial_boot()[0]


def run(command: list[str], vcans: list[str], timeout: float, memory: str = "2G") -> int:
    """Runs ``command`` inside UML with ``vcans`` created; returns its exit status
    (3: UML cannot run here, 124: timed out, 125: no status came back)."""
    try:
        status, _ = _boot(command, vcans, timeout, memory, capture=False)
    except UmlUnavailable as missing:
        print(f"uml_run: cannot run User-Mode Linux: {missing}", file=sys.stderr)
        return 3
    if status == 124:
        print(f"uml_run: the command did not finish within {timeout:g} s", file=sys.stderr)
    elif status == 125:
        print("uml_run: the command left no exit status (UML crashed?)", file=sys.stderr)
    return status


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--check", action="store_true",
                        help="boot a trivial command: exit 0 if UML runs here, else 3 and why")
    parser.add_argument("--vcan", action="append", default=[],
                        help="vcan interface to create (repeatable; default vcan0); "
                             "NAME:PEER creates a vxcan pair instead; each takes CAN FD frames, "
                             "a trailing +classic classical ones only (e.g. vcan2+classic)")
    parser.add_argument("--timeout", type=float, default=600, help="seconds (default 600)")
    parser.add_argument("--memory", default="2G", help="UML memory (default 2G)")
    parser.add_argument("command", nargs=argparse.REMAINDER)
    args = parser.parse_args()
    if args.check:
        missing = available()
        if missing:
            print(f"uml_run: User-Mode Linux cannot run here: {missing}", file=sys.stderr)
            return 3
        print("uml_run: User-Mode Linux boots here with vcan; ptrace xstate:",
              trial_boot()[1].replace("\n", "; "))
        return 0
    command = args.command[1:] if args.command[:1] == ["--"] else args.command
    if not command:
        parser.error("give a command after --")
    return run(command, args.vcan or ["vcan0"], args.timeout, args.memory)


if __name__ == "__main__":
    sys.exit(main())
