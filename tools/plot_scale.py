"""Plot `hil bench --scale`'s sweep: each process' CPU a cycle against the robot's drives,
hil's own master beside a bare python-can master, one panel per rate, the cycle's period
drawn across (a process above it cannot keep the rate). Writes an SVG for
docs/performance.md.

    python tools/plot_scale.py bench.json -o docs/scale_sweep.svg

A size whose run held the rate has a filled marker, one that did not a hollow one, one that
did not start none (its bare master's figures are drawn all the same). Needs matplotlib.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

#: how each process' line looks: (label, colour, line style)
_LINES = {("hil", "sim"): ("simulator, hil's master", "tab:blue", "-"),
          ("hil", "control"): ("hil control", "tab:orange", "-"),
          ("bare", "sim"): ("simulator, bare master", "tab:blue", ":"),
          ("bare", "control"): ("bare python-can master", "tab:green", ":")}


def series(rows: list[dict], rate: float) -> dict[tuple[str, str], list[tuple[int, float, bool]]]:
    """Per (master, process): (drives, CPU µs a cycle, held) for the rows at ``rate``."""
    found: dict[tuple[str, str], list[tuple[int, float, bool]]] = {}
    for row in sorted((r for r in rows if r["rate_hz"] == rate), key=lambda r: r["drives"]):
        runs = [("hil", row, row.get("holds", False)), ("bare", row.get("bare_master", {}),
                                                        _bare_held(row.get("bare_master", {})))]
        for master, run, held in runs:
            for process, microseconds in run.get("cpu_us_per_cycle", {}).items():
                found.setdefault((master, process), []).append((row["drives"], microseconds,
                                                                held))
    return found


def _bare_held(run: dict) -> bool:
    """Whether the bare master enabled every drive and missed at most 0.1 % of its cycles
    (the bound hil's own rows are held to)."""
    cycles = run.get("cycles", 0)
    return (cycles > 0 and run.get("enabled") == run.get("drives")
            and run.get("missed", 0) <= 0.001 * cycles)


def plot(report: dict, out: Path) -> None:
    import matplotlib                        # noqa: PLC0415 (this tool's only need)

    matplotlib.use("svg")
    import matplotlib.pyplot as plt          # noqa: PLC0415

    plt.rcParams["svg.fonttype"] = "none"    # text stays text: smaller, and searchable
    plt.rcParams["svg.hashsalt"] = "hil"     # the same figures, the same file

    rows = report["scale"]
    rates = sorted({row["rate_hz"] for row in rows})
    figure, axes = plt.subplots(1, len(rates), figsize=(5.5 * len(rates), 4), squeeze=False)
    for ax, rate in zip(axes[0], rates):
        for key, points in series(rows, rate).items():
            label, colour, style = _LINES.get(key, (" ".join(key), "tab:gray", "--"))
            ax.plot([p[0] for p in points], [p[1] for p in points], style, color=colour,
                    label=label)
            for drives, microseconds, held in points:
                ax.plot(drives, microseconds, "o", color=colour,
                        markerfacecolor=colour if held else "white")
        ax.axhline(1e6 / rate, color="black", linewidth=0.8, linestyle="--")
        ax.text(ax.get_xlim()[0], 1e6 / rate, " the period", va="bottom", fontsize=8)
        ax.set_title(f"{rate:g} Hz")
        ax.set_xlabel("drives")
        ax.set_ylabel("CPU a cycle (µs)")
        ax.set_ylim(bottom=0)
        ax.grid(alpha=0.3)
    axes[0][0].legend(fontsize=8)
    figure.tight_layout()
    figure.savefig(out, metadata={"Date": None})


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("report", type=Path, help="hil bench's JSON (with a 'scale' section)")
    parser.add_argument("-o", "--out", type=Path, default=Path("scale_sweep.svg"),
                        help="the SVG to write (default scale_sweep.svg)")
    args = parser.parse_args(argv)
    try:
        report = json.loads(args.report.read_text())
    except (OSError, ValueError) as exc:
        print(f"plot_scale: {args.report}: {exc}", file=sys.stderr)
        return 1
    if not report.get("scale"):
        print(f"plot_scale: {args.report} has no 'scale' rows: run hil bench --scale first",
              file=sys.stderr)
        return 1
    try:
        plot(report, args.out)
    except ModuleNotFoundError:
        print("plot_scale: needs matplotlib (pip install matplotlib)", file=sys.stderr)
        return 1
    print(f"plot_scale: {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
