#!/usr/bin/env python3
"""Where a reconstruction puts a thin bright bar, view by view, against the truth.

    lfnet render --scene configs/scenes/heldout_wide.json --grey --bits 16 --out T
    lfnet evaluate --model M --scene configs/scenes/heldout_wide.json --mode sensor --out R
    scripts/bar-parallax.py --truth T R [R2 ...]

For each folder: the bar's centre in every view of the centre row (a vertical bar moves with
horizontal parallax) or column (a horizontal bar, --horizontal), as the centroid of the
brightness above the region's median; the slope of those centres against the view offset is
the bar's parallax in px per view step. Also the PSNR of the whole light field and without the
bar's band (--exclude). The defaults are the mullion of heldout_window / heldout_wide
(docs/architectures.md).
"""
import argparse
import glob
import os
import re

import numpy as np
from skimage import io


def load(folder):
    """The light field of an lfnet folder (lf_R_C.png) as a (U, V, H, W) luma array in [0, 1]."""
    views = {}
    for path in glob.glob(os.path.join(folder, "lf_*_*.png")):
        m = re.fullmatch(r"lf_(\d+)_(\d+)\.png", os.path.basename(path))
        if m:
            views[(int(m.group(1)), int(m.group(2)))] = path
    if not views:
        raise SystemExit(f"bar-parallax: {folder} holds no lf_R_C.png views")
    rows = max(r for r, _ in views)
    cols = max(c for _, c in views)
    out = []
    for r in range(1, rows + 1):
        row = []
        for c in range(1, cols + 1):
            raw = io.imread(views[(r, c)])
            a = raw.astype(np.float64) / (65535.0 if raw.dtype == np.uint16 else 255.0)
            if a.ndim == 3:
                a = a[..., :3].mean(-1)
            row.append(a)
        out.append(np.stack(row))
    return np.stack(out)


def centres(lf, region, horizontal):
    """The bar's centre in each view of the centre row (or column)."""
    y0, y1, x0, x1 = region
    u, v = lf.shape[0], lf.shape[1]
    result = []
    for k in range(v if not horizontal else u):
        view = lf[u // 2, k] if not horizontal else lf[k, v // 2]
        patch = view[y0:y1, x0:x1]
        profile = patch.mean(0) if not horizontal else patch.mean(1)
        weight = np.clip(profile - np.median(profile), 0, None) ** 2
        positions = np.arange(x0, x1) if not horizontal else np.arange(y0, y1)
        result.append(float((weight * positions).sum() / max(weight.sum(), 1e-12)))
    return np.array(result)


def psnr(a, b, mask=None):
    e = (a - b) ** 2
    if mask is not None:
        e = e[..., mask]
    return 10 * np.log10(1.0 / e.mean())


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--truth", required=True, help="the true light field's folder")
    p.add_argument("folders", nargs="+", help="reconstructions (lfnet evaluate --out)")
    p.add_argument("--region", default="170:230,305:360", help="Y0:Y1,X0:X1 around the bar")
    p.add_argument("--horizontal", action="store_true", help="a horizontal bar")
    p.add_argument("--exclude", default="315:346", help="X0:X1 (Y0:Y1 with --horizontal): the bar's band")
    args = p.parse_args()
    ys, xs = args.region.split(",")
    region = [int(t) for t in ys.split(":") + xs.split(":")]
    e0, e1 = (int(t) for t in args.exclude.split(":"))
    truth = load(args.truth)
    mask = np.ones(truth.shape[2:], bool)
    if args.horizontal:
        mask[e0:e1, :] = False
    else:
        mask[:, e0:e1] = False
    offsets = np.arange(truth.shape[1 if not args.horizontal else 0]) - (
        truth.shape[1 if not args.horizontal else 0] // 2)
    print("| light field | bar centres (px) | parallax (px per view step) | PSNR dB | without the band |")
    print("|---|---|---:|---:|---:|")
    for name, lf in [(args.truth, truth)] + [(f, load(f)) for f in args.folders]:
        if lf.shape != truth.shape:
            raise SystemExit(f"bar-parallax: {name} is {lf.shape}, the truth {truth.shape}")
        c = centres(lf, region, args.horizontal)
        slope = np.polyfit(offsets, c, 1)[0]
        whole = "—" if lf is truth else f"{psnr(lf, truth):.2f}"
        part = "—" if lf is truth else f"{psnr(lf, truth, mask):.2f}"
        print(f"| {name} | {' '.join(f'{x:.1f}' for x in c)} | {slope:+.2f} | {whole} | {part} |")


if __name__ == "__main__":
    main()
