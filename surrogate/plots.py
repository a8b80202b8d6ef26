"""Figures about the surrogate (matplotlib, Agg backend)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def plot_history(history: list[dict[str, Any]], path: str | Path, title: str = "") -> None:
    """Training and validation loss, and the validation error in mm, per epoch."""
    epochs = [h["epoch"] for h in history]
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 3.8), constrained_layout=True)
    ax1.semilogy(epochs, [h["train_loss"] for h in history], label="training")
    ax1.semilogy(epochs, [h["validation_loss"] for h in history], label="validation")
    ax1.set_xlabel("epoch")
    ax1.set_ylabel("loss (Eq. 2, per sample, scaled units)")
    ax1.legend()
    ax2.semilogy(epochs, [h["validation_error_mm"] for h in history], color="C2")
    ax2.set_xlabel("epoch")
    ax2.set_ylabel("validation error (mean |u - û|, mm)")
    if title:
        fig.suptitle(title)
    fig.savefig(path, dpi=120)
    plt.close(fig)
