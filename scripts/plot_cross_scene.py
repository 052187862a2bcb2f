#!/usr/bin/python3
"""Bar chart of the cross-scene benchmark: each method's PSNR margin over pinv, per held-out
light field. Usage: plot_cross_scene.py RECORDS.jsonl OUT_STEM (writes OUT_STEM.png and .svg).
Reads the records that `lfnet evaluate --json` writes (scripts/results.sh cross-scene)."""
import json
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def label(r):
    return r.get("variant") or r["method"]


def main(records_path, stem):
    rows = [json.loads(line) for line in open(records_path) if line.strip()]
    scenes = list(dict.fromkeys(r["light_field"] for r in rows))
    pinv = {r["light_field"]: r["psnr_db"] for r in rows if r["method"] == "pinv" and "variant" not in r}
    series = [s for s in dict.fromkeys(label(r) for r in rows) if s != "pinv"]
    margins = {s: [] for s in series}
    for scene in scenes:
        by = {label(r): r["psnr_db"] for r in rows if r["light_field"] == scene}
        for s in series:
            margins[s].append(by.get(s, float("nan")) - pinv[scene])
    fig, ax = plt.subplots(figsize=(8.5, 4.6), dpi=120)
    width = 0.8 / len(series)
    for i, s in enumerate(series):
        xs = [k + (i - (len(series) - 1) / 2) * width for k in range(len(scenes))]
        ax.bar(xs, margins[s], width, label=s)
        for x, m in zip(xs, margins[s]):
            ax.annotate(f"{m:+.2f}", (x, m), ha="center", va="bottom" if m >= 0 else "top",
                        fontsize=7, xytext=(0, 2 if m >= 0 else -2), textcoords="offset points")
    ax.axhline(0, color="black", linewidth=0.8)
    ax.axhline(1.5, color="grey", linewidth=0.8, linestyle="--", label="target: +1.5 dB")
    ax.set_xticks(range(len(scenes)))
    ax.set_xticklabels(scenes)
    ax.set_ylabel("PSNR margin over pinv (dB)")
    ax.set_title("Cross-scene benchmark: ASP N = 2, stride 5, sensor mode, held-out light fields")
    # Below the axes: inside, it would cover the bars of some light field.
    ax.legend(fontsize=8, ncol=6, loc="upper center", bbox_to_anchor=(0.5, -0.1), frameon=False)
    fig.tight_layout()
    for ext in ("png", "svg"):
        fig.savefig(f"{stem}.{ext}")


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
