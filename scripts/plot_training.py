#!/usr/bin/python3
"""Training curves of a run: train loss and validation PSNR per epoch, one line per stage
(and K-SVD coding error for a dict stage). Usage: plot_training.py TRAINING.jsonl OUT_STEM
(writes OUT_STEM.png and OUT_STEM.svg). Reads the records `lfnet train` appends to
RUN/training.jsonl; `lfnet report RUN` runs it."""
import json
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def main(path, stem):
    stages = {}
    for line in open(path):
        if not line.strip():
            continue
        entry = json.loads(line)
        stages.setdefault(entry["stage"], []).append(entry["record"])
    networks = {s: r for s, r in stages.items() if r and "epoch" in r[0]}
    fig, (loss_ax, psnr_ax) = plt.subplots(1, 2, figsize=(10, 3.8), dpi=120)
    offset = 0
    for stage, records in networks.items():
        epochs = [offset + r["epoch"] for r in records]
        loss_ax.plot(epochs, [r["train_loss"] for r in records], marker="o", ms=3, label=stage)
        psnr_ax.plot(epochs, [r["val_psnr_db"] for r in records], marker="o", ms=3, label=stage)
        offset = epochs[-1]
    loss_ax.set_yscale("log")
    loss_ax.set_title("training loss")
    loss_ax.set_xlabel("epoch (stages one after another)")
    loss_ax.set_ylabel("loss (log scale)")
    psnr_ax.set_title("validation PSNR")
    psnr_ax.set_xlabel("epoch (stages one after another)")
    psnr_ax.set_ylabel("PSNR (dB)")
    for ax in (loss_ax, psnr_ax):
        ax.grid(True, alpha=0.3)
        if networks:
            ax.legend(title="stage")
    if "dict" in stages:
        its = [r["iteration"] for r in stages["dict"]]
        loss_ax.plot(its, [r["coding_rmse"] for r in stages["dict"]], ls="--", label="dict (K-SVD RMSE)")
        loss_ax.legend(title="stage")
    fig.tight_layout()
    fig.savefig(stem + ".png")
    fig.savefig(stem + ".svg")


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2])
