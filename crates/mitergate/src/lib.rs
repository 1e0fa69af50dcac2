//! `mitergate`: a finite-element miter gate leaf, condensed to the quoin and the strain gauges,
//! with a quoin contact model and synthetic / field data generators.
//!
//! Units throughout: inches, lbf, psi, lbf/in for line loads, microstrain for strains.
//!
//! # The finite-element leaf (paper Sec. 4.1, Eq. 47)
//!
//! The paper calibrated the quoin contact forces of a USACE Greenup-lock miter gate against an
//! ABAQUS shell model. We do not have that model, so this crate builds its own, parametrically:
//!
//! * [`GateConfig`] — every dimension of a horizontally framed leaf (skin plate, horizontal
//!   girders with downstream flanges, vertical diaphragms, quoin and miter end posts with bearing
//!   webs), the material, the mesh density and the strain gauges. [`GateConfig::default`] is an
//!   Ohio-River-lock-like leaf read from the embedded `data/default_gate.toml`.
//! * [`GateModel::build`] meshes the leaf with flat 4-node shells ([`fe::shell`]: QM6 incompatible-
//!   mode membrane + drilling penalty + MITC4 plate bending), applies the pintle, gudgeon and
//!   miter-bearing supports, assembles the sparse stiffness and factors it once (sparse
//!   supernodal Cholesky from `faer`).
//! * [`GateModel::condense`] reduces the leaf to what calibration needs: the strain matrix
//!   `A` of Eq. 47, the water terms and the quoin flexibility, as a
//!   [`CondensedGate`], using adjoint solves.
//!
//! Coordinates (the leaf frame): `x` along the leaf from the quoin (`x = 0`) to the miter end
//! (`x = L`); `y` normal to the skin plate, positive downstream (the skin plate is the plane
//! `y = 0`, framing at `y > 0`); `z` up from the sill (`z = 0`) to the top of the quoin
//! (`z = H`). Full-DOF vectors have 6 entries per node `[ux, uy, uz, rx, ry, rz]` (in, rad; or
//! lbf, lbf·in for loads).
//!
//! ```
//! use mitergate::{GateConfig, GateModel};
//! // a coarse version of the default leaf (the default mesh has 12 in elements)
//! let mut cfg = GateConfig::default();
//! cfg.mesh.element_size = 60.0;
//! let model = GateModel::build(&cfg).unwrap();
//! let f = model.water_load(600.0, 100.0).unwrap();
//! let u = model.solve(&f).unwrap();
//! let strains = model.gauge_strains(&u); // microstrain, one per gauge
//! assert_eq!(strains.len(), 7);
//! ```
//!
//! Users with their own gate model bring it as an Abaqus / CalculiX deck ([`inp`]): `S4`/`S4R`
//! quads, `S3` triangles ([`fe::tri`]) and `B31` beams ([`fe::beam`]) are built into the same
//! sparse system, and [`inp::ImportedModel::condense`] with an [`inp::ImportSpec`] (quoin set,
//! skin set, frame, gauges) gives the same [`CondensedGate`] through the same code.
//!
//! See `docs/mitergate.md` for the model description and `docs/verification.md` for the
//! element and model verification.
//!
//! # Contact, data and the multi-level model (paper Sec. 4.1-4.3)
//!
//! * [`condense`]: the condensed gate (`C`, `T`, `A`, water tables), the contract between
//!   the FE model and everything downstream.
//! * [`contact`]: the quoin contact model `g_BC(x, θ)` with a bottom gap (Eq. 45-46): linear
//!   normal springs without tension, the bilinear tangential law, solved exactly by an
//!   active-set method on the `2m`-sized condensed system (see `docs/contact.md`).
//! * [`multilevel`](mod@multilevel): `mlmodel` trait implementations (contact forces as the
//!   unobservable model, strains as the linear observable model) and the one constructor of
//!   the gate's multi-level model ([`build_contact`], then [`multilevel()`]).
//! * [`data::truth`]: the paper's synthetic truth (Sec. 4.3, Eq. 53-54, Table 1) and a check
//!   that the discrepancy is visible through the gauges.
//! * [`data::field`]: a field-data simulator (months of lockages, pools, temperatures and
//!   gauge effects such as thermal strain, drift or a growing gap) around any true strain
//!   function, for the close-the-loop workflow of `bamudi` (see `docs/closeloop.md`).
//!
//! # Layers
//!
//! `error` ← [`fe`] (elements, assembly) ← [`gate`] (the parametric leaf) ← [`condense`] ←
//! [`contact`] ← [`multilevel`](mod@multilevel), [`data`]; [`inp`] imports and exports decks
//! through `fe`, `gate` and `condense`. Each module imports from the layers below it, never
//! from the crate root. The feature `testing` adds `testing::doc_gate`, a tiny condensed gate
//! for documentation examples and tests.

// `!(x > 0.0)` is used on purpose throughout: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

/// The crate README's example, compiled and run as a doc test.
#[doc = include_str!("../README.md")]
#[cfg(doctest)]
pub struct ReadmeDoctest;

pub mod condense;
pub mod contact;
pub mod data;
pub mod error;
pub mod fe;
pub mod gate;
pub mod inp;
pub mod multilevel;
pub mod quoin_block;
pub mod reality;
#[cfg(any(test, feature = "testing"))]
pub mod testing;

pub use condense::{CondensedGate, DEFAULT_NU, HydrostaticTable, RigidQuoinResponse};
pub use contact::{ContactModel, ContactParams, ContactSolution};
pub use error::GateError;
pub use fe::{DOF_NAMES, Reactions};
pub use gate::{
    GateConfig, GateModel, MAX_ELEMENT_SIZE_IN, MAX_GAUGE_READING_MICROSTRAIN, WATER_LEVEL_RANGE,
};
pub use multilevel::{
    ContactForceModel, GateMultiLevel, GateSummary, MIN_HEAD_IN, MultiLevelSpec, StrainModel,
    build_contact, multilevel,
};
pub use quoin_block::{QuoinBlockModel, QuoinBlockParams};
