"""Figures about the FE sweep (matplotlib, Agg backend)."""

from __future__ import annotations

from pathlib import Path

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def plot_sweep_map(
    C1: np.ndarray,
    phi: np.ndarray,
    values: np.ndarray,
    path: str | Path,
    label: str,
    failed: np.ndarray | None = None,
    title: str = "",
) -> None:
    """A per-case quantity over the (C1, Φ) plane; failed cases marked with crosses."""
    fig, ax = plt.subplots(figsize=(7, 4.5), constrained_layout=True)
    sc = ax.scatter(phi, C1, c=values, cmap="viridis", s=60, marker="s")
    if failed is not None and np.any(failed):
        ax.scatter(phi[failed], C1[failed], marker="x", color="red", s=60, label="failed")
        ax.legend(loc="upper right")
    fig.colorbar(sc, ax=ax, label=label)
    ax.set_xlabel("gravity angle Φ (deg)")
    ax.set_ylabel("C1 (kPa)")
    if title:
        ax.set_title(title)
    fig.savefig(path, dpi=120)
    plt.close(fig)
