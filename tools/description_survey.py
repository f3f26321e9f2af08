"""Load every robot description under some folders as `hil check` would, and say what became
of each: loaded (with how many corrections), refused (the first error, and whether it names
a line), or a bug (a traceback or a time-out, which no description may cause).

    python tools/description_survey.py FOLDER [FOLDER ...] [--package-path DIR ...]

The folders are on the package path too, so `$(find pkg)` and `package://` resolve inside
them. Exit status 1 if any file caused a bug. The survey of public descriptions in the
README (any robot, issue 30) is this tool's output.
"""

from __future__ import annotations

import argparse
import signal
import sys
import traceback
from collections import Counter
from pathlib import Path

from hil.description import PackagePath, load_description
from hil.errors import HilError, Severity
from hil.plant import Plant

#: a description that takes longer than this (s) to load counts as a time-out
TIME_LIMIT = 60


def survey(path: Path, package_path: PackagePath) -> tuple[str, str]:
    """(outcome, detail) for one file: "loaded", "refused" or "bug"."""
    def out_of_time(*_):
        raise TimeoutError(f"no answer in {TIME_LIMIT} s")

    signal.signal(signal.SIGALRM, out_of_time)
    signal.alarm(TIME_LIMIT)
    try:
        robot = load_description(path, package_path)
        Plant(robot)
        movable = len(robot.movable_joints)
        return "loaded", f"{movable} movable joint(s), {len(robot.warnings)} warning(s)"
    except HilError as exc:
        first = next(d for d in exc.diagnostics if d.severity is Severity.ERROR)
        where = f"line {first.line}" if first.line else "no line"
        return "refused", f"[{where}] {first.message.splitlines()[0][:160]}"
    except Exception:           # what the survey is for: no description may do this
        return "bug", traceback.format_exc(limit=3).replace("\n", " | ")[-400:]
    finally:
        signal.alarm(0)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folders", nargs="+", type=Path)
    parser.add_argument("--package-path", action="append", default=[], type=Path)
    args = parser.parse_args()
    package_path = PackagePath(tuple(args.folders) + tuple(args.package_path))
    files = sorted(p for folder in args.folders for p in folder.rglob("*")
                   if p.suffix in (".urdf", ".xacro") and p.is_file())
    outcomes: Counter[str] = Counter()
    lineless = 0
    for path in files:
        outcome, detail = survey(path, package_path)
        outcomes[outcome] += 1
        lineless += outcome == "refused" and "[no line]" in detail
        print(f"{outcome:8s} {path}: {detail}", flush=True)
    print(f"\n{len(files)} file(s): {outcomes['loaded']} loaded, {outcomes['refused']} refused "
          f"({lineless} naming no line), {outcomes['bug']} bug(s)")
    return 1 if outcomes["bug"] else 0


if __name__ == "__main__":
    sys.exit(main())
