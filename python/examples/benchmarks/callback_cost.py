"""What a Python callback costs: the engine's analytic example (strip load, 6 sensors, 40
experiments) calibrated by the Rust example and by the same model as numpy callables, one
input at a time and vectorised. The times are the engine's own stage timings (Modules 2-3
and the adequacy checks, `Calibration::timings`), the median of `--repeats` runs each; the
same build profile on both sides is the fair comparison (the Rust example in
`target/<profile>/examples/analytic`, the Python extension built with that profile).

    cargo build --release -p bamudi --example analytic   # or without --release: dev profile
    python python/examples/benchmarks/callback_cost.py --rust target/release/examples/analytic
"""

import argparse
import json
import pathlib
import statistics
import subprocess
import sys
import time

import numpy as np

HERE = pathlib.Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
import analytic  # noqa: E402

import bamudi  # noqa: E402


def engine_seconds(cal) -> float:
    t = cal.timings
    return sum(t[k] for k in ("training_set_s", "estimator_s", "rho_s", "gp_s", "coefficients_s", "module3_s",
                              "adequacy_s"))


def counted(fn):
    calls = {"n": 0}

    def wrapped(x, theta):
        calls["n"] += 1
        return fn(x, theta)

    return wrapped, calls


def one_at_a_time(x, theta):
    return x[0] * np.exp(-theta[0] * analytic.POINTS)


def model(response, vectorised):
    return bamudi.Model(response, coordinates=analytic.POINTS, inputs=["load_kn_per_m"],
                        outputs=analytic.model.outputs, A=analytic.A,
                        prior={"decay_per_m": bamudi.Uniform(0.5, 3.0)},
                        discrepancy=bamudi.Discrepancy("legendre", 2, (0.0, 1.0)), vectorised=vectorised)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rust", default=str(HERE.parents[2] / "target" / "release" / "examples" / "analytic"))
    ap.add_argument("--repeats", type=int, default=15)
    args = ap.parse_args(argv)
    rows = {}
    rust = [json.loads(subprocess.run([args.rust, "--json"], capture_output=True, text=True, check=True)
                       .stdout.strip().splitlines()[-1]) for _ in range(args.repeats)]
    rows["Rust (examples/analytic.rs)"] = (statistics.median(r["calibration_s"] for r in rust), None, None)
    data = analytic.experiments()
    for name, fn, vec in [("Python, vectorised (x: (n, 1) at one theta)", analytic.strip_load, True),
                          ("Python, one input per call (x: (1,))", one_at_a_time, False)]:
        f, calls = counted(fn)
        m = model(f, vec)
        secs, walls = [], []
        for _ in range(args.repeats):
            calls["n"] = 0
            start = time.perf_counter()
            cal = bamudi.calibrate(m, data, analytic.CONFIG)
            walls.append(time.perf_counter() - start)
            secs.append(engine_seconds(cal))
        assert abs(cal.theta_mean[0] - rust[0]["theta"][0]) <= 1e-9 * rust[0]["theta"][0]
        rows[name] = (statistics.median(secs), calls["n"], statistics.median(walls))
    base = rows["Rust (examples/analytic.rs)"][0]
    print(f"{'':48s} {'engine s':>9s} {'ratio':>7s} {'callback calls':>15s} {'wall s':>8s}")
    for name, (s, n, w) in rows.items():
        print(f"{name:48s} {s:9.4f} {s / base:7.2f} {'' if n is None else n:>15} {'' if w is None else f'{w:8.4f}'}")
    return {k: {"engine_s": v[0], "ratio": v[0] / base, "calls": v[1]} for k, v in rows.items()}


if __name__ == "__main__":
    main()
