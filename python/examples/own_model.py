"""Calibrate your own model: a load along a strip decays as x0 exp(-theta d) (kN/m), six
sensors average it (kN/m), the measurements come from a reality the model lacks."""
import numpy as np

import bamudi

d = np.arange(21) / 20                                        # m, the response coordinates
A = 0.05 * np.exp(-((d - np.array([[0.05], [0.25], [0.45], [0.65], [0.85], [1.0]])) / 0.2) ** 2)


def load(x, theta):                                           # x: (n, 1), theta: (1,) -> (n, 21)
    return x[:, :1] * np.exp(-theta[0] * d)


model = bamudi.Model(load, coordinates=d, inputs=["load_kn_per_m"], A=A,
                     outputs=[f"sensor_{s}" for s in range(1, 7)],
                     prior={"decay_per_m": bamudi.Uniform(0.5, 3.0)},
                     discrepancy=bamudi.Discrepancy("legendre", terms=2))
x = np.linspace(1.0, 10.0, 40).reshape(-1, 1)                 # (n, inputs)
reality = 0.9 * load(x, [1.6]) + 0.04 * x * (1 - d)           # what the model lacks
y = reality @ A.T + 0.002 * np.random.default_rng(1).standard_normal((40, 6))  # (n, outputs)

cal = bamudi.calibrate(model, (x, y), {"estimator": {"kind": "exact_linear"}}, seed=7)
print(cal)                                                    # theta, rho, the adequacy verdict
(lo, hi), = cal.theta_ci95
print(f"decay {cal.theta_mean[0]:.3f} 1/m, 95 % [{lo:.3f}, {hi:.3f}] (truth 1.6)")
band = cal.predict(5.0)                                       # Module 4 at x = 5 kN/m
print("load at d = 0.5 m:", band["response_mean"][0, 10].round(3),
      "[", band["response_lower"][0, 10].round(3), band["response_upper"][0, 10].round(3), "] kN/m")
print("true load there:", (0.9 * 5 * np.exp(-1.6 * 0.5) + 0.04 * 5 * 0.5).round(3), "kN/m")
cal.save("own_model_calibration")                             # calibration.json + model.json
again = bamudi.ModelCalibration.load("own_model_calibration", model=model)
draws = cal.posterior_draws(n=2000)                           # theta (chains, draws, 1), rho
