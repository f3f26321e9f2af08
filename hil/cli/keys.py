"""``hil keys init DIR``: the certificate authority and role certificates of ``--secure``."""

from __future__ import annotations

import argparse
from pathlib import Path

from hil.zenoh_security import CA_KEY, ROLES, make_keys


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.description = (
        "Make a certificate authority and a certificate per role in DIR for --secure: mutual "
        "TLS between hil's processes, each process refusing what its peer's role may not do. "
        "Roles: " + "; ".join(f"{role} ({commands})" for role, commands in ROLES.items())
        + ". drives and controller may do everything; operator everything but put CAN frames; "
        "observer only subscribes (no frames, goals, cancels, resets or publications). Copy DIR "
        f"to every host, without {CA_KEY} (it signs new certificates; keep it offline).")
    parser.add_argument("action", choices=["init"], help="init: make the keys")
    parser.add_argument("folder", type=Path, metavar="DIR", help="where to write them")


def run(args: argparse.Namespace) -> int:
    written = make_keys(args.folder)
    print(f"hil keys: wrote {len(written)} files to {args.folder}: "
          + ", ".join(p.name for p in written))
    print(f"hil keys: start each process with --secure {args.folder}; keep {CA_KEY} off the "
          "hosts that run hil")
    return 0
