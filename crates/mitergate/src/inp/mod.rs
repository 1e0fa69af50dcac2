//! Abaqus / CalculiX input decks (`.inp`): export of the gate model, import of a user's shell
//! model, and the build of an imported deck into a supported, factored [`ShellModel`](crate::fe::ShellModel).
//!
//! # Export
//!
//! [`export_gate`] writes the meshed leaf of a [`crate::gate::GateModel`] as a CalculiX-compatible
//! deck: nodes, `S4` elements with one element set per structural member (`SKIN`,
//! `GIRDER_WEB_3`, `GIRDER_FLANGE_3`, `DIAPHRAGM_1`, `QUOIN_PLATE`, `MITER_PLATE`,
//! `QUOIN_BEARING_WEB`, `MITER_BEARING_WEB`), one `*SHELL SECTION` per member, the steel
//! (`*MATERIAL`, `*ELASTIC`), the node sets `QUOIN`, `MITER`, `PINTLE`, `GUDGEON`, the gauge
//! sets `GAUGE_<name>` (elements containing the gauge point, and their nodes), the supports
//! (pintle `1–3`, gudgeon `1–2`, the skewed miter roller `u·m = 0` as a `*TRANSFORM` of the
//! `MITER` set with local `x = m` and `*BOUNDARY MITER, 1, 1`, or as one `*EQUATION` per node),
//! optionally the held quoin (`QUOIN, 1, 2`: both `n` and `t` held fixes `ux` and `uy`), and
//! a `*STEP` / `*STATIC` with the consistent hydrostatic nodal loads as `*CLOAD` and output
//! requests (`*NODE PRINT` of `U`, `*NODE FILE` / `*EL FILE` of `U`, `S`, `E`).
//! Numbers are written in the shortest form that reads back to the same `f64`, so a round
//! trip is exact.
//!
//! # Import
//!
//! [`InpModel::parse`] reads the subset of the Abaqus keyword language that describes a
//! linear static shell model:
//!
//! | keyword | parameters | stored as |
//! |---|---|---|
//! | `*HEADING` | | [`InpModel::heading`] |
//! | `*NODE` | `NSET` | [`InpModel::nodes`] (missing `z` = 0) |
//! | `*ELEMENT` | `TYPE` = `S4`, `S4R`, `S3`, `B31`; `ELSET` | [`InpModel::elements`] |
//! | `*NSET`, `*ELSET` | `NSET` / `ELSET`, `GENERATE` | ids and nested set names |
//! | `*MATERIAL`, `*ELASTIC`, `*DENSITY` | `NAME`; `TYPE=ISOTROPIC` | [`InpMaterial`] |
//! | `*SHELL SECTION` | `ELSET`, `MATERIAL` | [`ShellSection`] (thickness) |
//! | `*BEAM SECTION` | `ELSET`, `MATERIAL`, `SECTION` | [`BeamSection`] (dimensions, direction) |
//! | `*BEAM GENERAL SECTION` | `ELSET`, `SECTION` (default `GENERAL`), `MATERIAL` | [`BeamSection`] (`A, I11, I12, I22, J`, direction, `E, G`) |
//! | `*BOUNDARY` | | [`Boundary`] (`ENCASTRE`, `PINNED` or DOF ranges, value 0) |
//! | `*TRANSFORM` | `NSET`, `TYPE=R` | [`Transform`] |
//! | `*EQUATION` | | [`Equation`] |
//! | `*STEP`, `*STATIC`, `*CLOAD`, `*END STEP` | | [`InpStep`] |
//! | `*NODE PRINT`, `*EL PRINT`, `*NODE FILE`, `*EL FILE`, `*OUTPUT`, `*NODE OUTPUT`, `*ELEMENT OUTPUT` | | skipped (output requests) |
//!
//! Keywords and parameters are case-insensitive; set and material names are upper-cased (Abaqus
//! names are case-insensitive). `**` starts a comment line. A keyword line ending in a comma
//! continues on the next line; `*ELEMENT` data lines continue until the element has all its
//! nodes. Any other keyword is a [`GateError::InpParse`](crate::error::GateError::InpParse) naming the line and the keyword.
//!
//! # Building a stiffness model from a deck
//!
//! [`InpModel::build`] turns the deck into an [`ImportedModel`]: `S4` and `S4R` elements become
//! our flat shell quadrilateral (QM6 membrane + MITC4 bending, fully integrated: `S4R`'s reduced
//! integration and hourglass control are not reproduced); `S3` elements the flat triangle of
//! [`crate::fe::tri`] (Allman membrane with drilling rotations + DKT bending); `B31` elements the
//! two-node Timoshenko beam of [`crate::fe::beam`] (sections `RECT` and `GENERAL`, Abaqus's axis
//! convention), all assembled into one sparse system. All shell sections must use one
//! isotropic material. Supports come from `*BOUNDARY` (homogeneous only), `*TRANSFORM` (one
//! local translation fixed = a skewed roller; all three = fixed) and `*EQUATION` (`a ux + b uy
//! + c uz = 0` of one node = a roller with normal `(a, b, c)`). Loads of a step come from
//! `*CLOAD` (in the local frame of transformed nodes, as in Abaqus).
//!
//! # Condensing a deck: bring your own gate
//!
//! [`ImportedModel::condense`] (or [`crate::condense::CondensedGate::from_inp_str`]) reduces
//! the deck to the same [`crate::condense::CondensedGate`] as [`crate::gate::GateModel::condense`],
//! through the same code. What the deck cannot say is given by an [`ImportSpec`] (builder or
//! TOML sidecar): the quoin node set (default `QUOIN`), the skin element set carrying the
//! water (default `SKIN`), the vertical and the sill, the quoin normal `n` (from the wall into
//! the gate) and the downstream side (which fixes `t`), and the gauges (point, face,
//! direction, optional element set). The defaults are the names and the frame the exporter
//! writes, so [`ImportSpec::for_exported_gate`] is all an exported deck needs.
//!
//! ```
//! use mitergate::inp::{export_gate, ExportOptions, InpModel};
//! use mitergate::{GateConfig, GateModel};
//! let mut cfg = GateConfig::default();
//! cfg.mesh.element_size = 96.0;
//! let gate = GateModel::build(&cfg).unwrap();
//! let deck = export_gate(&gate, &ExportOptions::default()).unwrap();
//! let back = InpModel::parse(&deck).unwrap();
//! assert_eq!(back.to_shell_mesh().unwrap().mesh, gate.mesh().shell);
//! ```

mod build;
mod cards;
mod condense;
mod export;
mod parse;

pub use build::{ImportedMesh, ImportedModel};
pub use condense::{Frame, ImportGauge, ImportSpec};
pub use export::{ExportOptions, MiterConstraint, export_gate};

use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// Element types the reader understands.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum InpElementType {
    /// 4-node shell (full integration in Abaqus).
    S4,
    /// 4-node shell with reduced integration.
    S4R,
    /// 3-node shell.
    S3,
    /// 2-node linear beam.
    B31,
}

impl InpElementType {
    /// Number of nodes of the element.
    ///
    /// ```
    /// assert_eq!(mitergate::inp::InpElementType::S3.n_nodes(), 3);
    /// ```
    pub fn n_nodes(self) -> usize {
        match self {
            Self::S4 | Self::S4R => 4,
            Self::S3 => 3,
            Self::B31 => 2,
        }
    }

    /// The Abaqus name (`S4`, `S4R`, `S3`, `B31`).
    ///
    /// ```
    /// assert_eq!(mitergate::inp::InpElementType::S4R.name(), "S4R");
    /// ```
    pub fn name(self) -> &'static str {
        match self {
            Self::S4 => "S4",
            Self::S4R => "S4R",
            Self::S3 => "S3",
            Self::B31 => "B31",
        }
    }

    fn from_name(s: &str) -> Option<Self> {
        match s {
            "S4" => Some(Self::S4),
            "S4R" => Some(Self::S4R),
            "S3" => Some(Self::S3),
            "B31" => Some(Self::B31),
            _ => None,
        }
    }
}

/// One element of the deck.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InpElement {
    /// Element id (label) in the deck.
    pub id: u64,
    /// Element type.
    pub kind: InpElementType,
    /// Node ids (labels), in the deck's order.
    pub nodes: Vec<u64>,
    /// Line of the deck where the element is defined (1-based).
    pub line: usize,
}

/// Isotropic linear elastic material (psi in the gate's units).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct InpMaterial {
    /// `(E, ν)` from `*ELASTIC`, if given.
    pub elastic: Option<(f64, f64)>,
    /// Mass density from `*DENSITY`, if given (stored, unused by the static model).
    pub density: Option<f64>,
}

/// A `*SHELL SECTION`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ShellSection {
    /// Element set (upper case).
    pub elset: String,
    /// Material name (upper case).
    pub material: String,
    /// Thickness (in).
    pub thickness: f64,
    /// Line of the keyword (1-based).
    pub line: usize,
}

/// A `*BEAM SECTION` or `*BEAM GENERAL SECTION` (see [`crate::fe::beam`] for the axes and the
/// supported section types).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BeamSection {
    /// Element set (upper case).
    pub elset: String,
    /// Material name (upper case; empty when a `*BEAM GENERAL SECTION` gives its moduli).
    pub material: String,
    /// Section type (`RECT`, `CIRC`, `PIPE`, `BOX`, `I`, `GENERAL`, ...; upper case).
    pub section: String,
    /// First data line: the section dimensions (or general section properties).
    pub data: Vec<f64>,
    /// Second data line: the direction of the first section axis, if given.
    pub direction: Option<[f64; 3]>,
    /// Third data line of a `*BEAM GENERAL SECTION`: `E, G` (psi).
    pub moduli: Option<[f64; 2]>,
    /// Defined by `*BEAM GENERAL SECTION` (else `*BEAM SECTION`).
    pub general_keyword: bool,
    /// Line of the keyword (1-based).
    pub line: usize,
}

/// A node or a node set named in a `*BOUNDARY`, `*CLOAD` or `*EQUATION` line.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub enum NodeRef {
    /// A node id.
    Node(u64),
    /// A node set name (upper case).
    Set(String),
}

/// One `*BOUNDARY` line: DOFs `first..=last` (1-based, 1–3 translations, 4–6 rotations) of
/// the target held at `value` (only 0 is supported by the build).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Boundary {
    /// Node or node set.
    pub target: NodeRef,
    /// First DOF (1-based).
    pub first_dof: usize,
    /// Last DOF (1-based).
    pub last_dof: usize,
    /// Prescribed value (in or rad).
    pub value: f64,
    /// Line (1-based).
    pub line: usize,
}

/// A `*TRANSFORM, TYPE=R`: the local `x` axis along `a`, local `y` in the plane of `a` and `b`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Transform {
    /// Node set (upper case).
    pub nset: String,
    /// Point `a` (direction of local `x`).
    pub a: [f64; 3],
    /// Point `b` (local `x`–`y` plane).
    pub b: [f64; 3],
    /// Line (1-based).
    pub line: usize,
}

impl Transform {
    /// Rows: the local axes `x, y, z` in global coordinates.
    ///
    /// ```
    /// use mitergate::inp::Transform;
    /// let t = Transform { nset: "S".into(), a: [0., 2., 0.], b: [-1., 0., 0.], line: 1 };
    /// let r = t.axes().unwrap();
    /// assert_eq!(r[0], [0., 1., 0.]);
    /// assert_eq!(r[2], [0., 0., 1.]);
    /// ```
    pub fn axes(&self) -> Option<[[f64; 3]; 3]> {
        let a = nalgebra::Vector3::from(self.a);
        let b = nalgebra::Vector3::from(self.b);
        let x = a.try_normalize(1e-14)?;
        let y = (b - x * b.dot(&x)).try_normalize(1e-14 * b.norm().max(1e-300))?;
        let z = x.cross(&y);
        Some([x.into(), y.into(), z.into()])
    }
}

/// A linear constraint `Σ c_i u(node_i, dof_i) = 0` (`*EQUATION`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Equation {
    /// `(node, dof 1-based, coefficient)` terms.
    pub terms: Vec<(NodeRef, usize, f64)>,
    /// Line of the term count (1-based).
    pub line: usize,
}

/// A concentrated load (`*CLOAD` line): `value` (lbf or lbf·in) on DOF `dof` (1-based).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Cload {
    /// Node or node set.
    pub target: NodeRef,
    /// DOF (1-based).
    pub dof: usize,
    /// Magnitude.
    pub value: f64,
    /// Line (1-based).
    pub line: usize,
}

/// A `*STEP` … `*END STEP` block.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct InpStep {
    /// `*STATIC` was given.
    pub is_static: bool,
    /// Concentrated loads.
    pub cloads: Vec<Cload>,
    /// Boundary conditions given inside the step.
    pub boundaries: Vec<Boundary>,
    /// Line of `*STEP` (1-based).
    pub line: usize,
}

/// A parsed `.inp` deck (see the [module docs](self) for the supported keywords).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct InpModel {
    /// `*HEADING` text lines.
    pub heading: Vec<String>,
    /// `(id, [x, y, z])` (in) in deck order.
    pub nodes: Vec<(u64, [f64; 3])>,
    /// Elements in deck order.
    pub elements: Vec<InpElement>,
    /// Node sets (upper-case name → node ids, in order of appearance, duplicates removed).
    pub nsets: BTreeMap<String, Vec<u64>>,
    /// Element sets (upper-case name → element ids).
    pub elsets: BTreeMap<String, Vec<u64>>,
    /// Materials by upper-case name.
    pub materials: BTreeMap<String, InpMaterial>,
    /// Shell sections.
    pub shell_sections: Vec<ShellSection>,
    /// Beam sections.
    pub beam_sections: Vec<BeamSection>,
    /// Model-level boundary conditions.
    pub boundaries: Vec<Boundary>,
    /// Local frames of node sets.
    pub transforms: Vec<Transform>,
    /// Linear constraints.
    pub equations: Vec<Equation>,
    /// Analysis steps.
    pub steps: Vec<InpStep>,
}
