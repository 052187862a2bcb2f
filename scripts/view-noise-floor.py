#!/usr/bin/python3
"""How far any reconstruction can rise above pinv on the set light fields whose views carry noise
(docs/protocol.md): the noise a view carries is known to the sensor only through the N values
each pixel measures, so even an oracle that knows the clean light field and adds the noise's
observed part (its per-pixel pseudo-inverse) scores a finite PSNR against the noisy truth.
Prints, per noisy light field of each set, that oracle's PSNR, pinv's and the difference: the
largest margin over pinv that a method can reach there.

    scripts/view-noise-floor.py [SET.json ...]   (default configs/sets/validation.json, test.json)

Needs build/apps/lfnet (LFNET) and python3-torch: it exports models/lfnet-asp-n2.ckpt for the
camera's simulate and per-pixel pseudo-inverse, and makes grey copies of each noisy light field
with and without its noise in a temporary folder."""
import glob
import json
import os
import subprocess
import sys
import tempfile

import imageio
import numpy as np
import torch

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
LFNET = os.environ.get("LFNET", os.path.join(ROOT, "build", "apps", "lfnet"))


def run(*args):
    subprocess.run([LFNET, "--threads", "1", "--log-level", "error", *args], check=True, cwd=ROOT,
                   stdout=subprocess.DEVNULL)


def load(folder):
    views = {}
    for f in glob.glob(os.path.join(folder, "lf_*_*.png")):
        r, c = (int(x) for x in os.path.basename(f)[3:-4].split("_"))
        views[(r, c)] = imageio.imread(f).astype(np.float64) / 65535.0
    rows, cols = max(k[0] for k in views), max(k[1] for k in views)
    grid = [[views[(r, c)] for c in range(1, cols + 1)] for r in range(1, rows + 1)]
    return torch.tensor(np.array(grid), dtype=torch.float32)


def psnr(error):
    return (-10 * torch.log10((error ** 2).mean())).item()


def main():
    sets = sys.argv[1:] or ["configs/sets/validation.json", "configs/sets/test.json"]
    torch.set_num_threads(1)
    with tempfile.TemporaryDirectory() as tmp:
        model = os.path.join(tmp, "asp.pt")
        run("export", "--model", "models/lfnet-asp-n2.ckpt", "--out", model)
        net = torch.jit.load(model)
        print("| light field | oracle PSNR dB | pinv PSNR dB | largest margin over pinv dB |")
        print("|---|---:|---:|---:|")
        for path in sets:
            spec = json.load(open(os.path.join(ROOT, path)))
            pairs = []
            for e in spec["light_fields"]:
                if e.get("view_noise", 0) > 0:
                    clean = dict(e, name=e["name"] + "-clean", view_noise=0, grey=True)
                    pairs += [dict(e, grey=True), clean]
            if not pairs:
                continue
            spec["light_fields"] = pairs
            grey_set = os.path.join(tmp, os.path.basename(path))
            json.dump(spec, open(grey_set, "w"))
            out = os.path.join(tmp, spec["name"])
            run("sets", "make", grey_set, "--out", out)
            for e in pairs[::2]:
                noisy = load(os.path.join(out, e["name"]))
                noise = noisy - load(os.path.join(out, e["name"] + "-clean"))
                with torch.no_grad():
                    observed = net.pixel_pinv_image(net.simulate(noise).unsqueeze(0))[0]
                    pinv = net.pixel_pinv_image(net.simulate(noisy).unsqueeze(0))[0]
                oracle = psnr(noise - observed.reshape(noise.shape))
                base = psnr(pinv.reshape(noise.shape).clamp(0, 1) - noisy)
                print(f"| {e['name']} | {oracle:.2f} | {base:.2f} | {oracle - base:+.2f} |")


if __name__ == "__main__":
    main()
