"""Draw docs/images/teach-scale.png (time and peak memory of `proposed` against the number
of instances, 1 and 2 local workers) from the figures `bench/bench_scale.py --json` keeps.

    .venv/bin/python bench/bench_scale.py --json docs/images/teach-scale.json   # minutes
    .venv/bin/python bench/plot_scale.py docs/images/teach-scale.json           # a second

Not part of scripts/docs_images.py: the measurements take many minutes and depend on what
else runs on the machine, so they are kept as JSON next to the picture.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def plot(figures: list[dict], out: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    fig, (ax_t, ax_m) = plt.subplots(1, 2, figsize=(9, 3.6), constrained_layout=True)
    for workers, marker in ((1, "o"), (2, "s")):
        rows = sorted((r for r in figures if r["backend"] == "local"
                       and r["workers"] == workers), key=lambda r: r["instances"])
        if not rows:
            continue
        n = [r["instances"] for r in rows]
        label = f"{workers} local worker{'s' if workers > 1 else ''}"
        ax_t.plot(n, [r["seconds"] for r in rows], marker=marker, label=label)
        ax_m.plot(n, [r["peak_rss_total_mb"] for r in rows], marker=marker,
                  label=f"{label} (all processes)")
        if workers > 1:
            ax_m.plot(n, [r["peak_rss_main_mb"] for r in rows], marker=marker, ls="--",
                      label=f"{label} (main process)")
    ax_t.set_yscale("log")
    ax_t.yaxis.set_major_formatter(matplotlib.ticker.ScalarFormatter())
    ax_m.set_ylim(bottom=0, top=1.1 * max(r["peak_rss_total_mb"] for r in figures))
    for ax, title, unit in ((ax_t, "time", "seconds"), (ax_m, "peak memory", "MB (RSS)")):
        ax.set_xscale("log", base=2)
        ax.set_xlabel("instances")
        ax.set_ylabel(unit)
        ax.set_title(f"teach(..., 'proposed'): {title}")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle("random gridworlds: 8 x 8 / 4 features up to 256 instances, then "
                 "10 x 10 / 5 features", fontsize=9)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def main() -> None:
    src = Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT / "docs/images/teach-scale.json"
    out = Path(sys.argv[2]) if len(sys.argv) > 2 else src.with_suffix(".png")
    print(plot(json.loads(src.read_text()), out))


if __name__ == "__main__":
    main()
