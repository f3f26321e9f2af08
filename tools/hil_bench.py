#!/usr/bin/env python3
"""The same as ``hil bench`` (for running from a checkout): tools/hil_bench.py [--quick]."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from hil.cli import main  # noqa: E402

sys.exit(main(["bench", *sys.argv[1:]]))
