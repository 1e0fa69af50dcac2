//! The reproduction's markdown report: the paper's value beside ours.

use super::fatigue::FatigueSummary;
use super::{
    ConditionalResult, DiscrepancyScore, FigureScores, ForceRmse, ReproduceReport,
    SENSITIVITY_EXPERIMENTS, SENSITIVITY_GRID, ScenarioResult, StrainRmse,
};
use crate::baselines::{Baselines, NormalTangential};
use crate::error::{GateAppError, Result};
use bamudi::EstimatorParams;
use bamudi::ThetaSummary;

/// Printed above the conditional-mode table.
pub(super) const CONDITIONAL_NOTE: &str = "\n## Module 3 with the coefficients conditioned on θ (not in the paper)\n\n\
The paper's Module 3 (Eq. 50) uses coefficients estimated with θ marginalised over its prior \
(Eq. 25/27), the same at every θ; they absorb the difference between the prior-averaged response \
and the response at the true θ, so the posterior is pulled towards the θ whose response equals the \
prior average and moves with the prior window. The conditional mode (`CoefficientMode::ConditionalOnTheta`) \
re-applies the same fitted estimator at each θ to the observations shifted to the prior-averaged model, \
re-conditions the coefficient GPs on them with their hyper-parameters held, and sets ρ* by Eq. 30 \
with θ profiled instead of marginalised (see docs/equations.md). Same data, same estimator:\n\n";

/// Printed above the headline table.
pub(super) const HEADLINE_NOTE: &str = "## Headline: the default mode (marginal coefficients, not in the paper)\n\n\
The discrepancy coefficients are integrated out under a Gaussian-process prior that is isotropic \
in force units, ρ over its uniform prior, and Module 4 carries θ, ρ and every coefficient direction \
(`CoefficientMode::Marginal`, crates/bamudi/src/posterior/marginal). Its intervals are the ones the \
validation protocol checks (docs/results/validation.md). Same data and estimator as the paper's \
Module 3 below.\n\n";

/// Printed above the baselines table.
pub(super) const BASELINES_NOTE: &str = "\n### The corrected force against the strongest baseline and the oracles\n\n\
\"Before → after\" above starts from (a), the weakest baseline. What a user should compare the \
corrected force (c) with is (b), the best calibration without any discrepancy, and what no method \
could beat: (e) knows θ* and recovers every part of δ the seven gauges see; (g) does the same with \
this calibration's θ posterior instead of θ*. Near the gap's edge the contact force changes by \
thousands of lbf/in per inch of gap, so θ's posterior spread (f) dominates every force RMSE over \
the quoin; (c) against (g) measures the discrepancy's correction alone. ρ of the split ρ g + δ is \
not identified by the data (a δ along g is indistinguishable from ρ); ρ⊥ is: the ρ that leaves \
the discrepancy's strains orthogonal to the model's, estimated with the gauges' noise as its only \
error. (crates/bamudi-gate/src/baselines.rs)\n\n";

/// Printed above the figures table.
pub(super) const FIGURES_NOTE: &str = "\n### Fig. 15 and Fig. 22 with numbers\n\n\
Fig. 15: the reconstructed discrepancy δ̂ with its 95 % band against the true δ along the quoin \
at the paper's condition (`docs/results/scenario-*/discrepancy_*.svg`). Fig. 22: the force at \
location A over a week of lockages (an 8-h filling and emptying cycle on a daily tailwater \
swing; `history_*.svg`). Location A is the first quoin point at or above a quarter of the quoin \
height: the paper's Fig. 10 marks A low on the quoin, above the gap, and a quarter of the \
height lies above every gap of either prior, so A is always in contact and its force is not \
the gap's edge, whose error is θ's (`bamudi_gate::paper::figures`).\n\n";

/// Printed above the fatigue table.
pub(super) const FATIGUE_NOTE: &str = "\n## Prediction level: quoin-block fatigue (Eq. 8; not in the paper's results)\n\n\
What the calibrated force means for the quoin blocks: the Miner damage of 1,000 lockages to the \
condition below (one cycle from the empty lock to it per lockage; Hertz line contact of 10-in \
in 10.5-in steel blocks, the largest sub-surface shear, EN 1993-1-9 shear curve Δτ_C = 100 MPa, \
m = 5; `mitergate::quoin_block`, illustrative block radii), from the true force, the nominal model \
(prior-mean force, ρ = 1, no discrepancy) and the headline calibration (2,000 joint draws of the \
force through the fatigue model, `bamudi::Predictor::predict_through`). The damage goes as the \
5th power of the stress, i.e. the 2.5th power of the line load: a 10 % force error is a 27 % \
damage error.\n\n";

/// Printed above the table of stage timings.
pub(super) const STAGES_NOTE: &str = "\n## Where the time goes\n\n\
Wall time of each stage of a scenario, in the order they ran (Module 1, the gate's build, is in \
the first line of this report; the calibration's own split into Module 2 and Module 3 is in the \
table above). The plots are written after the scenario and are not counted.\n\n";

/// Printed under each sensitivity table.
pub(super) const SENSITIVITY_NOTE: &str = "\nThe ρ range shapes only the training set of learnt estimators; the exact linear \
estimator needs no training set, so its ρ-range rows equal the default row (kept to show that). \
The α range enters the exact estimator through the prior moments of α.\n";

impl ReproduceReport {
    /// The `--json` document: `{"scenarios": [...], "gate": ..., "options": ..., "total_s"}`.
    pub fn to_json(&self) -> Result<String> {
        serde_json::to_string_pretty(self).map_err(|e| GateAppError::Serde {
            context: "reproduce-paper report".into(),
            reason: e.to_string(),
        })
    }

    /// The markdown report: the paper's values beside ours, the conditional-mode table and the
    /// sensitivity tables.
    pub fn markdown(&self) -> String {
        let mut s = String::from("# Reproduction of the paper's case study (Sec. 4.3)\n\n");
        s.push_str(&format!(
            "Gate: {} DOF ({} in elements), {} quoin nodes, Module 1 (build + condense) {:.1} s. \
             Experiments per scenario: {}, training samples: {}, estimator: {}. Total wall time {:.1} s.\n\n",
            self.gate.n_dofs,
            self.gate.element_size,
            self.gate.n_quoin_nodes,
            self.gate.module1_s,
            self.options.n_experiments,
            self.options.training_size,
            estimator_name(&self.options.estimator),
            self.total_s
        ));
        if self.scenarios.iter().any(|r| r.marginal.is_some()) {
            s.push_str(HEADLINE_NOTE);
            self.headline_table(&mut s);
            self.baselines_table(&mut s);
            self.figures_table(&mut s);
            s.push_str("\n## As published: the paper's Module 3 (Eq. 50)\n\n");
        }
        self.main_table(&mut s);
        self.worse_list(&mut s);
        if self.scenarios.iter().any(|r| r.fatigue.is_some()) {
            self.fatigue_table(&mut s);
        }
        if self.scenarios.iter().any(|r| r.conditional.is_some()) {
            s.push_str(CONDITIONAL_NOTE);
            self.conditional_table(&mut s);
        }
        for r in self.scenarios.iter().filter(|r| !r.sensitivity.is_empty()) {
            sensitivity_table(&mut s, r);
        }
        if self
            .scenarios
            .iter()
            .any(|r| !r.timings_s.stages.is_empty())
        {
            self.stage_table(&mut s);
        }
        s
    }

    /// Where each scenario's wall time went, stage by stage (issue 20's profile of the job).
    fn stage_table(&self, s: &mut String) {
        s.push_str(STAGES_NOTE);
        s.push_str("| stage | S1 (s) | S2 (s) |\n|---|---|---|\n");
        let first = &self.scenarios[0].timings_s.stages;
        for (i, stage) in first.iter().enumerate() {
            let (a, b) = self.cells(&|r| {
                r.timings_s
                    .stages
                    .get(i)
                    .map(|t| format!("{:.1}", t.seconds))
                    .unwrap_or_default()
            });
            s.push_str(&format!("| {} | {a} | {b} |\n", stage.stage));
        }
        let (a, b) = self.cells(&|r| format!("{:.1}", r.timings_s.total));
        s.push_str(&format!("| scenario total | {a} | {b} |\n"));
    }

    /// The prediction level: quoin-block fatigue before and after calibration.
    fn fatigue_table(&self, s: &mut String) {
        s.push_str(FATIGUE_NOTE);
        s.push_str("| | scenario 1 | scenario 2 |\n|---|---|---|\n");
        let row = |s: &mut String, label: &str, f: &dyn Fn(&FatigueSummary) -> String| {
            let (a, b) = self.cells(&|r| r.fatigue.as_ref().map(f).unwrap_or_default());
            s.push_str(&format!("| {label} | {a} | {b} |\n"));
        };
        row(s, "condition h_up, h_down (in)", &|f| {
            format!("{}, {}", f.h_up_in, f.h_down_in)
        });
        row(s, "true hot spot z (in)", &|f| {
            format!("{:.0}", f.hot_spot_z_in)
        });
        row(s, "damage per 1,000 lockages there: truth", &|f| {
            format!("{:.3e}", f.truth)
        });
        row(s, "before calibration (nominal model)", &|f| {
            format!("{:.3e} ({})", f.before, factor(f.before, f.truth))
        });
        row(s, "after: mean [95 % band]", &|f| {
            format!(
                "{:.3e} [{:.3e}, {:.3e}] ({}; truth {})",
                f.after_mean,
                f.after_lower,
                f.after_upper,
                factor(f.after_mean, f.truth),
                if f.after_lower <= f.truth && f.truth <= f.after_upper {
                    "inside"
                } else {
                    "outside"
                }
            )
        });
        row(s, "hot spot after calibration z (in)", &|f| {
            format!("{:.0}", f.after_hot_spot_z_in)
        });
        row(s, "quoin points whose true rate lies in the band", &|f| {
            format!("{:.2}", f.band_coverage)
        });
    }

    /// Our value per scenario, `f` of each (empty when a scenario is missing).
    fn cells(&self, f: &dyn Fn(&ScenarioResult) -> String) -> (String, String) {
        let sc = &self.scenarios;
        (f(&sc[0]), sc.get(1).map(f).unwrap_or_default())
    }

    fn main_table(&self, s: &mut String) {
        s.push_str(
            "| quantity | paper S1 | ours S1 | paper S2 | ours S2 |\n|---|---|---|---|---|\n",
        );
        let mut row = |name: &str, p1: &str, p2: &str, f: &dyn Fn(&ScenarioResult) -> String| {
            let (c1, c2) = self.cells(f);
            s.push_str(&format!("| {name} | {p1} | {c1} | {p2} | {c2} |\n"));
        };
        let (fig16, fig18, fig22) = ("(Fig. 16)", "reduced (Fig. 18)", "reduced (Fig. 22)");
        row("θ* (in)", "90", "150", &|r| format!("{}", r.theta_true));
        row("ρ* (truth 0.8)", "0.74", "0.83", &|r| {
            format!("{:.3}", r.rho_star)
        });
        let with = "θ posterior, with discrepancy: mean ± sd [95%]";
        let (close90, close150) = (
            format!("close to 90 {fig16}"),
            format!("close to 150 {fig16}"),
        );
        row(with, &close90, &close150, &|r| th(&r.theta_posterior));
        let biased = format!("biased {fig16}");
        row(
            "θ posterior, without discrepancy",
            &biased,
            &biased,
            &|r| th(&r.theta_posterior_no_discrepancy),
        );
        row(
            "normal force RMSE before → after (lbf/in)",
            fig18,
            fig18,
            &|r| arrow(r.force_rmse.normal_before, r.force_rmse.normal_after),
        );
        row(
            "tangential force RMSE before → after (lbf/in)",
            fig22,
            fig22,
            &|r| {
                arrow(
                    r.force_rmse.tangential_before,
                    r.force_rmse.tangential_after,
                )
            },
        );
        let strain = "strain RMSE at new conditions, with / without discrepancy (µε)";
        row(
            strain,
            "smaller with (Fig. 19)",
            "smaller with (Fig. 20)",
            &|r| {
                let e = &r.strain_rmse;
                format!("{:.2} / {:.2}", e.with_discrepancy, e.without_discrepancy)
            },
        );
        let true_delta = "RMS strain of the true discrepancy A δ (µε; noise σ = 1)";
        row(true_delta, "–", "–", &|r| {
            format!("{:.2}", r.discrepancy_strain_rms)
        });
        row(
            "σ_ε estimated for Module 3 (µε)",
            "1 (given)",
            "1 (given)",
            &|r| format!("{:.3}", r.sigma_eps),
        );
        row("Module 2 wall time (s)", "11,400 (190 min)", "–", &|r| {
            format!("{:.1}", r.timings_s.module2)
        });
        row("Module 3 wall time (s)", "3,360 (56 min)", "–", &|r| {
            format!("{:.1}", r.timings_s.module3)
        });
        row("scenario total (s)", "14,820 (247 min)", "–", &|r| {
            format!("{:.1}", r.timings_s.total)
        });
    }

    fn headline_table(&self, s: &mut String) {
        s.push_str("| quantity | S1 | S2 |\n|---|---|---|\n");
        type Cell<'a> = &'a dyn Fn(&ScenarioResult, &ConditionalResult) -> String;
        let rows: [(&str, Cell<'_>); 11] = [
            ("θ* (in)", &|r, _| format!("{}", r.theta_true)),
            ("θ posterior: mean ± sd [95%]", &|_, m| {
                th(&m.theta_posterior)
            }),
            ("95 % interval holds θ*", &|r, m| {
                yes_no(holds(&m.theta_posterior, r.theta_true))
            }),
            (
                "ρ⊥, the data's scale of g: mean ± sd (truth's ρ⊥)",
                &|r, m| match (m.rho_projection, r.rho_projection_true) {
                    (Some([mean, sd]), Some(t)) => format!("{mean:.4} ± {sd:.4} ({t:.4})"),
                    _ => "–".into(),
                },
            ),
            ("normal force RMSE before → after (lbf/in)", &|_, m| {
                ratio_arrow(m.force_rmse.normal_before, m.force_rmse.normal_after)
            }),
            (
                "tangential force RMSE before → after (lbf/in)",
                &|_, m| {
                    ratio_arrow(
                        m.force_rmse.tangential_before,
                        m.force_rmse.tangential_after,
                    )
                },
            ),
            (
                "strain RMSE at new conditions, with / without discrepancy (µε)",
                &|_, m| {
                    format!(
                        "{:.2} / {:.2}",
                        m.strain_rmse.with_discrepancy, m.strain_rmse.without_discrepancy
                    )
                },
            ),
            (
                "δ̂ RMSE / true δ RMS, normal; tangential (lbf/in)",
                &|_, m| delta_rmse(&m.discrepancy),
            ),
            (
                "true δ inside the 95 % δ̂ band, normal / tangential",
                &|_, m| {
                    let d = &m.discrepancy;
                    format!(
                        "{:.2} / {:.2}",
                        d.normal_band_coverage, d.tangential_band_coverage
                    )
                },
            ),
            ("σ_ε estimated (µε)", &|_, m| {
                format!("{:.3}", m.sigma_eps)
            }),
            (
                "estimator (Eq. 29) on held-out samples: mean R² over coefficients (worst; n) (Fig. 12)",
                &|r, _| {
                    let a = &r.estimator_accuracy;
                    let worst = a.r2.iter().copied().fold(f64::INFINITY, f64::min);
                    format!("{:.3} ({worst:.3}; {})", a.mean_r2(), a.n)
                },
            ),
        ];
        for (name, f) in rows {
            let cell =
                |r: &ScenarioResult| r.marginal.as_ref().map(|m| f(r, m)).unwrap_or_default();
            let (c1, c2) = self.cells(&cell);
            s.push_str(&format!("| {name} | {c1} | {c2} |\n"));
        }
    }

    /// The headline's corrected force beside every baseline and oracle.
    fn baselines_table(&self, s: &mut String) {
        if !self
            .scenarios
            .iter()
            .any(|r| r.marginal.as_ref().is_some_and(|m| m.baselines.is_some()))
        {
            return;
        }
        s.push_str(BASELINES_NOTE);
        s.push_str("| force RMSE over the new conditions and quoin points (lbf/in) | S1 normal | S1 tangential | S2 normal | S2 tangential |\n|---|---|---|---|---|\n");
        type Pick<'a> = &'a dyn Fn(&Baselines) -> NormalTangential;
        let rows: [(&str, Pick<'_>); 7] = [
            (
                "(a) prior mean, ρ = 1, no δ (the paper's \"before\")",
                &|b| b.prior_mean,
            ),
            ("(b) best fit without a discrepancy (ρ, θ fitted)", &|b| {
                b.no_discrepancy
            }),
            ("(c) **default mode (corrected force)**", &|b| b.calibrated),
            (
                "(d) oracle: the truth's ρ* g(θ*) (error = the true δ)",
                &|b| b.oracle_split,
            ),
            ("(e) oracle: (d) + the part of δ the gauges see", &|b| {
                b.oracle_seen
            }),
            (
                "(f) the truth at this calibration's θ posterior (θ's spread alone)",
                &|b| b.theta_spread,
            ),
            ("(g) (e) at this calibration's θ posterior", &|b| {
                b.oracle_seen_posterior
            }),
        ];
        let cell = |r: &ScenarioResult, f: &dyn Fn(&Baselines) -> String| {
            r.marginal
                .as_ref()
                .and_then(|m| m.baselines.as_ref())
                .map(f)
                .unwrap_or_else(|| "– | –".into())
        };
        for (name, pick) in rows {
            let (a, b) = self.cells(&|r| {
                cell(r, &|b| {
                    let v = pick(b);
                    format!("{:.1} | {:.1}", v.normal, v.tangential)
                })
            });
            s.push_str(&format!("| {name} | {a} | {b} |\n"));
        }
        let ratio = |name: &str, den: Pick<'_>| {
            let (a, b) = self.cells(&|r| {
                cell(r, &|b| {
                    let (c, d) = (b.calibrated, den(b));
                    format!(
                        "{:.2} | {:.2}",
                        c.normal / d.normal,
                        c.tangential / d.tangential
                    )
                })
            });
            format!("| {name} | {a} | {b} |\n")
        };
        s.push_str(&ratio("(c) / (b)", &|b| b.no_discrepancy));
        s.push_str(&ratio("(c) / (e)", &|b| b.oracle_seen));
        s.push_str(&ratio("(c) / (g)", &|b| b.oracle_seen_posterior));
        self.rho_projection_row(s);
    }

    /// `ρ⊥` of the headline against the truth's.
    fn rho_projection_row(&self, s: &mut String) {
        let (a, b) = self.cells(&|r| {
            let p = r.marginal.as_ref().and_then(|m| m.rho_projection);
            format!(
                "{} | truth {}",
                p.map_or("–".into(), |[mean, sd]| format!("{mean:.4} ± {sd:.4}")),
                r.rho_projection_true
                    .map_or("–".into(), |t| format!("{t:.4}"))
            )
        });
        s.push_str(&format!(
            "| ρ⊥, the data's own scale of g (mean ± sd) | {a} | {b} |\n"
        ));
    }

    /// Fig. 15 and Fig. 22 with numbers (the headline calibration).
    fn figures_table(&self, s: &mut String) {
        if !self.scenarios.iter().any(|r| r.figures.is_some()) {
            return;
        }
        s.push_str(FIGURES_NOTE);
        s.push_str(
            "| | S1 normal | S1 tangential | S2 normal | S2 tangential |\n|---|---|---|---|---|\n",
        );
        type Pick<'a> = &'a dyn Fn(&FigureScores, bool) -> String;
        let rows: [(&str, Pick<'_>); 11] = [
            ("Fig. 15 condition h_up, h_down (in)", &|f, _| {
                format!("{}, {}", f.fig15.condition[0], f.fig15.condition[1])
            }),
            ("Fig. 15: true δ RMS along the quoin (lbf/in)", &|f, n| {
                format!("{:.1}", c15(f, n).true_rms)
            }),
            ("Fig. 15: δ̂ RMSE (lbf/in)", &|f, n| {
                format!("{:.1}", c15(f, n).rmse)
            }),
            ("Fig. 15: true δ inside the 95 % band", &|f, n| {
                format!("{:.2}", c15(f, n).band_coverage)
            }),
            ("Fig. 15: median band half-width (lbf/in)", &|f, n| {
                format!("{:.1}", c15(f, n).median_halfwidth)
            }),
            ("Fig. 22: location A, height (in)", &|f, _| {
                format!("{:.1}", f.fig22.location_in)
            }),
            ("Fig. 22: true force RMS over the week (lbf/in)", &|f, n| {
                format!("{:.0}", c22(f, n).true_rms)
            }),
            ("Fig. 22: RMSE before (prior mean, ρ = 1)", &|f, n| {
                format!("{:.1}", c22(f, n).rmse_before)
            }),
            ("Fig. 22: RMSE of the best fit without δ", &|f, n| {
                format!("{:.1}", c22(f, n).rmse_no_discrepancy)
            }),
            ("Fig. 22: RMSE after (default mode)", &|f, n| {
                format!("{:.1}", c22(f, n).rmse_after)
            }),
            (
                "Fig. 22: truth inside the 95 % band / median half-width",
                &|f, n| {
                    let c = c22(f, n);
                    format!("{:.2} / {:.1}", c.band_coverage, c.median_halfwidth)
                },
            ),
        ];
        for (name, f) in rows {
            let (a, b) = self.cells(&|r| {
                r.figures.as_ref().map_or("– | –".into(), |fs| {
                    format!("{} | {}", f(fs, true), f(fs, false))
                })
            });
            s.push_str(&format!("| {name} | {a} | {b} |\n"));
        }
    }

    /// Every quantity that calibration made worse, per mode and scenario.
    fn worse_list(&self, s: &mut String) {
        let mut lines = Vec::new();
        for r in &self.scenarios {
            let mut check = |mode: &str,
                             f: &ForceRmse,
                             e: &StrainRmse,
                             d: &DiscrepancyScore,
                             t: &ThetaSummary| {
                let mut bad = Vec::new();
                if f.normal_after > f.normal_before {
                    bad.push(format!(
                        "normal force RMSE {}",
                        arrow(f.normal_before, f.normal_after)
                    ));
                }
                if f.tangential_after > f.tangential_before {
                    bad.push(format!(
                        "tangential force RMSE {}",
                        arrow(f.tangential_before, f.tangential_after)
                    ));
                }
                if e.with_discrepancy > e.without_discrepancy {
                    bad.push(format!(
                        "strain RMSE with discrepancy {:.2} > without {:.2} µε",
                        e.with_discrepancy, e.without_discrepancy
                    ));
                }
                if d.tangential_rmse > d.tangential_true_rms {
                    bad.push(format!(
                        "tangential δ̂ RMSE {:.1} > true δ RMS {:.1} lbf/in",
                        d.tangential_rmse, d.tangential_true_rms
                    ));
                }
                if d.normal_rmse > d.normal_true_rms {
                    bad.push(format!(
                        "normal δ̂ RMSE {:.1} > true δ RMS {:.1} lbf/in",
                        d.normal_rmse, d.normal_true_rms
                    ));
                }
                if !holds(t, r.theta_true) {
                    bad.push(format!(
                        "95 % θ interval [{:.2}, {:.2}] misses θ* = {}",
                        t.ci95.0, t.ci95.1, r.theta_true
                    ));
                }
                lines.extend(
                    bad.into_iter()
                        .map(|b| format!("- {}, {mode}: {b}\n", r.name)),
                );
            };
            check(
                "paper's Module 3",
                &r.force_rmse,
                &r.strain_rmse,
                &r.discrepancy,
                &r.theta_posterior,
            );
            for (mode, v) in [("conditional", &r.conditional), ("marginal", &r.marginal)] {
                if let Some(c) = v {
                    check(
                        mode,
                        &c.force_rmse,
                        &c.strain_rmse,
                        &c.discrepancy,
                        &c.theta_posterior,
                    );
                }
            }
        }
        s.push_str("\n### What got worse or missed\n\n");
        if lines.is_empty() {
            s.push_str("Nothing: every error fell and every 95 % interval holds θ*.\n");
        }
        lines.iter().for_each(|l| s.push_str(l));
    }

    fn conditional_table(&self, s: &mut String) {
        s.push_str("| quantity | paper's Module 3 S1 | conditional S1 | paper's Module 3 S2 | conditional S2 |\n|---|---|---|---|---|\n");
        type Row<'a> = (
            &'a str,
            &'a dyn Fn(&ScenarioResult) -> String,
            &'a dyn Fn(&ConditionalResult) -> String,
        );
        let rows: [Row<'_>; 7] = [
            ("ρ* (truth 0.8)", &|r| format!("{:.3}", r.rho_star), &|c| {
                format!("{:.3}", c.rho_star)
            }),
            (
                "θ posterior: mean ± sd [95%] (truth 90 / 150)",
                &|r| th(&r.theta_posterior),
                &|c| th(&c.theta_posterior),
            ),
            (
                "normal force RMSE before → after (lbf/in)",
                &|r| arrow(r.force_rmse.normal_before, r.force_rmse.normal_after),
                &|c| arrow(c.force_rmse.normal_before, c.force_rmse.normal_after),
            ),
            (
                "tangential force RMSE before → after (lbf/in)",
                &|r| {
                    arrow(
                        r.force_rmse.tangential_before,
                        r.force_rmse.tangential_after,
                    )
                },
                &|c| {
                    arrow(
                        c.force_rmse.tangential_before,
                        c.force_rmse.tangential_after,
                    )
                },
            ),
            (
                "strain RMSE at new conditions (µε)",
                &|r| format!("{:.2}", r.strain_rmse.with_discrepancy),
                &|c| format!("{:.2}", c.strain_rmse.with_discrepancy),
            ),
            (
                "σ_ε estimated for Module 3 (µε)",
                &|r| format!("{:.3}", r.sigma_eps),
                &|c| format!("{:.3}", c.sigma_eps),
            ),
            ("extra wall time (s)", &|_| "–".into(), &|c| {
                format!("{:.1}", c.seconds)
            }),
        ];
        for (name, f, g) in rows {
            let cell = |r: &ScenarioResult| r.conditional.as_ref().map(g).unwrap_or_default();
            let (a1, a2) = self.cells(f);
            let (b1, b2) = self.cells(&cell);
            s.push_str(&format!("| {name} | {a1} | {b1} | {a2} | {b2} |\n"));
        }
    }
}

fn sensitivity_table(s: &mut String, r: &ScenarioResult) {
    s.push_str(&format!(
        "\n## Sampling-rule sensitivity, {} (θ* = {}; first {} experiments, {} θ nodes)\n\n| rule | ρ range | α scale c | ρ* | θ mean ± sd [95%] |\n|---|---|---|---|---|\n",
        r.name, r.theta_true, SENSITIVITY_EXPERIMENTS, SENSITIVITY_GRID
    ));
    for row in &r.sensitivity {
        s.push_str(&format!(
            "| {} | [{}, {}] | {} | {:.3} | {} |\n",
            row.rule,
            row.rho_range[0],
            row.rho_range[1],
            row.alpha_scale,
            row.rho_star,
            th(&row.theta)
        ));
    }
    s.push_str(SENSITIVITY_NOTE);
}

fn c15(f: &FigureScores, normal: bool) -> super::figures::CurveScore {
    if normal {
        f.fig15.normal
    } else {
        f.fig15.tangential
    }
}

fn c22(f: &FigureScores, normal: bool) -> super::figures::HistoryScore {
    if normal {
        f.fig22.normal
    } else {
        f.fig22.tangential
    }
}

fn th(t: &ThetaSummary) -> String {
    format!(
        "{:.2} ± {:.2} [{:.2}, {:.2}]",
        t.mean, t.sd, t.ci95.0, t.ci95.1
    )
}

fn holds(t: &ThetaSummary, truth: f64) -> bool {
    (t.ci95.0..=t.ci95.1).contains(&truth)
}

fn yes_no(b: bool) -> String {
    if b { "yes".into() } else { "**no**".into() }
}

/// `value / truth` as "1.23x the truth" (or "no damage" when both are zero).
fn factor(value: f64, truth: f64) -> String {
    match (value == 0.0, truth == 0.0) {
        (true, true) => "no damage, as the truth".into(),
        (_, true) => "the truth has none".into(),
        _ => format!("{:.2}x the truth", value / truth),
    }
}

fn ratio_arrow(before: f64, after: f64) -> String {
    format!("{before:.1} → {after:.1} ({:.1}x smaller)", before / after)
}

fn delta_rmse(d: &DiscrepancyScore) -> String {
    format!(
        "{:.1} / {:.1}; {:.1} / {:.1}",
        d.normal_rmse, d.normal_true_rms, d.tangential_rmse, d.tangential_true_rms
    )
}

fn arrow(before: f64, after: f64) -> String {
    format!("{before:.1} → {after:.1}")
}

fn estimator_name(e: &EstimatorParams) -> &'static str {
    match e {
        EstimatorParams::Lstm(_) => "LSTM (seqnet)",
        EstimatorParams::Ridge(_) => "ridge (smartcore)",
        EstimatorParams::ExactLinear => "exact linear-Gaussian",
    }
}
