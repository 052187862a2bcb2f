"""Reference Batch-OMP from scikit-learn for lfnet's OMP tests.

Usage: reference_omp.py GRAM.f64 XY.f64 K B n_nonzero N OUT.f64
       reference_omp.py GRAM.f64 XY.f64 K B tol TOL NORMS.f64 OUT.f64
Writes the (K, B) float64 coefficients of orthogonal_mp_gram to OUT and prints JSON
{"n_iter": [...]} with the atoms used per column.
"""
import json
import sys
import warnings

import numpy as np
from sklearn.linear_model import orthogonal_mp_gram

gram_path, xy_path = sys.argv[1], sys.argv[2]
k, b = int(sys.argv[3]), int(sys.argv[4])
mode = sys.argv[5]
gram = np.fromfile(gram_path, dtype=np.float64).reshape(k, k)
xy = np.fromfile(xy_path, dtype=np.float64).reshape(k, b)
with warnings.catch_warnings():
    warnings.simplefilter("ignore", RuntimeWarning)
    if mode == "n_nonzero":
        coef, n_iter = orthogonal_mp_gram(gram, xy, n_nonzero_coefs=int(sys.argv[6]),
                                          return_n_iter=True)
        out_path = sys.argv[7]
    elif mode == "tol":
        norms = np.fromfile(sys.argv[7], dtype=np.float64).reshape(b)
        coef, n_iter = orthogonal_mp_gram(gram, xy, tol=float(sys.argv[6]), norms_squared=norms,
                                          return_n_iter=True)
        out_path = sys.argv[8]
    else:
        raise SystemExit("unknown mode " + mode)
coef = np.asarray(coef, dtype=np.float64).reshape(k, b)
coef.tofile(out_path)
print(json.dumps({"n_iter": [int(n) for n in np.atleast_1d(n_iter)]}))
