//! The gate reduced to what calibration needs: the quoin and the gauges (Module 1 of BA-MUDI).
//!
//! A [`CondensedGate`] is produced once from the finite-element model by static condensation
//! and then used by the contact model (`g_BC`, Eq. 45-46) and the strain model (Eq. 47):
//!
//! * strain (microstrain) = `A q + s_w(h_up, h_down)`, `q` the quoin line loads (lbf/in) at the
//!   `N_u` representation points, component blocked `[normal; tangential]`;
//! * quoin-node displacements (in) = `C P + u_w(h_up, h_down)`, `P` the nodal quoin forces (lbf)
//!   at the `m` FE quoin nodes, blocked `[normal; tangential]`, `C` symmetric positive definite.
//!
//! # Sign conventions
//! At every quoin node the unit vector `n` points from the wall quoin block into the gate (the
//! direction in which a compressive contact force pushes the gate); `t` is horizontal, normal
//! to `n`, pointing downstream. Forces and displacement components are both measured along
//! `(n, t)`, so `C` is symmetric positive definite and a contact penetration is `-d_N > 0`.
//!
//! # Water loads
//! Water at level `h` (inches above the sill) on one face of the skin plate gives a response that
//! is a piecewise cubic in `h` with breakpoints at the skin-node heights (a linear pressure
//! integrated against bilinear shape functions). [`HydrostaticTable`] stores values and slopes at
//! the breakpoints and evaluates that cubic exactly by Hermite interpolation. Downstream water
//! acts on the downstream face of the same skin plate, so the response to levels
//! `(h_up, h_down)` is `R(h_up) - R(h_down)`.
//!
//! # Condensation
//!
//! With `K` the supported stiffness, `b_g` the strain functional of gauge `g` and `Q` the unit
//! quoin loads (along `n` and `t` at the `m` quoin nodes), `K X = Q` (`2m` solves) gives the
//! quoin flexibility `C = Qᵀ X` and `K Λ = B` (one adjoint solve per gauge) the strain matrix
//! `A = Λᵀ Q blockdiag(T, T)`; the water terms are `Λᵀ f_w(h)` and `Xᵀ f_w(h)` tabulated with
//! their `h`-derivatives. The algorithm is written once, for the parametric
//! [`GateModel`](crate::gate::GateModel) ([`GateModel::condense`](crate::gate::GateModel::condense))
//! and for imported decks
//! ([`ImportedModel::condense`](crate::inp::ImportedModel::condense)).

mod algorithm;
mod condensed;

pub(crate) use algorithm::{CondensationSource, SparseLoad, condense, sorted_unique};
pub use algorithm::{DEFAULT_NU, RigidQuoinResponse};
pub use condensed::{CondensedGate, HydrostaticTable};
