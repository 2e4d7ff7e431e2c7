"""The benchmark's figure: the cumulative distribution of the corner errors, one curve per method"""

from __future__ import annotations

import numpy as np


def plot_cdf(results: dict[str, list[dict]], titles: dict[str, str], fn: str) -> None:
    """results: method -> pose rows (scoring.pose_row); titles: method -> its name in the legend"""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.2))
    for key, rows in results.items():
        e = np.sort(np.concatenate([r["errors_px"] for r in rows]) if rows else np.empty(0))
        if e.size:
            ax.step(e, np.arange(1, e.size + 1) / e.size, where="post", label=f"{titles[key]} ({e.size})")
    ax.set_xscale("log")
    ax.set_xlabel("corner error against truth, px")
    ax.set_ylabel("fraction of the detected corners")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, loc="upper left")
    ax.set_title("Corner error CDF (correct boards only)", fontsize=10)
    fig.tight_layout()
    fig.savefig(fn, dpi=110)
    plt.close(fig)
