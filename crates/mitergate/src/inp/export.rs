//! Writing the gate model as an Abaqus / CalculiX deck.

use crate::error::GateError;
use crate::gate::{GateModel, Member};
use std::collections::BTreeMap;
use std::fmt::Write;

/// How the skewed miter roller `u·m = 0` is written.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum MiterConstraint {
    /// `*TRANSFORM` of the `MITER` set (local `x = m`) and `*BOUNDARY MITER, 1, 1`.
    /// Displacements of those nodes are then printed in the local frame by CalculiX.
    #[default]
    Transform,
    /// One `*EQUATION` `m_x ux + m_y uy = 0` per miter node.
    Equation,
}

/// Options of [`export_gate`].
#[derive(Debug, Clone, PartialEq)]
pub struct ExportOptions {
    /// Upstream water level (in) of the load step.
    pub h_up: f64,
    /// Downstream water level (in) of the load step.
    pub h_down: f64,
    /// Hold the quoin nodes in `n` and `t` (`*BOUNDARY QUOIN, 1, 2`): the rigid-quoin case of
    /// [`GateModel::rigid_quoin_response`].
    pub hold_quoin: bool,
    /// Miter roller representation.
    pub miter: MiterConstraint,
}

impl Default for ExportOptions {
    /// Full head (`h_up = 744`, `h_down = 24` in), free quoin, `*TRANSFORM` miter roller.
    fn default() -> Self {
        Self {
            h_up: 744.0,
            h_down: 24.0,
            hold_quoin: false,
            miter: MiterConstraint::Transform,
        }
    }
}

impl ExportOptions {
    /// Sets the water levels (in).
    ///
    /// ```
    /// let o = mitergate::inp::ExportOptions::default().with_levels(600.0, 50.0);
    /// assert_eq!((o.h_up, o.h_down), (600.0, 50.0));
    /// ```
    pub fn with_levels(mut self, h_up: f64, h_down: f64) -> Self {
        self.h_up = h_up;
        self.h_down = h_down;
        self
    }

    /// Holds (or frees) the quoin nodes.
    ///
    /// ```
    /// assert!(mitergate::inp::ExportOptions::default().with_hold_quoin(true).hold_quoin);
    /// ```
    pub fn with_hold_quoin(mut self, hold: bool) -> Self {
        self.hold_quoin = hold;
        self
    }

    /// Chooses the miter roller representation.
    ///
    /// ```
    /// use mitergate::inp::{ExportOptions, MiterConstraint};
    /// let o = ExportOptions::default().with_miter(MiterConstraint::Equation);
    /// assert_eq!(o.miter, MiterConstraint::Equation);
    /// ```
    pub fn with_miter(mut self, miter: MiterConstraint) -> Self {
        self.miter = miter;
        self
    }
}

/// Element set name of a member.
pub(crate) fn member_set(m: Member) -> String {
    match m {
        Member::Skin => "SKIN".into(),
        Member::GirderWeb(i) => format!("GIRDER_WEB_{i}"),
        Member::GirderFlange(i) => format!("GIRDER_FLANGE_{i}"),
        Member::Diaphragm(i) => format!("DIAPHRAGM_{i}"),
        Member::QuoinPlate => "QUOIN_PLATE".into(),
        Member::MiterPlate => "MITER_PLATE".into(),
        Member::QuoinBearingWeb => "QUOIN_BEARING_WEB".into(),
        Member::MiterBearingWeb => "MITER_BEARING_WEB".into(),
    }
}

/// CalculiX reads at most 20 characters per data field.
const MAX_FIELD: usize = 20;

/// Shortest text that reads back to the same `f64` (plain, else with exponent), or, when that
/// is longer than CalculiX's 20-character fields, the most digits that fit (relative rounding
/// below 1e-13).
fn num(v: f64) -> String {
    // both forms are the shortest round-trip representation; prefer the plain one
    for s in [format!("{v}"), format!("{v:e}")] {
        if s.len() <= MAX_FIELD {
            return s;
        }
    }
    let s = format!("{v:e}");
    (1..16)
        .rev()
        .map(|p| format!("{v:.p$e}"))
        .find(|s| s.len() <= MAX_FIELD)
        .unwrap_or(s)
}

/// Writes ids, 16 per line (the Abaqus limit for set data lines).
fn id_lines(out: &mut String, ids: impl IntoIterator<Item = usize>) {
    let ids: Vec<usize> = ids.into_iter().collect();
    for chunk in ids.chunks(16) {
        let line: Vec<String> = chunk.iter().map(|i| i.to_string()).collect();
        let _ = writeln!(out, "{}", line.join(", "));
    }
}

/// The gate as an Abaqus / CalculiX deck: mesh, member sets and sections, material, node and
/// gauge sets, supports, and one static step with the consistent water loads as `*CLOAD`
/// (see the [module docs](super)). Node `i` and element `e` of the mesh get ids `i + 1` and
/// `e + 1`.
///
/// ```
/// use mitergate::inp::{export_gate, ExportOptions};
/// use mitergate::{GateConfig, GateModel};
/// let mut cfg = GateConfig::default();
/// cfg.mesh.element_size = 96.0;
/// let gate = GateModel::build(&cfg).unwrap();
/// let deck = export_gate(&gate, &ExportOptions::default()).unwrap();
/// assert!(deck.contains("*TRANSFORM, NSET=MITER, TYPE=R"));
/// assert!(deck.contains("*SHELL SECTION, ELSET=SKIN, MATERIAL=STEEL\n0.625"));
/// ```
pub fn export_gate(gate: &GateModel, opts: &ExportOptions) -> Result<String, GateError> {
    let cfg = gate.config();
    let mesh = gate.mesh();
    let load = gate.water_load(opts.h_up, opts.h_down)?;
    let mut out = String::new();
    let g = &cfg.geometry;
    let _ = writeln!(
        out,
        "*HEADING\nbamudi mitergate leaf: H = {} in, L = {} in, element size {} in; units in, lbf, psi\n\
         ** exported by mitergate::inp::export_gate; water h_up = {} in, h_down = {} in",
        num(g.quoin_height),
        num(g.leaf_length),
        num(cfg.mesh.element_size),
        num(opts.h_up),
        num(opts.h_down)
    );
    let thickness = write_mesh(&mut out, gate)?;
    let m = &cfg.material;
    let _ = writeln!(
        out,
        "*MATERIAL, NAME=STEEL\n*ELASTIC\n{}, {}",
        num(m.youngs_modulus),
        num(m.poisson_ratio)
    );
    for (set, t) in &thickness {
        let _ = writeln!(
            out,
            "*SHELL SECTION, ELSET={set}, MATERIAL=STEEL\n{}",
            num(*t)
        );
    }
    for (name, nodes) in [
        ("QUOIN", mesh.quoin_nodes.clone()),
        ("MITER", mesh.miter_nodes.clone()),
        ("PINTLE", vec![mesh.pintle_node]),
        ("GUDGEON", vec![mesh.gudgeon_node]),
    ] {
        let _ = writeln!(out, "*NSET, NSET={name}");
        id_lines(&mut out, nodes.iter().map(|n| n + 1));
    }
    write_gauge_sets(&mut out, gate)?;
    write_supports(&mut out, gate, opts);
    out.push_str("*STEP\n*STATIC\n*CLOAD\n");
    for (dof, v) in load.iter().enumerate().filter(|(_, v)| **v != 0.0) {
        let _ = writeln!(out, "{}, {}, {}", dof / 6 + 1, dof % 6 + 1, num(*v));
    }
    out.push_str(
        "*NODE PRINT, NSET=NALL\nU\n*NODE FILE, OUTPUT=3D\nU\n*EL FILE\nS, E\n*END STEP\n",
    );
    Ok(out)
}

/// Nodes (set `NALL`) and `S4` elements, one `*ELEMENT` block per run of elements of the same
/// member (which keeps the element order); returns the thickness of each member's set.
fn write_mesh(out: &mut String, gate: &GateModel) -> Result<BTreeMap<String, f64>, GateError> {
    let mesh = gate.mesh();
    let shell = &mesh.shell;
    out.push_str("*NODE, NSET=NALL\n");
    for (i, p) in shell.nodes.iter().enumerate() {
        let _ = writeln!(
            out,
            "{}, {}, {}, {}",
            i + 1,
            num(p[0]),
            num(p[1]),
            num(p[2])
        );
    }
    let mut thickness: BTreeMap<String, f64> = BTreeMap::new();
    let mut start = 0;
    while start < shell.elements.len() {
        let member = mesh.members[start];
        let mut end = start;
        while end < shell.elements.len() && mesh.members[end] == member {
            end += 1;
        }
        let set = member_set(member);
        let _ = writeln!(out, "*ELEMENT, TYPE=S4, ELSET={set}");
        for e in start..end {
            let el = &shell.elements[e];
            let t = *thickness.entry(set.clone()).or_insert(el.thickness);
            if t != el.thickness {
                return Err(GateError::InvalidMesh(format!(
                    "member {set} has elements of different thickness ({t}, {})",
                    el.thickness
                )));
            }
            let n = el.nodes.map(|n| n + 1);
            let _ = writeln!(out, "{}, {}, {}, {}, {}", e + 1, n[0], n[1], n[2], n[3]);
        }
        start = end;
    }
    Ok(thickness)
}

/// `GAUGE_<name>` element sets (elements whose face carries the gauge) and node sets (their
/// nodes), with the gauge point, face and direction in a comment.
fn write_gauge_sets(out: &mut String, gate: &GateModel) -> Result<(), GateError> {
    let cfg = gate.config();
    for (spec, point) in cfg.gauges.iter().zip(gate.gauge_points()) {
        let side = spec.location.instrumented_side();
        let elements = gauge_elements(gate, point, side);
        if elements.is_empty() {
            return Err(GateError::GaugeNotOnMesh {
                name: spec.name.clone(),
                point,
                side,
            });
        }
        let name = spec.name.to_uppercase();
        let _ = writeln!(
            out,
            "** gauge {}: point {:?} in, face towards {:?}, direction {:?}\n*ELSET, ELSET=GAUGE_{name}",
            spec.name, point, side, spec.direction
        );
        id_lines(out, elements.iter().map(|e| e + 1));
        let mut nodes: Vec<usize> = elements
            .iter()
            .flat_map(|&e| gate.mesh().shell.elements[e].nodes)
            .collect();
        nodes.sort_unstable();
        nodes.dedup();
        let _ = writeln!(out, "*NSET, NSET=GAUGE_{name}");
        id_lines(out, nodes.iter().map(|n| n + 1));
    }
    Ok(())
}

/// Elements containing `point` on their mid-plane with normal parallel to `side`.
fn gauge_elements(gate: &GateModel, point: [f64; 3], side: [f64; 3]) -> Vec<usize> {
    let s = nalgebra::Vector3::from(side).normalize();
    gate.shell_model()
        .quads()
        .iter()
        .enumerate()
        .filter(|(_, q)| {
            let (xi, eta, dist) = q.natural_coordinates(point);
            nalgebra::Vector3::from(q.normal()).dot(&s).abs() >= 0.99
                && dist.abs() <= 1e-6 * q.area().sqrt()
                && xi.abs() <= 1.0 + 1e-9
                && eta.abs() <= 1.0 + 1e-9
        })
        .map(|(e, _)| e)
        .collect()
}

fn write_supports(out: &mut String, gate: &GateModel, opts: &ExportOptions) {
    let m = gate.config().miter_direction();
    match opts.miter {
        MiterConstraint::Transform => {
            // local x = m, local y = z x m (in the plane of the leaf), local z = +z
            let _ = writeln!(
                out,
                "*TRANSFORM, NSET=MITER, TYPE=R\n{}, {}, {}, {}, {}, {}",
                num(m[0]),
                num(m[1]),
                num(m[2]),
                num(-m[1]),
                num(m[0]),
                num(0.0)
            );
        }
        MiterConstraint::Equation => {
            out.push_str("*EQUATION\n");
            for &n in &gate.mesh().miter_nodes {
                let _ = writeln!(
                    out,
                    "2\n{}, 1, {}, {}, 2, {}",
                    n + 1,
                    num(m[0]),
                    n + 1,
                    num(m[1])
                );
            }
        }
    }
    out.push_str("*BOUNDARY\nPINTLE, 1, 3\nGUDGEON, 1, 2\n");
    if opts.miter == MiterConstraint::Transform {
        out.push_str("MITER, 1, 1\n");
    }
    if opts.hold_quoin {
        // n and t span the horizontal plane, so holding both fixes ux and uy
        out.push_str("QUOIN, 1, 2\n");
    }
}
