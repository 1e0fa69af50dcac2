"""Write the gp anchor data set (identical to /work/shared/anchors/gp_anchor.py, seed 0) to CSV
and report scikit-learn's fit on it, for the like-with-like LML comparison in docs/benchmarks.md.

Usage: python3 scripts/gp_vs_sklearn.py [--fit]
Writes crates/gp/tests/data/anchor_n500.csv (columns x0,x1,y; inches, inches, output units).
With --fit also fits sklearn (C*RBF(ARD)+White, normalize_y=True, 5 restarts, random_state=0)
and prints its LML both in standardised units (sklearn's value) and in original output units
(sklearn's value - n*ln(std(y)), std with ddof=0 as sklearn's normalize_y).
Not needed by CI.
"""
import os, sys, time
import numpy as np

N = 500
HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(HERE, "..", "crates", "gp", "tests", "data", "anchor_n500.csv")


def make_data(seed):
    rng = np.random.default_rng(seed)
    X = rng.uniform(24.0, 744.0, size=(N, 2))  # water levels, inches
    y = 3 * (X[:, 0] - X[:, 1]) * 0.001 + np.sin(X[:, 0] / 200) + rng.normal(0, 0.05, N)
    return X, y


X, y = make_data(0)
np.savetxt(OUT, np.column_stack([X, y]), delimiter=",", header="x0,x1,y", comments="", fmt="%.17g")
print(f"wrote {OUT}")
if "--fit" in sys.argv:
    import warnings
    from sklearn.gaussian_process import GaussianProcessRegressor
    from sklearn.gaussian_process.kernels import ConstantKernel, RBF, WhiteKernel
    warnings.filterwarnings("ignore")
    k = ConstantKernel(1.0) * RBF(length_scale=[100.0, 100.0]) + WhiteKernel(noise_level=1e-2)
    gp = GaussianProcessRegressor(k, normalize_y=True, n_restarts_optimizer=5, random_state=0)
    t0 = time.perf_counter(); gp.fit(X, y); t = time.perf_counter() - t0
    lml = gp.log_marginal_likelihood_value_
    sd = y.std()
    g = np.linspace(24.0, 744.0, 50)
    Xp = np.array(np.meshgrid(g, g)).reshape(2, -1).T  # the anchor's 2,500 grid points
    pt = []
    for _ in range(5):
        t0 = time.perf_counter(); gp.predict(Xp, return_std=True); pt.append(time.perf_counter() - t0)
    print(f"sklearn predict2500_std_s(median of 5)={sorted(pt)[2]:.4f}")
    print("kernel:", gp.kernel_)
    print(f"sklearn fit_s={t:.3f} lml_standardised={lml:.8f} lml_original={lml - N * np.log(sd):.8f} "
          f"std_y={sd:.6f} noise_var_original={gp.kernel_.k2.noise_level * sd**2:.6e}")
