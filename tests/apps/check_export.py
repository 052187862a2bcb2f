"""Runs a file `lfnet export` wrote with Python's torch and compares it with reference outputs.

usage: check_export.py MODEL.pt DIR

DIR holds raw little-endian arrays and reference.json with their shapes:
  y.f32 (B, N h w), phase.i64 (B), want.f32 (B, U, V, h, w): patches and the checkpoint's output;
  sensor.f32 (N, H, W), recon.f32 (U, V, H, W): a sensor image and lfnet's reconstruction of it
  at reference.json's stride (unclamped);
  lf.f32 (U, V, H, W), simulated.f32 (N, H, W): a light field and its sensor image.
Prints one JSON object with the largest differences and what the file says about itself.
"""
import json
import os
import sys

import numpy as np
import torch


def read(folder, name, shape, dtype):
    data = np.fromfile(os.path.join(folder, name), dtype=dtype)
    return torch.from_numpy(data.reshape(shape))


def main():
    model_path, folder = sys.argv[1], sys.argv[2]
    with open(os.path.join(folder, "reference.json")) as f:
        ref = json.load(f)
    extra = {"lfnet.json": ""}
    model = torch.jit.load(model_path, _extra_files=extra)
    metadata = json.loads(extra["lfnet.json"])
    shapes = ref["shapes"]
    y = read(folder, "y.f32", shapes["y"], np.float32)
    phase = read(folder, "phase.i64", shapes["phase"], np.int64)
    want = read(folder, "want.f32", shapes["want"], np.float32)
    sensor = read(folder, "sensor.f32", shapes["sensor"], np.float32)
    recon = read(folder, "recon.f32", shapes["recon"], np.float32)
    lf = read(folder, "lf.f32", shapes["lf"], np.float32)
    simulated = read(folder, "simulated.f32", shapes["simulated"], np.float32)
    with torch.no_grad():
        got = model(y, phase)
        rec = model.reconstruct(sensor, stride=ref["stride"], clamp=False)
        sim = model.simulate(lf)
    result = {
        "torch_version": torch.__version__,
        "forward_max_diff": float((got - want).abs().max()),
        "reconstruct_max_diff": float((rec - recon).abs().max()),
        "simulate_max_diff": float((sim - simulated).abs().max()),
        "output_shape": list(got.shape),
        "phi_spec": json.loads(model.phi_spec),
        "metadata_phi": metadata["phi"],
        "metadata_matches_attribute": json.loads(model.metadata) == metadata,
        "format_version": int(model.format_version),
        "patch_shape": list(model.patch_shape),
        "file_bytes": os.path.getsize(model_path),
    }
    print(json.dumps(result))


if __name__ == "__main__":
    main()
