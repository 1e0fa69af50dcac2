//! Condensing an imported deck to a [`CondensedGate`]: the user contract ([`ImportSpec`]) and
//! the [`CondensationSource`] of an [`ImportedModel`].

use super::{ImportedModel, InpModel};
use crate::condense::{CondensationSource, CondensedGate, SparseLoad, condense, sorted_unique};
use crate::error::GateError;
use crate::fe::loads::face_pressure_integrals;
use crate::fe::{ShellModel, Support};
use crate::gate::GateModel;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};
use std::collections::HashSet;
use std::path::Path;

/// A strain gauge of an imported gate: a point on a plate mid-surface (in), the instrumented
/// face (the side of the plate the gauge is bonded to, as a vector roughly normal to the
/// plate), and the measuring direction (in the plate's plane). The strain is membrane +
/// bending at that face, in microstrain; a point on a shared element edge averages the
/// elements that contain it. `elset` optionally restricts the search to an element set (the
/// exporter writes `GAUGE_<NAME>`).
///
/// ```
/// use mitergate::inp::ImportGauge;
/// let g = ImportGauge::new("SG1", [96.0, 30.0, 18.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0])
///     .with_elset("GAUGE_SG1");
/// assert_eq!(g.elset.as_deref(), Some("GAUGE_SG1"));
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImportGauge {
    /// Gauge name (output label).
    pub name: String,
    /// Point on the plate mid-surface (in, deck coordinates).
    pub point: [f64; 3],
    /// Vector towards the instrumented face (normal to the plate, either sign selects a face).
    pub side: [f64; 3],
    /// Measuring direction, in the plate's plane.
    pub direction: [f64; 3],
    /// Element set to search for the gauge point (default: every shell element).
    #[serde(default)]
    pub elset: Option<String>,
}

impl ImportGauge {
    /// A gauge searched on every shell element.
    ///
    /// ```
    /// let g = mitergate::inp::ImportGauge::new("G", [0.; 3], [0., 1., 0.], [1., 0., 0.]);
    /// assert!(g.elset.is_none());
    /// ```
    pub fn new(name: &str, point: [f64; 3], side: [f64; 3], direction: [f64; 3]) -> Self {
        Self {
            name: name.into(),
            point,
            side,
            direction,
            elset: None,
        }
    }

    /// Restricts the search to the element set `elset` (case-insensitive).
    ///
    /// ```
    /// let g = mitergate::inp::ImportGauge::new("G", [0.; 3], [0., 1., 0.], [1., 0., 0.])
    ///     .with_elset("gauge_g");
    /// assert_eq!(g.elset.as_deref(), Some("gauge_g"));
    /// ```
    pub fn with_elset(mut self, elset: &str) -> Self {
        self.elset = Some(elset.into());
        self
    }
}

/// What an imported deck cannot say by itself: which node set is the quoin, which elements
/// carry the water, the vertical and the quoin directions, and the gauges. Defaults are the
/// names and the frame written by [`super::export_gate`] (leaf frame: `x` from the quoin along
/// the leaf, `y` downstream, `z` up from the sill), so an exported deck needs only its gauges
/// ([`ImportSpec::for_exported_gate`] fills them in).
///
/// * **Quoin**: the node set [`quoin_nset`](Self::quoin_nset) (default `QUOIN`), the nodes
///   through which the wall's contact forces enter, one node per height. They must not be
///   supported in translation. `n` ([`quoin_normal`](Self::quoin_normal), horizontal) points
///   from the wall quoin block into the gate; `t` is the horizontal unit vector normal to `n`
///   on the downstream side (`t·downstream > 0`).
/// * **Heights**: `z = vertical·x − sill_elevation` (in above the sill). The quoin spans
///   `[0, H]`, `H` = [`quoin_height`](Self::quoin_height) or, if unset, the highest quoin node.
/// * **Water**: hydrostatic pressure `γ (h − z)₊` on the upstream face of the shell elements
///   of the element set [`skin_elset`](Self::skin_elset) (default `SKIN`), pushing each
///   element along its normal oriented towards [`downstream`](Self::downstream); downstream
///   water at `h_down` acts on the downstream face (response `R(h_up) − R(h_down)`).
/// * **Supports**: the deck's model-level `*BOUNDARY`, `*TRANSFORM` and `*EQUATION` (and
///   those of its first step), as in [`InpModel::build`]: the leaf must be stable without
///   quoin contact (pintle, gudgeon, miter bearing).
/// * **Gauges**: [`gauges`](Self::gauges), at least one.
///
/// The spec can be read from a TOML sidecar ([`ImportSpec::from_toml_str`]); every field
/// except `gauges` has a default.
///
/// ```
/// use mitergate::inp::{ImportGauge, ImportSpec};
/// let spec = ImportSpec::default()
///     .with_quoin_nset("QUOIN_LINE")
///     .with_gauge(ImportGauge::new("SG1", [96.0, 30.0, 18.0], [0., 0., 1.], [1., 0., 0.]));
/// assert_eq!(spec.skin_elset, "SKIN");
/// let toml = r#"
/// quoin_nset = "QUOIN_LINE"
/// [[gauges]]
/// name = "SG1"
/// point = [96.0, 30.0, 18.0]
/// side = [0.0, 0.0, 1.0]
/// direction = [1.0, 0.0, 0.0]
/// "#;
/// assert_eq!(ImportSpec::from_toml_str(toml).unwrap(), spec);
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ImportSpec {
    /// Node set of the quoin contact line (default `QUOIN`).
    pub quoin_nset: String,
    /// Element set of the skin plate that carries the water (default `SKIN`).
    pub skin_elset: String,
    /// Upward vertical direction (default `[0, 0, 1]`).
    pub vertical: [f64; 3],
    /// Coordinate of the sill along `vertical` (in, default 0).
    pub sill_elevation: f64,
    /// Quoin height `H` (in above the sill); `None`: the highest quoin node.
    pub quoin_height: Option<f64>,
    /// Horizontal quoin normal `n`, from the wall into the gate (default `[1, 0, 0]`).
    pub quoin_normal: [f64; 3],
    /// A vector pointing downstream (default `[0, 1, 0]`).
    pub downstream: [f64; 3],
    /// Unit weight of water (lbf/in³, default 0.0361).
    pub unit_weight: f64,
    /// Drilling penalty factor used when [`CondensedGate::from_inp_str`] builds the model
    /// (default `1e-3`, see [`crate::fe::shell`]).
    pub drilling_penalty: f64,
    /// The strain gauges, in output order.
    pub gauges: Vec<ImportGauge>,
}

impl Default for ImportSpec {
    fn default() -> Self {
        Self {
            quoin_nset: "QUOIN".into(),
            skin_elset: "SKIN".into(),
            vertical: [0.0, 0.0, 1.0],
            sill_elevation: 0.0,
            quoin_height: None,
            quoin_normal: [1.0, 0.0, 0.0],
            downstream: [0.0, 1.0, 0.0],
            unit_weight: 0.0361,
            drilling_penalty: 1e-3,
            gauges: Vec::new(),
        }
    }
}

impl ImportSpec {
    /// The spec of a deck written by [`super::export_gate`] from `gate`: default set names
    /// and frame, the gate's quoin normal, quoin height, unit weight, drilling penalty and its
    /// gauges (searched in their `GAUGE_<NAME>` element sets).
    ///
    /// ```
    /// use mitergate::{GateConfig, GateModel, inp::ImportSpec};
    /// let mut cfg = GateConfig::default();
    /// cfg.mesh.element_size = 96.0;
    /// let spec = ImportSpec::for_exported_gate(&GateModel::build(&cfg).unwrap());
    /// assert_eq!(spec.gauges.len(), 7);
    /// assert_eq!(spec.gauges[0].elset.as_deref(), Some("GAUGE_SG1"));
    /// ```
    pub fn for_exported_gate(gate: &GateModel) -> Self {
        let cfg = gate.config();
        let gauges = cfg
            .gauges
            .iter()
            .zip(gate.gauge_points())
            .map(|(g, p)| {
                ImportGauge::new(&g.name, p, g.location.instrumented_side(), g.direction)
                    .with_elset(&format!("GAUGE_{}", g.name.to_uppercase()))
            })
            .collect();
        Self {
            quoin_height: Some(cfg.geometry.quoin_height),
            quoin_normal: cfg.quoin_directions().0,
            unit_weight: cfg.water.unit_weight,
            drilling_penalty: cfg.mesh.drilling_penalty,
            gauges,
            ..Self::default()
        }
    }

    /// Parses a TOML sidecar (fields as in the struct; unknown keys are errors).
    ///
    /// ```
    /// let e = mitergate::inp::ImportSpec::from_toml_str("quoin_set = 'Q'").unwrap_err();
    /// assert!(e.to_string().contains("quoin_set"));
    /// ```
    pub fn from_toml_str(text: &str) -> Result<Self, GateError> {
        toml::from_str(text).map_err(|e| GateError::ConfigParse {
            path: None,
            message: e.to_string(),
        })
    }

    /// Reads a TOML sidecar file.
    ///
    /// ```
    /// let e = mitergate::inp::ImportSpec::from_file(std::path::Path::new("/no/spec.toml"));
    /// assert!(e.unwrap_err().to_string().contains("/no/spec.toml"));
    /// ```
    pub fn from_file(path: &Path) -> Result<Self, GateError> {
        let text = std::fs::read_to_string(path).map_err(|source| GateError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        toml::from_str(&text).map_err(|e| GateError::ConfigParse {
            path: Some(path.to_path_buf()),
            message: e.to_string(),
        })
    }

    /// Sets the quoin node set.
    ///
    /// ```
    /// assert_eq!(mitergate::inp::ImportSpec::default().with_quoin_nset("Q").quoin_nset, "Q");
    /// ```
    pub fn with_quoin_nset(mut self, name: &str) -> Self {
        self.quoin_nset = name.into();
        self
    }

    /// Sets the skin element set.
    ///
    /// ```
    /// assert_eq!(mitergate::inp::ImportSpec::default().with_skin_elset("S").skin_elset, "S");
    /// ```
    pub fn with_skin_elset(mut self, name: &str) -> Self {
        self.skin_elset = name.into();
        self
    }

    /// Sets the upward vertical and the sill's coordinate along it (in).
    ///
    /// ```
    /// let s = mitergate::inp::ImportSpec::default().with_vertical([0., 1., 0.], -12.0);
    /// assert_eq!((s.vertical, s.sill_elevation), ([0., 1., 0.], -12.0));
    /// ```
    pub fn with_vertical(mut self, vertical: [f64; 3], sill_elevation: f64) -> Self {
        self.vertical = vertical;
        self.sill_elevation = sill_elevation;
        self
    }

    /// Sets the quoin height `H` (in).
    ///
    /// ```
    /// assert_eq!(mitergate::inp::ImportSpec::default().with_quoin_height(762.0).quoin_height, Some(762.0));
    /// ```
    pub fn with_quoin_height(mut self, h: f64) -> Self {
        self.quoin_height = Some(h);
        self
    }

    /// Sets the quoin normal `n` (from the wall into the gate) and the downstream direction.
    ///
    /// ```
    /// let s = mitergate::inp::ImportSpec::default().with_directions([0., 1., 0.], [-1., 0., 0.]);
    /// assert_eq!(s.quoin_normal, [0., 1., 0.]);
    /// ```
    pub fn with_directions(mut self, quoin_normal: [f64; 3], downstream: [f64; 3]) -> Self {
        self.quoin_normal = quoin_normal;
        self.downstream = downstream;
        self
    }

    /// Sets the unit weight of water (lbf/in³).
    ///
    /// ```
    /// assert_eq!(mitergate::inp::ImportSpec::default().with_unit_weight(0.036).unit_weight, 0.036);
    /// ```
    pub fn with_unit_weight(mut self, gamma: f64) -> Self {
        self.unit_weight = gamma;
        self
    }

    /// Sets the drilling penalty factor used by [`CondensedGate::from_inp_str`].
    ///
    /// ```
    /// assert_eq!(mitergate::inp::ImportSpec::default().with_drilling_penalty(1e-2).drilling_penalty, 1e-2);
    /// ```
    pub fn with_drilling_penalty(mut self, alpha: f64) -> Self {
        self.drilling_penalty = alpha;
        self
    }

    /// Appends a gauge.
    ///
    /// ```
    /// use mitergate::inp::{ImportGauge, ImportSpec};
    /// let s = ImportSpec::default().with_gauge(ImportGauge::new("G", [0.; 3], [0., 1., 0.], [1., 0., 0.]));
    /// assert_eq!(s.gauges.len(), 1);
    /// ```
    pub fn with_gauge(mut self, gauge: ImportGauge) -> Self {
        self.gauges.push(gauge);
        self
    }

    /// Checks the numbers and directions, naming the offending field.
    ///
    /// ```
    /// use mitergate::inp::ImportSpec;
    /// let e = ImportSpec::default().with_directions([0., 0., 1.], [0., 1., 0.]).validate();
    /// assert!(e.unwrap_err().to_string().contains("quoin_normal"));
    /// ```
    pub fn validate(&self) -> Result<Frame, GateError> {
        let bad = |parameter: &str, reason: String| GateError::InvalidConfig {
            parameter: format!("import spec `{parameter}`"),
            reason,
        };
        let unit = |name: &str, v: [f64; 3]| {
            Vector3::from(v)
                .try_normalize(0.0)
                .filter(|u| u.iter().all(|c| c.is_finite()))
                .ok_or_else(|| bad(name, format!("{v:?} must be a finite non-zero vector")))
        };
        let vertical = unit("vertical", self.vertical)?;
        let n = unit("quoin_normal", self.quoin_normal)?;
        let down = unit("downstream", self.downstream)?;
        if n.dot(&vertical).abs() > 1e-6 {
            return Err(bad(
                "quoin_normal",
                format!(
                    "{:?} must be horizontal (normal to `vertical`)",
                    self.quoin_normal
                ),
            ));
        }
        let n = (n - vertical * n.dot(&vertical)).normalize();
        let t = vertical.cross(&n);
        let side = t.dot(&down);
        if side.abs() < 1e-6 {
            return Err(bad(
                "downstream",
                format!(
                    "{:?} must have a component normal to the quoin normal in the horizontal plane",
                    self.downstream
                ),
            ));
        }
        let t = t * side.signum();
        if !self.sill_elevation.is_finite() {
            return Err(bad("sill_elevation", "must be finite".into()));
        }
        if let Some(h) = self.quoin_height
            && !(h > 0.0 && h.is_finite())
        {
            return Err(bad("quoin_height", format!("{h} must be > 0")));
        }
        if !(self.unit_weight > 0.0 && self.unit_weight.is_finite()) {
            return Err(bad(
                "unit_weight",
                format!("{} must be > 0", self.unit_weight),
            ));
        }
        if !(self.drilling_penalty > 0.0 && self.drilling_penalty.is_finite()) {
            return Err(bad(
                "drilling_penalty",
                format!("{} must be > 0", self.drilling_penalty),
            ));
        }
        if self.gauges.is_empty() {
            return Err(bad("gauges", "at least one gauge is needed".into()));
        }
        Ok(Frame {
            vertical: vertical.into(),
            quoin_normal: n.into(),
            quoin_tangent: t.into(),
            downstream: down.into(),
        })
    }
}

/// The validated unit directions of an [`ImportSpec`].
///
/// ```
/// let f = mitergate::inp::ImportSpec::default()
///     .with_gauge(mitergate::inp::ImportGauge::new("G", [0.; 3], [0., 1., 0.], [1., 0., 0.]))
///     .validate().unwrap();
/// assert_eq!(f.quoin_tangent, [0.0, 1.0, 0.0]);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frame {
    /// Upward unit vertical.
    pub vertical: [f64; 3],
    /// Unit quoin normal `n` (horizontal, wall into gate).
    pub quoin_normal: [f64; 3],
    /// Unit quoin tangent `t` (horizontal, `⟂ n`, downstream side).
    pub quoin_tangent: [f64; 3],
    /// Unit downstream direction.
    pub downstream: [f64; 3],
}

/// `(node indices, unit force direction)` of a wetted skin face.
type WetFace = (Vec<usize>, [f64; 3]);

/// An imported model with its spec resolved: quoin nodes sorted by height, gauge functionals,
/// skin faces with their pressure directions.
struct ImportedLeaf<'a> {
    model: &'a ImportedModel,
    frame: Frame,
    sill: f64,
    gamma: f64,
    quoin_height: f64,
    quoin_nodes: Vec<usize>,
    quoin_heights: Vec<f64>,
    gauges: Vec<(String, SparseLoad)>,
    faces: Vec<WetFace>,
}

fn build_err(reason: impl Into<String>) -> GateError {
    GateError::InpBuild(reason.into())
}

impl<'a> ImportedLeaf<'a> {
    fn new(model: &'a ImportedModel, spec: &ImportSpec) -> Result<Self, GateError> {
        let frame = spec.validate()?;
        let set = spec.quoin_nset.to_uppercase();
        let (quoin_nodes, quoin_heights) = quoin_line(model, spec, &frame, &set)?;
        let top = *quoin_heights.last().expect("2 nodes");
        let quoin_height = spec.quoin_height.unwrap_or(top);
        let tol = 1e-9 * quoin_height;
        if quoin_heights[0] < -tol || top > quoin_height + tol {
            return Err(build_err(format!(
                "quoin nodes span heights [{}, {top}] in, outside [0, H = {quoin_height}] \
                 (check ImportSpec::sill_elevation / quoin_height)",
                quoin_heights[0]
            )));
        }
        check_quoin_unsupported(model, &quoin_nodes, &set)?;
        let gauges = spec
            .gauges
            .iter()
            .map(|g| Ok((g.name.clone(), gauge_functional(model, g)?)))
            .collect::<Result<Vec<_>, GateError>>()?;
        let faces = skin_faces(model, &spec.skin_elset, frame.downstream)?;
        Ok(Self {
            model,
            frame,
            sill: spec.sill_elevation,
            gamma: spec.unit_weight,
            quoin_height,
            quoin_nodes,
            quoin_heights,
            gauges,
            faces,
        })
    }

    fn node_height(&self, n: usize) -> f64 {
        Vector3::from(self.model.mesh().mesh.nodes[n]).dot(&Vector3::from(self.frame.vertical))
            - self.sill
    }
}

/// The nodes of the quoin node set `set` sorted by height above the sill, and their heights:
/// at least two, one per height.
fn quoin_line(
    model: &ImportedModel,
    spec: &ImportSpec,
    frame: &Frame,
    set: &str,
) -> Result<(Vec<usize>, Vec<f64>), GateError> {
    let nodes = &model.mesh().mesh.nodes;
    let height = |n: usize| {
        Vector3::from(nodes[n]).dot(&Vector3::from(frame.vertical)) - spec.sill_elevation
    };
    if !model.deck().nsets.contains_key(set) {
        return Err(build_err(format!(
            "the quoin node set {set} (ImportSpec::quoin_nset) is not defined in the deck \
             (*NSET, NSET={set})"
        )));
    }
    let mut quoin_nodes = model.node_set(set)?;
    quoin_nodes.sort_by(|&a, &b| height(a).total_cmp(&height(b)));
    quoin_nodes.dedup();
    let quoin_heights: Vec<f64> = quoin_nodes.iter().map(|&n| height(n)).collect();
    let id = |n: usize| model.mesh().node_ids[n];
    if quoin_nodes.len() < 2 {
        return Err(build_err(format!(
            "quoin node set {set} needs at least 2 nodes"
        )));
    }
    for (w, nw) in quoin_heights.windows(2).zip(quoin_nodes.windows(2)) {
        if w[1] <= w[0] {
            return Err(build_err(format!(
                "quoin nodes {} and {} of {set} are at the same height {} in: the quoin \
                 must be one line of nodes, one per height",
                id(nw[0]),
                id(nw[1]),
                w[0]
            )));
        }
    }
    Ok((quoin_nodes, quoin_heights))
}

/// Rejects quoin nodes supported in translation: the contact forces must enter as loads.
fn check_quoin_unsupported(
    model: &ImportedModel,
    quoin_nodes: &[usize],
    set: &str,
) -> Result<(), GateError> {
    let quoin: HashSet<usize> = quoin_nodes.iter().copied().collect();
    for s in model.shell_model().supports() {
        let node = match *s {
            Support::Fixed { node, dof } if dof < 3 => node,
            Support::Roller { node, .. } => node,
            Support::Fixed { .. } => continue,
        };
        if quoin.contains(&node) {
            return Err(build_err(format!(
                "quoin node {} of {set} is supported in translation: the quoin contact \
                 forces must enter as loads (remove its *BOUNDARY / *EQUATION)",
                model.mesh().node_ids[node]
            )));
        }
    }
    Ok(())
}

fn gauge_functional(model: &ImportedModel, g: &ImportGauge) -> Result<SparseLoad, GateError> {
    let allowed = match &g.elset {
        None => None,
        Some(name) => {
            let set = name.to_uppercase();
            let ids = model.deck().elsets.get(&set).ok_or_else(|| {
                build_err(format!(
                    "gauge {}: element set {set} is not defined",
                    g.name
                ))
            })?;
            Some(ids.iter().copied().collect::<HashSet<u64>>())
        }
    };
    model
        .gauge_operator_in(g.point, g.side, g.direction, allowed.as_ref())
        .ok_or_else(|| GateError::GaugeNotOnMesh {
            name: g.name.clone(),
            point: g.point,
            side: g.side,
        })
}

/// Faces of the skin element set with the unit direction of the water force.
fn skin_faces(
    model: &ImportedModel,
    elset: &str,
    downstream: [f64; 3],
) -> Result<Vec<WetFace>, GateError> {
    let set = elset.to_uppercase();
    let ids = model.deck().elsets.get(&set).ok_or_else(|| {
        build_err(format!(
            "the skin element set {set} (ImportSpec::skin_elset) is not defined in the deck"
        ))
    })?;
    let down = Vector3::from(downstream);
    ids.iter()
        .map(|&id| {
            let (nodes, normal) = model.shell_face(id).ok_or_else(|| {
                build_err(format!("skin element {id} of {set} is not a shell element"))
            })?;
            let along = normal.dot(&down);
            if along.abs() < 1e-3 {
                return Err(build_err(format!(
                    "skin element {id} of {set} is parallel to the downstream direction: \
                     the water cannot push it"
                )));
            }
            Ok((nodes, (normal * along.signum()).into()))
        })
        .collect()
}

impl CondensationSource for ImportedLeaf<'_> {
    fn shell_model(&self) -> &ShellModel {
        self.model.shell_model()
    }
    fn quoin_height(&self) -> f64 {
        self.quoin_height
    }
    fn quoin_node_heights(&self) -> Vec<f64> {
        self.quoin_heights.clone()
    }
    fn quoin_unit_loads(&self) -> Vec<SparseLoad> {
        let unit = |dir: [f64; 3]| {
            self.quoin_nodes.iter().map(move |&n| {
                (0..3)
                    .filter(|&k| dir[k] != 0.0)
                    .map(|k| (6 * n + k, dir[k]))
                    .collect::<Vec<_>>()
            })
        };
        unit(self.frame.quoin_normal)
            .chain(unit(self.frame.quoin_tangent))
            .collect()
    }
    fn gauge_functionals(&self) -> Vec<(String, SparseLoad)> {
        self.gauges.clone()
    }
    fn water_breakpoints(&self) -> Vec<f64> {
        sorted_unique(
            self.faces
                .iter()
                .flat_map(|(nodes, _)| nodes.iter().map(|&n| self.node_height(n)))
                .collect(),
        )
    }
    fn upstream_water_load(&self, h: f64, derivative: bool) -> Result<SparseLoad, GateError> {
        let coords = &self.model.mesh().mesh.nodes;
        let mut out = Vec::new();
        for (nodes, dir) in &self.faces {
            let xyz: Vec<[f64; 3]> = nodes.iter().map(|&n| coords[n]).collect();
            let z: Vec<f64> = nodes.iter().map(|&n| self.node_height(n)).collect();
            let f = face_pressure_integrals(&xyz, &z, self.gamma, h, derivative);
            for (&n, fi) in nodes.iter().zip(f) {
                for k in (0..3).filter(|&k| dir[k] != 0.0) {
                    out.push((6 * n + k, fi * dir[k]));
                }
            }
        }
        Ok(out)
    }
}

impl ImportedModel {
    /// Condenses the imported leaf to `nu` uniformly spaced quoin representation points over
    /// `[0, H]`: the same [`CondensedGate`] (quoin flexibility `C`, water tables, load
    /// transfer, strain matrix `A` by adjoint solves) as [`GateModel::condense`], from the
    /// same code. `spec` names the quoin set, the skin set, the frame and the gauges (see
    /// [`ImportSpec`]); errors name the missing set or the offending node.
    ///
    /// ```
    /// use mitergate::inp::{export_gate, ExportOptions, ImportSpec, InpModel};
    /// use mitergate::{GateConfig, GateModel};
    /// let mut cfg = GateConfig::default();
    /// cfg.mesh.element_size = 96.0;
    /// let gate = GateModel::build(&cfg).unwrap();
    /// let deck = export_gate(&gate, &ExportOptions::default()).unwrap();
    /// let model = InpModel::parse(&deck).unwrap().build(1e-3).unwrap();
    /// let cg = model.condense(&ImportSpec::for_exported_gate(&gate), 21).unwrap();
    /// assert_eq!(cg.a_matrix.shape(), (7, 42));
    /// ```
    pub fn condense(&self, spec: &ImportSpec, nu: usize) -> Result<CondensedGate, GateError> {
        condense(&ImportedLeaf::new(self, spec)?, nu)
    }

    /// Full nodal load vector (lbf; 6 per node, deck node order) of upstream water at `h_up`
    /// and downstream water at `h_down` (in above the sill, `0 <= h_down <= h_up`) on the
    /// skin set of `spec`: the load whose response the condensed water tables hold.
    ///
    /// ```
    /// use mitergate::inp::{export_gate, ExportOptions, ImportSpec, InpModel};
    /// use mitergate::{GateConfig, GateModel};
    /// let mut cfg = GateConfig::default();
    /// cfg.mesh.element_size = 96.0;
    /// let gate = GateModel::build(&cfg).unwrap();
    /// let deck = export_gate(&gate, &ExportOptions::default()).unwrap();
    /// let model = InpModel::parse(&deck).unwrap().build(1e-3).unwrap();
    /// let f = model.water_load(&ImportSpec::for_exported_gate(&gate), 744.0, 24.0).unwrap();
    /// let g = gate.water_load(744.0, 24.0).unwrap();
    /// assert!(f.iter().zip(&g).all(|(a, b)| (a - b).abs() < 1e-9 * (1.0 + b.abs())));
    /// ```
    pub fn water_load(
        &self,
        spec: &ImportSpec,
        h_up: f64,
        h_down: f64,
    ) -> Result<Vec<f64>, GateError> {
        for (parameter, value) in [("h_up", h_up), ("h_down", h_down)] {
            if !(value.is_finite() && value >= 0.0) {
                return Err(GateError::InvalidWaterLevel {
                    parameter,
                    value,
                    reason: "must be finite and >= 0 (above the sill)".into(),
                });
            }
        }
        if h_up < h_down {
            return Err(GateError::InvalidWaterLevel {
                parameter: "h_up",
                value: h_up,
                reason: format!("must be >= h_down = {h_down} in"),
            });
        }
        let leaf = ImportedLeaf::new(self, spec)?;
        let mut f = vec![0.0; self.shell_model().n_dofs()];
        for (sign, h) in [(1.0, h_up), (-1.0, h_down)] {
            for (dof, v) in leaf.upstream_water_load(h, false)? {
                f[dof] += sign * v;
            }
        }
        Ok(f)
    }
}

impl CondensedGate {
    /// Parses an `.inp` deck (text), builds it with `spec.drilling_penalty` and condenses it
    /// ([`ImportedModel::condense`]).
    ///
    /// ```
    /// use mitergate::condense::CondensedGate;
    /// use mitergate::inp::{export_gate, ExportOptions, ImportSpec};
    /// use mitergate::{GateConfig, GateModel};
    /// let mut cfg = GateConfig::default();
    /// cfg.mesh.element_size = 96.0;
    /// let gate = GateModel::build(&cfg).unwrap();
    /// let deck = export_gate(&gate, &ExportOptions::default()).unwrap();
    /// let cg = CondensedGate::from_inp_str(&deck, &ImportSpec::for_exported_gate(&gate), 11).unwrap();
    /// assert_eq!(cg.gauge_names[6], "SG7");
    /// ```
    pub fn from_inp_str(text: &str, spec: &ImportSpec, nu: usize) -> Result<Self, GateError> {
        spec.validate()?;
        InpModel::parse(text)?
            .build(spec.drilling_penalty)?
            .condense(spec, nu)
    }

    /// Reads an `.inp` deck file and condenses it ([`CondensedGate::from_inp_str`]).
    ///
    /// ```
    /// use mitergate::condense::CondensedGate;
    /// use mitergate::inp::ImportSpec;
    /// let e = CondensedGate::from_inp_file(std::path::Path::new("/no/gate.inp"), &ImportSpec::default(), 11);
    /// assert!(e.is_err());
    /// ```
    pub fn from_inp_file(path: &Path, spec: &ImportSpec, nu: usize) -> Result<Self, GateError> {
        InpModel::from_file(path)?
            .build(spec.drilling_penalty)?
            .condense(spec, nu)
    }
}
