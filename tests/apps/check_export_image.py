"""Runs a file `lfnet export` wrote from a net of the lfnet architecture with Python's torch and
compares it with reference outputs.

usage: check_export_image.py MODEL.pt DIR

DIR holds raw little-endian float32 arrays and reference.json with their shapes, the tile and
the noise sigma: sensor.f32 (N, H, W); whole.f32 (1, U, V, H, W), the checkpoint's
forward_image of the whole sensor image; tiled.f32 (1, U, V, H, W), lfnet's tiled
reconstruction (unclamped); lf.f32 (U, V, H, W) and simulated.f32 (N, H, W), a light field and
its sensor image. Prints one JSON object with the largest differences.
"""
import json
import os
import sys

import numpy as np
import torch


def read(folder, name, shape):
    data = np.fromfile(os.path.join(folder, name), dtype=np.float32)
    return torch.from_numpy(data.reshape(shape))


def main():
    model_path, folder = sys.argv[1], sys.argv[2]
    with open(os.path.join(folder, "reference.json")) as f:
        ref = json.load(f)
    shapes = ref["shapes"]
    model = torch.jit.load(model_path)
    sensor = read(folder, "sensor.f32", shapes["sensor"])
    whole = read(folder, "whole.f32", shapes["whole"])
    tiled = read(folder, "tiled.f32", shapes["tiled"])
    lf = read(folder, "lf.f32", shapes["lf"])
    simulated = read(folder, "simulated.f32", shapes["simulated"])
    sigma = ref["noise_sigma"]
    with torch.no_grad():
        got_whole = model(sensor.unsqueeze(0), 0, sigma)
        got_tiled = model.reconstruct(sensor, tile=ref["tile"], clamp=False, noise_sigma=sigma)
        got_sim = model.simulate(lf)
    print(json.dumps({
        "torch_version": torch.__version__,
        "forward_max_diff": float((got_whole - whole).abs().max()),
        "reconstruct_max_diff": float((got_tiled - tiled[0]).abs().max()),
        "simulate_max_diff": float((got_sim - simulated).abs().max()),
        "output_shape": list(got_tiled.shape),
        "noise_input": bool(model.noise_input),
    }))


if __name__ == "__main__":
    main()
