#!/usr/bin/env bash
# Build hil's wheel, install it into a fresh virtual environment and run `hil check ur3`,
# `hil up pigot --demo --no-viewer --lock-step` and the pytest examples of docs/testing.md (with
# JUnit) from an empty folder: what a user gets from `pip install`, with no checkout in reach.
# The wheel is built from a copy of the tracked files (.ci/run installs hil in the checkout
# meanwhile) and kept in the folder given as the argument, if one is (.ci/run takes its
# compiled modules).
# `hil bench --quick` is tests/test_bench.py's (CI's hosts are slower now: stop 58 took 4,614 s
# of CI's 5,400 before this check's bench had run a fifth). Run from the repository root.
set -euo pipefail
root=$(pwd)
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
python3 -m venv "$work/venv"
"$work/venv/bin/pip" install --quiet --upgrade pip
dist=${1:-$work/dist}
mkdir -p "$work/src" "$dist"
git ls-files -z | xargs -0 cp --parents -t "$work/src"
"$work/venv/bin/pip" wheel --quiet --no-deps --wheel-dir "$dist" "$work/src"
"$work/venv/bin/pip" install --quiet "$dist"/hil-*.whl
mkdir "$work/empty"
cd "$work/empty"
echo "wheel check: $(ls "$dist") in a fresh environment, from an empty folder"
"$work/venv/bin/hil" --version
# every module of hil.compiled's builds runs compiled from the wheel (.ci/run installs a C
# compiler)
compiled=$("$work/venv/bin/python" "$root/tools/compiled_check.py")
echo "wheel check: $compiled"
"$work/venv/bin/hil" check ur3
# lock-step: this checks what the wheel installs; real time is `hil bench`'s to measure (on a
# shared 2-CPU VM a hypervisor stall mid-demo is a silent drive, issue 18)
"$work/venv/bin/hil" up pigot --demo --no-viewer --lock-step
# a user's own tests, as docs/testing.md shows them, with hil's pytest plugin from the wheel
"$work/venv/bin/pip" install --quiet pytest
"$work/venv/bin/python" - "$root/docs/testing.md" <<'PY'
import pathlib, re, sys
page = pathlib.Path(sys.argv[1]).read_text()
examples = [b for b in re.findall(r"```python\n(.*?)```", page, re.DOTALL) if "def test_" in b]
for number, example in enumerate(examples):
    pathlib.Path(f"test_docs_example_{number}.py").write_text(example)
print(f"wheel check: {len(examples)} pytest example(s) of docs/testing.md")
PY
PATH="$work/venv/bin:$PATH" "$work/venv/bin/python" -m pytest -q -p no:cacheprovider \
    --junitxml=report.xml .
grep -q 'failures="0"' report.xml && grep -q 'errors="0"' report.xml
echo "wheel check: passed"
