#!/usr/bin/env bash
# The README's picture of the viewer, taken for real: `hil up pigot --demo` records a run, and
# rerun's native viewer opens that recording on a virtual display (Xvfb, Mesa's software
# Vulkan: Mesa's GL lacks a render format rerun needs) and saves a screenshot, scaled to
# 1600x1000. Needs the apt packages xvfb and mesa-vulkan-drivers. Writes docs/viewer.png (or $1).
# Run from the repository root with hil installed (.venv/bin on PATH or given as HIL_BIN).
set -euo pipefail
bin=$(realpath "${HIL_BIN:-.venv/bin}")
out=$(realpath -m "${1:-docs/viewer.png}")
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
(cd "$work" && "$bin/hil" up pigot --demo --no-viewer --save "$work/run.rrd")
# the viewer lays out the recording's blueprint, then saves the window and quits
xvfb-run --auto-servernum --server-args="-screen 0 1600x1000x24" \
    "$bin/rerun" "$work/run.rrd" --renderer vulkan --window-size 1600x1000 \
    --screenshot-to "$work/shot.png"
"$bin/python" -c "import sys; from PIL import Image
Image.open(sys.argv[1]).convert('RGB').resize((1600, 1000)).save(sys.argv[2], optimize=True)" \
    "$work/shot.png" "$out"
echo "screenshot: $out"
