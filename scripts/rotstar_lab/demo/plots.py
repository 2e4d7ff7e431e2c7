"""The demo's figure: one corner near the image corner at each exposure, rotating-star frame and checkerboard"""

from __future__ import annotations


def exposure_figure(crops: dict, fn: str) -> None:
    """crops: {exposure label: (rotating-star crop, averaged checkerboard crop)}, 16-bit values"""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, len(crops), figsize=(2.2 * len(crops), 4.4), constrained_layout=True)
    for k, (label, (rot, cb)) in enumerate(crops.items()):
        for row, (img, what) in enumerate(((rot, "rotating-star frame 1"), (cb, "checkerboard, 8 averaged"))):
            ax = axes[row, k]
            ax.imshow(img, cmap="gray", vmin=0, vmax=65535, interpolation="nearest")
            ax.set_title(f"{label}\n{what}", fontsize=7)
            ax.axis("off")
    fig.savefig(fn, dpi=110)
    plt.close(fig)
