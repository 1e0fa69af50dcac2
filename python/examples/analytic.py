"""The engine's analytic example (crates/bamudi/examples/analytic.rs) written as numpy
callables: a load along a strip decays as x0 exp(-theta d) (kN/m), six sensors average it,
and the measurements come from a reality the model lacks (90 % of its load plus a smooth
extra load). Same data, same configuration and seed as the Rust example: the same posterior,
to 1e-9 where numpy's exp is the C library's, and to about 1e-5 of θ's posterior mean where it
is not (numpy's own SIMD exp on AVX-512 machines differs in the last bit at a few points, and
the engine's optimisers amplify that; the test module builds the example with the C library's
exp through ``experiments(exp=...)`` and ``sensor_matrix(exp)`` for the bit-for-bit check).

    python python/examples/analytic.py
"""

import numpy as np

import bamudi

POINTS = np.arange(21) / 20  # m along the strip (0, 0.05, ..., 1: the Rust literals, bit for bit)
CENTRES = np.array([0.05, 0.25, 0.45, 0.65, 0.85, 1.0])


def sensor_matrix(exp=np.exp):
    """The six sensors' averaging weights over the 21 points: (6, 21)."""
    return 0.05 * exp(-(((POINTS[None, :] - CENTRES[:, None]) / 0.2) ** 2))


A = sensor_matrix()


def strip_load(x, theta):
    """q(d) = x0 exp(-theta d) at every point, for all inputs x (n, 1) at one theta: (n, 21)."""
    return x[:, :1] * np.exp(-theta[0] * POINTS)[None, :]


model = bamudi.Model(
    strip_load,
    coordinates=POINTS,
    inputs=["load_kn_per_m"],
    outputs=[f"sensor_{s}" for s in range(1, 7)],
    A=A,
    prior={"decay_per_m": bamudi.Uniform(0.5, 3.0)},
    discrepancy=bamudi.Discrepancy("legendre", terms=2, interval=(0.0, 1.0)),
)


def experiments(theta_true=1.6, n=40, exp=np.exp):
    """The Rust example's synthetic measurements, bit for bit where ``exp`` is the C library's
    (deterministic pseudo-noise).

    The sensor sums run in the Rust example's order (point by point, as nalgebra's gemv adds
    them) rather than as ``q @ A.T``, whose BLAS order differs in the last bit: the engine's
    optimisers (GP fits, the ρ search) turn a 1e-16 relative change of the data into about
    1e-6 of θ's posterior mean (measured), so an agreement to 1e-9 needs the same data."""
    x = 1.0 + 9.0 * np.arange(n) / (n - 1)
    a = sensor_matrix(exp)
    q = 0.9 * x[:, None] * exp(-theta_true * POINTS)[None, :] + 0.04 * x[:, None] * (1.0 - POINTS)[None, :]
    y = np.zeros((n, 6))
    for b in range(len(POINTS)):
        y = a[:, b][None, :] * q[:, b][:, None] + y if b else a[:, 0][None, :] * q[:, 0][:, None]
    i, s = np.meshgrid(np.arange(n), np.arange(6), indexing="ij")
    return x.reshape(-1, 1), y + 0.002 * (((i * 7 + s * 3) % 11) / 5.0 - 1.0)


CONFIG = {
    "estimator": {"kind": "exact_linear"},
    "coefficients": "conditional_on_theta",
    "sampling": {"noise_sd": 0.002},
    "theta_grid_points": 121,
}

if __name__ == "__main__":
    x, y = experiments()
    cal = bamudi.calibrate(model, (x, y), CONFIG)
    (lo, hi), = cal.theta_ci95
    print(f"theta = {cal.theta_mean[0]:.3f} ± {cal.theta_sd[0]:.3f} (95 % [{lo:.3f}, {hi:.3f}]; truth 1.6), "
          f"rho* = {cal.rho_star:.3f}")
    band = cal.predict(5.0)
    print(f"load at d = 0.5 m for x = 5 kN/m: {band['response_mean'][0, 10]:.3f} kN/m "
          f"[{band['response_lower'][0, 10]:.3f}, {band['response_upper'][0, 10]:.3f}]")

    def peak_and_resultant(x, theta, q):
        return [q[0].max(), np.sum(0.05 * 0.5 * (q[0, 1:] + q[0, :-1]))]

    p = cal.predict_through(peak_and_resultant, ["peak_kn_per_m", "resultant_kn"], [5.0], 2000, 7)
    print(f"resultant for x = 5 kN/m: {p['mean'][1]:.4f} kN [{p['lower'][1]:.4f}, {p['upper'][1]:.4f}]")
