"""Reference LASSO from scikit-learn (coordinate descent) for lfnet's ADMM tests.

Usage: reference_lasso.py THETA.f64 Y.f64 M K B LAMBDA OUT.f64
Solves min_a 1/2 ||Theta a - y||^2 + LAMBDA ||a||_1 for each row y of Y (B, M) and writes the
(B, K) float64 solutions to OUT. scikit-learn's Lasso scales the loss by 1 / (2 M), so its
alpha is LAMBDA / M.
"""
import sys

import numpy as np
from sklearn.linear_model import Lasso

theta_path, y_path = sys.argv[1], sys.argv[2]
m, k, b = (int(v) for v in sys.argv[3:6])
lam = float(sys.argv[6])
theta = np.fromfile(theta_path, dtype=np.float64).reshape(m, k)
ys = np.fromfile(y_path, dtype=np.float64).reshape(b, m)
out = np.zeros((b, k))
for i in range(b):
    model = Lasso(alpha=lam / m, fit_intercept=False, tol=1e-12, max_iter=1000000)
    model.fit(theta, ys[i])
    out[i] = model.coef_
out.tofile(sys.argv[7])
