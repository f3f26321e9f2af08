#!/bin/sh
# Install LeRobot 0.4.4 into a virtual environment beside hil, for tests/test_lerobot_damiao.py
# (LeRobot's Damiao bus and OpenArm followers, unchanged, against hil's Damiao motors):
#   tools/install_lerobot.sh .venv
# Without its dependencies: LeRobot's own pins (rerun-sdk<0.27, packaging<26, torch<2.11) are
# not hil's, and its motors and robots import only the few named below. lerobot.processor
# imports torchvision at import time, and PyPI's torchvision loads only beside PyPI's torch
# (a CUDA build, which runs on the CPU); datasets 4.3.0 because later ones import what
# huggingface-hub below 0.36 (LeRobot's pin) lacks. docs/protocols/damiao.md, "LeRobot".
set -eu
venv=${1:-.venv}
"$venv/bin/pip" install --quiet torch==2.14.1 torchvision==0.29.1
"$venv/bin/pip" install --quiet --no-deps lerobot==0.4.4
"$venv/bin/pip" install --quiet draccus==0.10.0 'deepdiff>=7.0.1,<9' 'accelerate>=1.10,<2' \
    datasets==4.3.0 'huggingface-hub>=0.34.2,<0.36' tqdm 'av>=15,<16' 'einops>=0.8,<0.9'
