"""Reference PSNR and SSIM from scikit-image for lfnet's metric tests.

Usage: reference_metrics.py EST.f64 TRUTH.f64 C U V H W
Prints JSON: psnr, per_view_psnr (U x V), ssim (mean over views of the channel-mean SSIM).
"""
import json
import sys

import numpy as np
from skimage.metrics import peak_signal_noise_ratio, structural_similarity

est_path, truth_path = sys.argv[1], sys.argv[2]
c, u, v, h, w = (int(x) for x in sys.argv[3:8])
est = np.fromfile(est_path, dtype=np.float64).reshape(c, u, v, h, w)
truth = np.fromfile(truth_path, dtype=np.float64).reshape(c, u, v, h, w)

per_view = [[peak_signal_noise_ratio(truth[:, i, j], est[:, i, j], data_range=1.0)
             for j in range(v)] for i in range(u)]
ssims = []
for i in range(u):
    for j in range(v):
        a = np.moveaxis(truth[:, i, j], 0, -1)
        b = np.moveaxis(est[:, i, j], 0, -1)
        ssims.append(structural_similarity(a, b, gaussian_weights=True, sigma=1.5,
                                           use_sample_covariance=True,
                                           data_range=1.0, channel_axis=-1))
print(json.dumps({
    "psnr": peak_signal_noise_ratio(truth, est, data_range=1.0),
    "per_view_psnr": per_view,
    "ssim": float(np.mean(ssims)),
}))
