"""Python quick start: simulate the paper's scenario 1 on the default gate, calibrate the gap,
predict the quoin forces with 95 % bands, save the calibration for `bamudi predict`.

    pip install ./python
    python python/examples/quickstart.py
"""

import sys
import tempfile

import bamudi

element_size = float(sys.argv[1]) if len(sys.argv) > 1 else 12.0  # in; 60 is coarse and fast
gate = bamudi.Gate(element_size=element_size)
print(gate)
exps = bamudi.simulate_experiments(gate, scenario=1, n=200, seed=1)  # true gap 90 in
config = {
    "gap_prior": [81.0, 105.0],
    "calibration": {"estimator": {"kind": "exact_linear"}, "sampling": {"noise_sd": 1.0}},
}
cal = bamudi.calibrate(gate, exps, config)
lo, hi = cal.theta_ci95
print(f"gap: {cal.theta_mean:.2f} ± {cal.theta_sd:.2f} in, 95 % [{lo:.2f}, {hi:.2f}]; verdict {cal.verdict}")
p = cal.predict(700.0, 100.0)
peak = p["normal_mean"].argmax()
print(
    f"peak normal force at z = {cal.z_in[peak]:.0f} in: {p['normal_mean'][peak]:.0f} lbf/in "
    f"[{p['normal_lower'][peak]:.0f}, {p['normal_upper'][peak]:.0f}]"
)
with tempfile.TemporaryDirectory() as d:
    cal.save(d)
    again = bamudi.Calibration.load(d)
    assert again.theta_mean == cal.theta_mean
print("saved and reloaded: the same calibration")
