#!/usr/bin/python3
"""lfnet's figures, drawn with matplotlib (Debian's python3-matplotlib): PNG for the Markdown and
SVG beside it (the vector twin), from the JSON that `lfnet report` writes.

Usage:
  figures.py SPEC.json               every figure of a spec: {"figures": [{"kind": ..., ...}]}
  figures.py training LOG.jsonl STEM training curves of a run (RUN/training.jsonl)

Kinds of a spec (each has "stem": the output path without extension, relative to the spec file's
folder, and "title"; image paths in a spec are relative to that folder too):
  pareto    points [{method, variant, n, stride, whole_image, seconds, psnr_db, front}], xlabel
  heatmaps  panels [{label, psnr}] of U x V per-view PSNR, one shared colour range
  views     panels [{label, psnr_db, view, epi}] (16-bit PNG crops); the first is the truth
  sweep     series [{label, method, x, y, kind: ours|paper|baseline}], xlabel, xlog
  weights   tiles [rows][columns][h][w] in [0, 1] of a camera's code, signed, wrapped, wrap
  margins   records (lfnet evaluate records), over (the baseline method), over_variant (its
            variant, "" none), series (the series drawn, [] all), target (dB)
"""
import json
import math
import os
import sys

import matplotlib

matplotlib.use("Agg")
matplotlib.rcParams["svg.hashsalt"] = "lfnet"  # the same data gives the same SVG
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from PIL import Image  # noqa: E402

# One colour per method in every figure, by the method's place in lfnet's method registry (the
# spec's "methods": net, ae, cnn, dict, pinv, pinv-nlm, adjoint, no-parallax for the built-ins,
# then any registered later); no-parallax, the truth's angular mean, is black. Variants (a
# second model of one method) take the spare colours.
REGISTRY_PALETTE = ["C0", "C2", "C1", "C4", "C3", "C5", "C7", "C6", "C8", "C9"]
METHOD_COLOURS = {}
SPARE_COLOURS = ["#1b9e77", "#d95f02", "#7570b3", "#e7298a", "#66a61e", "#e6ab02", "#a6761d",
                 "#666666", "#1f78b4", "#fb9a99"]


def set_method_colours(methods):
    """Colours for the registered methods, in registry order."""
    METHOD_COLOURS.clear()
    for i, m in enumerate(methods):
        METHOD_COLOURS[m] = "black" if m == "no-parallax" else REGISTRY_PALETTE[i % len(REGISTRY_PALETTE)]


set_method_colours(["net", "ae", "cnn", "dict", "pinv", "pinv-nlm", "adjoint", "no-parallax"])
MARKERS = ["o", "s", "^", "D", "v", "P", "X", "*"]
ERROR_MAX = 0.1  # |error| at the top of every error map's colour bar


class Colours:
    def __init__(self):
        self.extra = {}

    def __call__(self, series):
        if series in METHOD_COLOURS:
            return METHOD_COLOURS[series]
        if series not in self.extra:
            self.extra[series] = SPARE_COLOURS[len(self.extra) % len(SPARE_COLOURS)]
        return self.extra[series]


def save(fig, stem):
    stem = os.path.join(BASE, stem)
    fig.savefig(stem + ".png", bbox_inches="tight")
    fig.savefig(stem + ".svg", bbox_inches="tight", metadata={"Date": None})
    plt.close(fig)


def series_name(p):
    """A method, or a method and its variant: "net (paper scale)"."""
    return f"{p['method']} ({p['variant']})" if p.get("variant") else p["method"]


def pareto(spec):
    """PSNR against seconds (log): colour = method (or variant), marker = camera (N), the
    stride written beside each point; the front is a black step line through ringed points."""
    points = [p for p in spec["points"] if p.get("psnr_db") is not None]
    colour = Colours()
    ns = sorted({p["n"] for p in points})
    marker = {n: MARKERS[i % len(MARKERS)] for i, n in enumerate(ns)}
    strides = {p["stride"] for p in points if not p.get("whole_image")}
    fig, ax = plt.subplots(figsize=(11, 6), dpi=120)
    seconds = [p["seconds"] for p in points if p["seconds"] > 0]
    x_floor = min(seconds) / 2 if seconds else 1e-3
    # A far outlier (more than 5 dB above every other point) is pinned to the top edge.
    psnr = sorted(p["psnr_db"] for p in points)
    y_top = psnr[-1]
    for k in range(len(psnr) - 1, 0, -1):
        if psnr[k] - psnr[k - 1] <= 5:
            break
        y_top = psnr[k - 1]
    y_bottom = psnr[0]
    pad = 0.06 * max(y_top - y_bottom, 1)
    for p in points:
        x = max(p["seconds"], x_floor)
        y = min(p["psnr_db"], y_top + pad / 2)
        ax.scatter(x, y, s=60 if p.get("front") else 36, marker=marker[p["n"]],
                   color=colour(series_name(p)), edgecolors="black" if p.get("front") else "none",
                   linewidths=1.2, zorder=3)
        notes = []
        if p.get("whole_image"):
            notes.append("whole")
        elif len(strides) > 1:
            notes.append(f"s{p['stride']}")
        if p["psnr_db"] > y_top + pad / 2:
            notes.append(f"↑ {p['psnr_db']:.1f} dB")
        if p["seconds"] <= 0:
            notes.append(f"< {x_floor:.2g} s")
        if notes:
            ax.annotate(" ".join(notes), (x, y), xytext=(5, 3), textcoords="offset points",
                        fontsize=7, color="0.3")
    front = sorted((p for p in points if p.get("front")), key=lambda p: p["seconds"])
    if front:
        ax.step([max(p["seconds"], x_floor) for p in front],
                [min(p["psnr_db"], y_top + pad / 2) for p in front], where="post",
                color="black", linestyle="--", linewidth=1, zorder=2)
    ax.set_xscale("log")
    ax.set_ylim(y_bottom - pad, y_top + pad)
    ax.set_xlabel(spec.get("xlabel", "reconstruction time (s, log scale)"))
    ax.set_ylabel("PSNR (dB)")
    ax.set_title(spec["title"])
    ax.grid(True, which="both", alpha=0.25)
    methods = list(dict.fromkeys(series_name(p) for p in points))
    method_handles = [Line2D([], [], marker="o", linestyle="", color=colour(m), label=m)
                      for m in methods]
    method_handles.append(Line2D([], [], color="black", linestyle="--", marker="o",
                                 markerfacecolor="white", label="Pareto front"))
    camera_handles = [Line2D([], [], marker=marker[n], linestyle="", color="0.4", label=f"N = {n}")
                      for n in ns]
    # Legends in a column of their own to the right of the axes.
    fig.subplots_adjust(left=0.07, right=0.7, top=0.93, bottom=0.1)
    fig.legend(handles=method_handles, title="method", fontsize=8, loc="upper left",
               bbox_to_anchor=(0.71, 0.93))
    camera_title = "camera" + ("\n(sK beside a point:\npatch stride K;\nwhole: no patches)"
                               if len(strides) > 1 else "")
    fig.legend(handles=camera_handles, title=camera_title, fontsize=8, title_fontsize=8,
               loc="lower left", bbox_to_anchor=(0.71, 0.1))
    save(fig, spec["stem"])


def heatmaps(spec):
    """Per-view PSNR of several methods side by side on one colour range, with one colour bar."""
    panels = spec["panels"]
    values = [np.array([[np.nan if x is None else x for x in row] for row in p["psnr"]], float)
              for p in panels]
    lo = min(np.nanmin(v) for v in values)
    hi = max(np.nanmax(v) for v in values)
    if hi - lo < 0.1:
        lo, hi = lo - 0.05, hi + 0.05
    fig, axes = plt.subplots(1, len(panels), figsize=(2.9 * len(panels) + 1.2, 3.3), dpi=120,
                             squeeze=False)
    for ax, p, v in zip(axes[0], panels, values):
        image = ax.imshow(v, cmap="viridis", vmin=lo, vmax=hi)
        for (u, w), x in np.ndenumerate(v):
            ax.text(w, u, "inf" if np.isnan(x) else f"{x:.1f}", ha="center", va="center",
                    fontsize=7, color="black" if (x - lo) / (hi - lo) > 0.6 else "white")
        ax.set_xticks(range(v.shape[1]), [str(i + 1) for i in range(v.shape[1])])
        ax.set_yticks(range(v.shape[0]), [str(i + 1) for i in range(v.shape[0])])
        ax.set_xlabel("view column v")
        if ax is axes[0][0]:
            ax.set_ylabel("view row u")
        ax.set_title(f"{p['label']}\nmean of the views {np.nanmean(v):.2f} dB", fontsize=9)
    bar = fig.colorbar(image, ax=axes[0].tolist(), shrink=0.85)
    bar.set_label("PSNR (dB)")
    fig.suptitle(spec["title"], fontsize=10)
    save(fig, spec["stem"])


BASE = ""  # the spec file's folder: relative stems and image paths are read from it


def read_png(path):
    """A 16-bit (or 8-bit) grey PNG as floats in [0, 1]."""
    a = np.asarray(Image.open(os.path.join(BASE, path)))
    return a.astype(np.float64) / (65535.0 if a.dtype == np.uint16 or a.max() > 255 else 255.0)


def views(spec):
    """Centre views, horizontal EPIs and |error| maps (one colour range, one bar); the first
    panel is the truth (no error map of its own)."""
    panels = spec["panels"]
    truth_view = read_png(panels[0]["view"])
    n = len(panels)
    fig = plt.figure(figsize=(2.6 * n + 0.8, 6.4), dpi=120)
    grid = fig.add_gridspec(3, n + 1, height_ratios=[1, 0.5, 1], width_ratios=[1] * n + [0.06])
    error_image = None
    for i, p in enumerate(panels):
        view, epi = read_png(p["view"]), read_png(p["epi"])
        title = p["label"] if p.get("psnr_db") is None else f"{p['label']}\n{p['psnr_db']:.2f} dB"
        ax = fig.add_subplot(grid[0, i])
        ax.imshow(view, cmap="gray", vmin=0, vmax=1)
        ax.set_title(title, fontsize=9)
        ax.set_axis_off()
        ax = fig.add_subplot(grid[1, i])
        ax.imshow(epi, cmap="gray", vmin=0, vmax=1, aspect="auto", interpolation="nearest")
        ax.set_xticks([])
        ax.set_yticks([])
        if i == 0:
            ax.set_ylabel("EPI (v)", fontsize=8)
            ax = fig.add_subplot(grid[2, i])
            ax.text(0.5, 0.5, "|estimate - truth|\nof the centre view\nbelow each method",
                    ha="center", va="center", fontsize=8, transform=ax.transAxes)
            ax.set_axis_off()
            continue
        ax = fig.add_subplot(grid[2, i])
        error_image = ax.imshow(np.abs(view - truth_view), cmap="viridis", vmin=0, vmax=ERROR_MAX)
        ax.set_axis_off()
    if error_image is not None:
        bar = fig.colorbar(error_image, cax=fig.add_subplot(grid[2, n]))
        bar.set_label(f"|error|, clipped at {ERROR_MAX}", fontsize=8)
    fig.suptitle(spec["title"], fontsize=10)
    fig.tight_layout()
    save(fig, spec["stem"])


def sweep(spec):
    """PSNR against one setting: our methods as solid lines, the paper's numbers dashed with open
    markers in the same colour, baselines thin."""
    colour = Colours()
    fig, ax = plt.subplots(figsize=(7.5, 4.4), dpi=120)
    for s in spec["series"]:
        kind = s.get("kind", "ours")
        c = colour(s["method"] if kind == "paper" else s["label"])
        style = {"ours": dict(linestyle="-", marker="o", linewidth=1.8),
                 "paper": dict(linestyle="--", marker="s", markerfacecolor="white", linewidth=1.2),
                 "baseline": dict(linestyle=":", marker=".", linewidth=1.2)}[kind]
        ax.plot(s["x"], s["y"], color=c, label=s["label"], **style)
    if spec.get("xlog"):
        ax.set_xscale("log")
    xs = sorted({x for s in spec["series"] for x in s["x"]})
    if len(xs) <= 8:
        ax.set_xticks(xs, [f"{x:g}" for x in xs])
    ax.set_xlabel(spec["xlabel"])
    ax.set_ylabel("PSNR (dB)")
    ax.set_title(spec["title"], fontsize=10)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1))
    fig.tight_layout()
    save(fig, spec["stem"])


def weights(spec):
    """A camera's code: one tile per (pixel, measurement) showing measurement n's weight on each
    view (u down, v across); rows are the first pixels of the sensor's top row (or every pixel of
    a small period, `pixels` giving each row's (y, x)), unless one pixel's measurements are
    wrapped into rows."""
    tiles = np.array(spec["tiles"], dtype=float)  # (rows, columns, h, w)
    rows, cols = tiles.shape[:2]
    size = 1.15 if tiles.shape[2] <= 9 else 1.6
    height = size * rows + 1.2
    fig, axes = plt.subplots(rows, cols, figsize=(size * cols + 1.6, height), dpi=120,
                             squeeze=False)
    fig.subplots_adjust(top=1 - 0.8 / height)  # room for the two lines of the title
    signed = spec.get("signed", False)
    cmap = "gray"  # signed weights: 0.5 (mid grey) is zero
    for i in range(rows):
        for j in range(cols):
            ax = axes[i][j]
            n = i * spec["wrap"] + j if spec.get("wrapped") else j
            if spec.get("wrapped") and n >= spec["measurements"]:
                ax.set_axis_off()
                continue
            image = ax.imshow(tiles[i, j], cmap=cmap, vmin=0, vmax=1, interpolation="nearest")
            ax.set_xticks([])
            ax.set_yticks([])
            if spec.get("wrapped"):
                ax.set_title(f"n = {n + 1}", fontsize=8)
            elif i == 0:
                ax.set_title(f"n = {j + 1}", fontsize=8)
            if not spec.get("wrapped") and j == 0:
                pixels = spec.get("pixels") or [[0, k] for k in range(rows)]
                y, x = pixels[i]
                two_d = any(q[0] != 0 for q in pixels)
                ax.set_ylabel(f"pixel (y, x) = ({y}, {x})" if two_d else f"pixel x = {x}",
                              fontsize=8)
    bar = fig.colorbar(image, ax=axes.ravel().tolist(), shrink=0.8)
    if signed:
        bar.set_ticks([0, 0.5, 1], labels=["-max |w|", "0", "+max |w|"])
    else:
        bar.set_ticks([0, 0.5, 1], labels=["0", "0.5", "max"])
    bar.set_label("weight", fontsize=8)
    what = (f"each tile: {spec['views']} views, u down, v across" if not spec.get("block") else
            f"each tile: {spec['views']} views of the {spec['block']} x {spec['block']} block")
    fig.suptitle(f"{spec['title']}\n({what})", fontsize=9)
    save(fig, spec["stem"])


def training(log_path, stem):
    """Training loss and validation PSNR per epoch, the stages one after another (and K-SVD
    coding error for a dict stage)."""
    stages = {}
    for line in open(log_path):
        if line.strip():
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
    loss_ax.set_ylabel("loss (log scale)")
    psnr_ax.set_title("validation PSNR")
    psnr_ax.set_ylabel("PSNR (dB)")
    if "dict" in stages:
        its = [r["iteration"] for r in stages["dict"]]
        loss_ax.plot(its, [r["coding_rmse"] for r in stages["dict"]], ls="--",
                     label="dict (K-SVD RMSE)")
    for ax in (loss_ax, psnr_ax):
        ax.set_xlabel("epoch (stages one after another)")
        ax.grid(True, alpha=0.3)
        if networks or "dict" in stages:
            ax.legend(title="stage")
    fig.tight_layout()
    save(fig, stem)


def margins(spec):
    """Each method's PSNR margin over a baseline (pinv; of the variant over_variant, if given)
    per light field: the cross-scene benchmark, with its target as a dashed line. `series`, if
    given, names the series drawn (method, or "method (variant)")."""
    rows = spec["records"]
    over = spec.get("over", "pinv")
    over_variant = spec.get("over_variant") or ""
    scenes = list(dict.fromkeys(r["light_field"] for r in rows))
    base = {r["light_field"]: r["psnr_db"] for r in rows
            if r["method"] == over and (r.get("variant") or "") == over_variant}
    baseline = f"{over} ({over_variant})" if over_variant else over
    series = [s for s in dict.fromkeys(series_name(r) for r in rows) if s != baseline]
    if spec.get("series"):
        series = [s for s in spec["series"] if s in series]
    colour = Colours()
    fig, ax = plt.subplots(figsize=(8.5, 4.6), dpi=120)
    width = 0.8 / max(len(series), 1)
    for i, s in enumerate(series):
        by = [{series_name(r): r["psnr_db"] for r in rows if r["light_field"] == sc}.get(s, math.nan)
              - base.get(sc, math.nan) for sc in scenes]
        xs = [k + (i - (len(series) - 1) / 2) * width for k in range(len(scenes))]
        ax.bar(xs, by, width, label=s, color=colour(s))
        for x, m in zip(xs, by):
            if not math.isnan(m):
                ax.annotate(f"{m:+.2f}", (x, m), ha="center", va="bottom" if m >= 0 else "top",
                            fontsize=7, xytext=(0, 2 if m >= 0 else -2),
                            textcoords="offset points")
    ax.axhline(0, color="black", linewidth=0.8)
    if spec.get("target") is not None:
        ax.axhline(spec["target"], color="grey", linewidth=0.8, linestyle="--",
                   label=f"target: {spec['target']:+g} dB")
    ax.set_xticks(range(len(scenes)), scenes)
    ax.set_xlabel("held-out light field")
    ax.set_ylabel(f"PSNR margin over {baseline} (dB)")
    ax.set_title(spec["title"], fontsize=10)
    ax.legend(fontsize=8, ncol=4, loc="upper center", bbox_to_anchor=(0.5, -0.14), frameon=False)
    save(fig, spec["stem"])


KINDS = {"pareto": pareto, "heatmaps": heatmaps, "views": views, "sweep": sweep,
         "weights": weights, "margins": margins}


def main(argv):
    global BASE
    if len(argv) == 2 and argv[1].endswith(".json"):
        BASE = os.path.dirname(argv[1])
        with open(argv[1]) as f:
            spec = json.load(f)
        if "methods" in spec:
            set_method_colours(spec["methods"])
        for figure in spec["figures"]:
            if figure["kind"] not in KINDS:
                sys.exit(f"figures.py: unknown figure kind '{figure['kind']}'")
            KINDS[figure["kind"]](figure)
        return
    if len(argv) == 4 and argv[1] == "training":
        training(argv[2], argv[3])
        return
    sys.exit(__doc__)


if __name__ == "__main__":
    main(sys.argv)
