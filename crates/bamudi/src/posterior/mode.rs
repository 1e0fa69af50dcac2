//! What each coefficient mode fitted besides `θ`'s posterior ([`ModeFit`]), and the saved
//! calibration's layout of it.
//!
//! A calibration file keeps the flat layout it always had (`rho_profile`, `refit_gps`,
//! `alpha_hat`, `alpha_correction`, `marginal`, `averaged` side by side, each `null` when the
//! mode has none), so files written before and after read alike; reading one builds the
//! variant its fields make and refuses a mixture of two modes, naming the key.

use super::average::ModelAverage;
use super::conditional::RhoProfile;
use super::likelihood::FactorReport;
use super::marginal::MarginalFit;
use super::no_discrepancy::NoDiscrepancyFit;
use super::theta::ThetaPosterior;
use super::{MarginalModeFit, ModeFit, Module3};
use crate::params::ModeKind;
use crate::surrogate::gps::CoefficientGps;
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

/// What the conditional mode ([`crate::CoefficientMode::ConditionalOnTheta`]) fitted.
#[derive(Debug, Clone)]
pub struct ConditionalFit {
    /// The profile search for `ρ` (the Eq.-30 value is kept inside it).
    pub rho_profile: RhoProfile,
    /// The GPs refitted at `ρ*`, when they fit at least as well as Module 2's and replace them.
    pub refit_gps: Option<CoefficientGps>,
    /// The posterior-averaged GP targets `E_θ[α̂(θ)]` (`N_e x K`).
    pub alpha_hat: DMatrix<f64>,
    /// The smoother weights (`N_e x K`) of `E_θ[α̂(θ)] − α̂`: the GP mean at `x` becomes
    /// `μ_k(x) + Σ_k(x, X) w_k` (`ConditionalCoefficients::weights`).
    pub alpha_correction: DMatrix<f64>,
}

impl ModeFit {
    /// The coefficient mode this fit belongs to (without its settings).
    pub fn kind(&self) -> ModeKind {
        match self {
            Self::PriorMarginal => ModeKind::PriorMarginal,
            Self::ConditionalOnTheta(_) => ModeKind::ConditionalOnTheta,
            Self::Marginal(_) => ModeKind::Marginal,
        }
    }
}

/// The saved layout, borrowed for writing (the field order is the file's).
#[derive(Serialize)]
struct Written<'a> {
    rho_star: f64,
    rho_profile: Option<&'a RhoProfile>,
    refit_gps: Option<&'a CoefficientGps>,
    alpha_hat: Option<&'a DMatrix<f64>>,
    alpha_correction: Option<&'a DMatrix<f64>>,
    sigma_eps: f64,
    sigma_eps_estimated: bool,
    covariance: &'a FactorReport,
    posterior: &'a ThetaPosterior,
    posterior_no_discrepancy: &'a ThetaPosterior,
    no_discrepancy: Option<&'a NoDiscrepancyFit>,
    marginal: Option<&'a MarginalFit>,
    averaged: Option<&'a ModelAverage>,
}

impl Serialize for Module3 {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let c = self.conditional();
        Written {
            rho_star: self.rho_star,
            rho_profile: c.map(|c| &c.rho_profile),
            refit_gps: c.and_then(|c| c.refit_gps.as_ref()),
            alpha_hat: c.map(|c| &c.alpha_hat),
            alpha_correction: c.map(|c| &c.alpha_correction),
            sigma_eps: self.sigma_eps,
            sigma_eps_estimated: self.sigma_eps_estimated,
            covariance: &self.covariance,
            posterior: &self.posterior,
            posterior_no_discrepancy: &self.posterior_no_discrepancy,
            no_discrepancy: self.no_discrepancy.as_ref(),
            marginal: self.marginal(),
            averaged: self.averaged(),
        }
        .serialize(s)
    }
}

/// The saved layout, read.
#[derive(Deserialize)]
pub(crate) struct Read {
    rho_star: f64,
    rho_profile: Option<RhoProfile>,
    refit_gps: Option<CoefficientGps>,
    alpha_hat: Option<DMatrix<f64>>,
    alpha_correction: Option<DMatrix<f64>>,
    sigma_eps: f64,
    sigma_eps_estimated: bool,
    covariance: FactorReport,
    posterior: ThetaPosterior,
    posterior_no_discrepancy: ThetaPosterior,
    #[serde(default)]
    no_discrepancy: Option<NoDiscrepancyFit>,
    #[serde(default)]
    marginal: Option<MarginalFit>,
    #[serde(default)]
    averaged: Option<ModelAverage>,
}

impl TryFrom<Read> for Module3 {
    type Error = String;

    fn try_from(r: Read) -> Result<Self, String> {
        let conditional = [
            ("rho_profile", r.rho_profile.is_some()),
            ("refit_gps", r.refit_gps.is_some()),
            ("alpha_hat", r.alpha_hat.is_some()),
            ("alpha_correction", r.alpha_correction.is_some()),
        ];
        let given = |keys: &[(&'static str, bool)]| -> Vec<&'static str> {
            keys.iter().filter(|(_, g)| *g).map(|(k, _)| *k).collect()
        };
        let mode = match (r.marginal, r.alpha_correction) {
            (Some(fit), _) => {
                let stray = given(&conditional);
                if !stray.is_empty() {
                    return Err(format!(
                        "module3 holds the marginal mode's fit and the conditional mode's {}: \
                         a calibration has one mode",
                        stray.join(", ")
                    ));
                }
                ModeFit::Marginal(Box::new(MarginalModeFit {
                    fit,
                    averaged: r.averaged,
                }))
            }
            (None, Some(alpha_correction)) => {
                let (Some(rho_profile), Some(alpha_hat)) = (r.rho_profile, r.alpha_hat) else {
                    return Err("module3.alpha_correction (the conditional mode) needs \
                                module3.rho_profile and module3.alpha_hat too"
                        .into());
                };
                if r.averaged.is_some() {
                    return Err("module3.averaged belongs to the marginal mode, but the \
                                calibration holds the conditional mode's fit"
                        .into());
                }
                ModeFit::ConditionalOnTheta(Box::new(ConditionalFit {
                    rho_profile,
                    refit_gps: r.refit_gps,
                    alpha_hat,
                    alpha_correction,
                }))
            }
            (None, None) => {
                let mut stray = given(&conditional);
                if r.averaged.is_some() {
                    stray.push("averaged");
                }
                if !stray.is_empty() {
                    return Err(format!(
                        "module3.{} given without the fit of its mode (module3.marginal or \
                         module3.alpha_correction)",
                        stray.join(", module3.")
                    ));
                }
                ModeFit::PriorMarginal
            }
        };
        Ok(Module3 {
            rho_star: r.rho_star,
            sigma_eps: r.sigma_eps,
            sigma_eps_estimated: r.sigma_eps_estimated,
            covariance: r.covariance,
            posterior: r.posterior,
            posterior_no_discrepancy: r.posterior_no_discrepancy,
            no_discrepancy: r.no_discrepancy,
            mode,
        })
    }
}
