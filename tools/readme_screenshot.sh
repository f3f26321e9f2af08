#!/usr/bin/env bash
# The README's picture of the viewer, taken for real: `hil up pigot --demo` records a run, and
# rerun's viewer, headless (its offscreen harness on Mesa's software Vulkan: Mesa's GL lacks a
# render format rerun needs), opens that recording, lays out its blueprint, waits out its
# start-up notices and saves a screenshot, scaled to 1600x900. Needs the apt package
# mesa-vulkan-drivers. Writes docs/viewer.png (or $1).
# Run from the repository root with hil installed (.venv/bin on PATH or given as HIL_BIN).
set -euo pipefail
bin=$(realpath "${HIL_BIN:-.venv/bin}")
out=$(realpath -m "${1:-docs/viewer.png}")
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
(cd "$work" && "$bin/hil" up pigot --demo --no-viewer --save "$work/run.rrd")
WGPU_BACKEND=vulkan "$bin/python" - "$work/run.rrd" "$work/shot.png" "$bin/rerun" <<'EOF'
import sys, time
from rerun.experimental import ViewerClient
recording, shot, viewer = sys.argv[1:4]
client = ViewerClient.spawn(headless=True, hide_welcome_screen=True, executable_path=viewer)
try:
    client.open(recording)
    time.sleep(20)          # the layout settles and the viewer's start-up notices fade
    client.save_screenshot(shot)
finally:
    client.quit()
EOF
"$bin/python" -c "import sys; from PIL import Image
Image.open(sys.argv[1]).convert('RGB').resize((1600, 900)).save(sys.argv[2], optimize=True)" \
    "$work/shot.png" "$out"
echo "screenshot: $out"
