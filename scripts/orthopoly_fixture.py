#!/usr/bin/env python3
"""Reference fixture and timing for the `orthopoly` crate (not needed by CI).

Writes crates/orthopoly/tests/data/numpy_fixture.json with values of the classical
Legendre P_n, Chebyshev T_n and probabilists' Hermite He_n (n <= 20) computed by
numpy.polynomial, plus numpy's Gauss-Legendre (leggauss) and Gauss-Hermite-E (hermegauss)
nodes and weights for a few orders, together with 40-digit mpmath references for the same
rules (numpy's own weights carry relative errors up to ~2e-12, recorded in the fixture, so
the tight checks of the Rust rules use the mpmath values). With --time, also times numpy's basis matrix for the
benchmark in docs/benchmarks.md (legvander on 509 points x 6 terms on [0, 762] in, including
the affine map and the orthonormal scaling sqrt(2n+1)).

Usage:  python3 scripts/orthopoly_fixture.py [--time | --time-only]
        (requires numpy and mpmath: pip install numpy mpmath)
"""
import json
import pathlib
import sys
import timeit

import mpmath as mp
import numpy as np
from numpy.polynomial import chebyshev as C
from numpy.polynomial import hermite_e as HE
from numpy.polynomial import legendre as L

MAX_DEGREE = 20
OUT = pathlib.Path(__file__).resolve().parent.parent / "crates/orthopoly/tests/data/numpy_fixture.json"


def values(vander, points):
    """Rows: degree n = 0..MAX_DEGREE; columns: points."""
    return vander(np.asarray(points), MAX_DEGREE).T.tolist()


def mp_gauss_legendre(n, guesses):
    """Nodes/weights of Gauss-Legendre to 40 digits, polishing numpy's nodes."""
    nodes, weights = [], []
    for g in guesses:
        r = mp.findroot(lambda t: mp.legendre(n, t), mp.mpf(g))
        dp = mp.diff(lambda t: mp.legendre(n, t), r)
        nodes.append(r)
        weights.append(2 / ((1 - r**2) * dp**2))
    return nodes, weights


def mp_hermite_e(n, x):
    """Probabilists' He_n(x) = 2^(-n/2) H_n(x / sqrt 2)."""
    return mp.hermite(n, x / mp.sqrt(2)) / mp.power(2, mp.mpf(n) / 2)


def mp_gauss_hermite_e(n, guesses):
    """Nodes/weights for weight exp(-x^2/2): w = sqrt(2 pi) n! / (n He_{n-1}(x))^2."""
    nodes, weights = [], []
    for g in guesses:
        # Scaled to O(1) so findroot's residual test is meaningful for large n and |x|.
        scale = mp.sqrt(mp.factorial(n))
        r = mp.findroot(lambda t: mp_hermite_e(n, t) * mp.exp(-t * t / 4) / scale, mp.mpf(g))
        nodes.append(r)
        weights.append(mp.sqrt(2 * mp.pi) * mp.factorial(n) / (n * mp_hermite_e(n - 1, r)) ** 2)
    return nodes, weights


def rule_entry(n, x, w, ref_x, ref_w):
    ref_x = [float(v) for v in ref_x]
    ref_w = [float(v) for v in ref_w]
    return {
        "n": n,
        "nodes": x.tolist(),
        "weights": w.tolist(),
        "mp_nodes": ref_x,
        "mp_weights": ref_w,
        "numpy_max_node_error": max(abs(a - b) for a, b in zip(x, ref_x)),
        "numpy_max_weight_rel_error": max(abs(a - b) / b for a, b in zip(w, ref_w)),
    }


def main():
    mp.mp.dps = 40
    unit = np.linspace(-1.0, 1.0, 51)
    wide = np.linspace(-6.0, 6.0, 49)
    fixture = {
        "numpy_version": np.__version__,
        "max_degree": MAX_DEGREE,
        "unit_points": unit.tolist(),
        "wide_points": wide.tolist(),
        "legendre": values(L.legvander, unit),
        "chebyshev": values(C.chebvander, unit),
        "hermite_e_unit": values(HE.hermevander, unit),
        "hermite_e_wide": values(HE.hermevander, wide),
        "leggauss": [],
        "hermegauss": [],
    }
    for n in (1, 2, 3, 5, 10, 20, 64, 100):
        x, w = L.leggauss(n)
        fixture["leggauss"].append(rule_entry(n, x, w, *mp_gauss_legendre(n, x)))
    for n in (1, 2, 3, 5, 10, 20, 50, 100):
        x, w = HE.hermegauss(n)
        fixture["hermegauss"].append(rule_entry(n, x, w, *mp_gauss_hermite_e(n, x)))
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(json.dumps(fixture, indent=1) + "\n")
    print(f"wrote {OUT}")


def time_basis_matrix():
    t = np.linspace(0.0, 762.0, 509)
    scale = np.sqrt(2.0 * np.arange(6) + 1.0)

    def build():
        z = (t - 381.0) / 381.0
        return L.legvander(z, 5) * scale

    number = 20000
    best = min(timeit.repeat(build, number=number, repeat=5)) / number
    print(f"numpy legvander 509 x 6 (map + scale): {best * 1e6:.2f} us")

    def gauss():
        return L.leggauss(64)

    number = 2000
    best = min(timeit.repeat(gauss, number=number, repeat=5)) / number
    print(f"numpy leggauss(64): {best * 1e6:.2f} us")


if __name__ == "__main__":
    if "--time-only" not in sys.argv:
        main()
    if "--time" in sys.argv or "--time-only" in sys.argv:
        time_basis_matrix()
