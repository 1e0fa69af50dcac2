//! From a parsed deck to a supported, factored shell model.

use super::{InpElementType, InpModel, NodeRef};
use crate::error::GateError;
use crate::fe::beam::{Beam, BeamMaterial, BeamSectionProperties};
use crate::fe::shell::ShellMaterial;
use crate::fe::tri::ShellTriangle;
use crate::fe::{GeneralElement, QuadElement, ShellMesh, ShellModel, Support, element_dofs};
use nalgebra::{DMatrix, Vector3};
use std::collections::{BTreeMap, HashMap, HashSet};

/// The shell mesh of a deck, with the deck ids of its nodes and elements.
#[derive(Debug, Clone, PartialEq)]
pub struct ImportedMesh {
    /// Nodes (deck order) and shell elements (deck order) with their section thickness.
    pub mesh: ShellMesh,
    /// Deck id of each mesh node.
    pub node_ids: Vec<u64>,
    /// Deck id of each mesh element.
    pub element_ids: Vec<u64>,
    /// The (single) isotropic material of the shell sections (`E = 1`, `ν = 0`, unused, when
    /// the deck has beams only).
    pub material: ShellMaterial,
    /// `S3` triangles: node indices and section thickness (in), deck order.
    pub triangles: Vec<([usize; 3], f64)>,
    /// Deck id of each triangle.
    pub triangle_ids: Vec<u64>,
    /// `B31` beams: node indices and the beam (section frame, properties, moduli).
    pub beams: Vec<([usize; 2], Beam)>,
    /// Deck id of each beam.
    pub beam_ids: Vec<u64>,
}

/// A deck built into a supported and factored [`ShellModel`] (supports of the model level and
/// of the first step).
#[derive(Debug)]
pub struct ImportedModel {
    deck: InpModel,
    mesh: ImportedMesh,
    index: HashMap<u64, usize>,
    /// Deck element id → index in `mesh.mesh.elements`.
    element_index: HashMap<u64, usize>,
    /// Triangle operators (same order as `mesh.triangles`).
    triangles: Vec<ShellTriangle>,
    /// Deck triangle id → index in `mesh.triangles`.
    triangle_index: HashMap<u64, usize>,
    model: ShellModel,
}

fn build_err(reason: impl Into<String>) -> GateError {
    GateError::InpBuild(reason.into())
}

impl InpModel {
    /// Map from deck node id to mesh node index (errors on duplicate ids).
    ///
    /// ```
    /// let m = mitergate::inp::InpModel::parse("*NODE\n7, 0, 0, 0\n").unwrap();
    /// assert_eq!(m.node_index().unwrap()[&7], 0);
    /// ```
    pub fn node_index(&self) -> Result<HashMap<u64, usize>, GateError> {
        let mut index = HashMap::with_capacity(self.nodes.len());
        for (i, &(id, _)) in self.nodes.iter().enumerate() {
            if index.insert(id, i).is_some() {
                return Err(build_err(format!("node id {id} is defined twice")));
            }
        }
        Ok(index)
    }

    /// The mesh: `S4`/`S4R` quadrilaterals and `S3` triangles with the thickness of their
    /// `*SHELL SECTION`, `B31` beams with their `*BEAM SECTION` / `*BEAM GENERAL SECTION`
    /// (see [`crate::fe::beam`]). Elements without a section, shell sections with different
    /// materials and unsupported beam section types are errors ([`GateError::InpBuild`]).
    ///
    /// ```
    /// use mitergate::inp::InpModel;
    /// let deck = "*NODE\n1,0,0,0\n2,1,0,0\n3,1,1,0\n4,0,1,0\n*ELEMENT,TYPE=S4R,ELSET=P\n1,1,2,3,4\n\
    ///             *ELEMENT,TYPE=B31,ELSET=B\n2,1,2\n\
    ///             *MATERIAL,NAME=STEEL\n*ELASTIC\n29e6,0.3\n*SHELL SECTION,ELSET=P,MATERIAL=STEEL\n0.5\n\
    ///             *BEAM SECTION,ELSET=B,MATERIAL=STEEL,SECTION=RECT\n0.5,2.0\n0,1,0\n";
    /// let m = InpModel::parse(deck).unwrap().to_shell_mesh().unwrap();
    /// assert_eq!(m.mesh.elements[0].thickness, 0.5);
    /// assert_eq!(m.beams[0].1.section_axes()[1], [0.0, 1.0, 0.0]);
    /// ```
    pub fn to_shell_mesh(&self) -> Result<ImportedMesh, GateError> {
        let index = self.node_index()?;
        let thickness = self.element_thickness()?;
        let beam_sections = self.beam_section_of_elements()?;
        let mut out = ImportedMesh {
            mesh: ShellMesh {
                nodes: self.nodes.iter().map(|n| n.1).collect(),
                elements: Vec::with_capacity(self.elements.len()),
            },
            node_ids: self.nodes.iter().map(|n| n.0).collect(),
            element_ids: Vec::with_capacity(self.elements.len()),
            material: self.shell_material()?,
            triangles: Vec::new(),
            triangle_ids: Vec::new(),
            beams: Vec::new(),
            beam_ids: Vec::new(),
        };
        for el in &self.elements {
            let nodes = el
                .nodes
                .iter()
                .map(|n| {
                    index.get(n).copied().ok_or_else(|| {
                        build_err(format!(
                            "element {} (line {}) uses undefined node {n}",
                            el.id, el.line
                        ))
                    })
                })
                .collect::<Result<Vec<usize>, _>>()?;
            if el.kind == InpElementType::B31 {
                let s = beam_sections.get(&el.id).ok_or_else(|| {
                    build_err(format!(
                        "B31 element {} (line {}) is in no *BEAM SECTION element set",
                        el.id, el.line
                    ))
                })?;
                let beam = self.beam(el, s, [nodes[0], nodes[1]])?;
                out.beams.push(([nodes[0], nodes[1]], beam));
                out.beam_ids.push(el.id);
                continue;
            }
            let t = *thickness.get(&el.id).ok_or_else(|| {
                build_err(format!(
                    "element {} (line {}) is in no *SHELL SECTION element set",
                    el.id, el.line
                ))
            })?;
            if el.kind == InpElementType::S3 {
                out.triangles.push(([nodes[0], nodes[1], nodes[2]], t));
                out.triangle_ids.push(el.id);
            } else {
                out.mesh.elements.push(QuadElement {
                    nodes: [nodes[0], nodes[1], nodes[2], nodes[3]],
                    thickness: t,
                });
                out.element_ids.push(el.id);
            }
        }
        Ok(out)
    }

    /// Beam section (index into `beam_sections`) of every element in a beam section's set.
    fn beam_section_of_elements(&self) -> Result<HashMap<u64, usize>, GateError> {
        let mut out = HashMap::new();
        for (i, s) in self.beam_sections.iter().enumerate() {
            let ids = self.elsets.get(&s.elset).ok_or_else(|| {
                build_err(format!(
                    "*BEAM SECTION (line {}) names undefined element set {}",
                    s.line, s.elset
                ))
            })?;
            for &e in ids {
                if out.insert(e, i).is_some() {
                    return Err(build_err(format!(
                        "element {e} is in two beam sections (second: {}, line {})",
                        s.elset, s.line
                    )));
                }
            }
        }
        Ok(out)
    }

    /// The beam of a `B31` element from its section.
    fn beam(
        &self,
        el: &super::InpElement,
        section: &usize,
        nodes: [usize; 2],
    ) -> Result<Beam, GateError> {
        let s = &self.beam_sections[*section];
        let ctx = |reason: String| {
            build_err(format!(
                "B31 element {} (line {}), beam section of {} (line {}): {reason}",
                el.id, el.line, s.elset, s.line
            ))
        };
        let props = match s.section.as_str() {
            "RECT" if s.data.len() >= 2 => BeamSectionProperties::rectangle(s.data[0], s.data[1]),
            "GENERAL" if s.data.len() >= 5 => BeamSectionProperties::general(
                s.data[0], s.data[1], s.data[2], s.data[3], s.data[4],
            ),
            "RECT" | "GENERAL" => {
                return Err(ctx(format!(
                    "SECTION={} needs {} numbers on its first data line, got {}",
                    s.section,
                    if s.section == "RECT" { 2 } else { 5 },
                    s.data.len()
                )));
            }
            other => {
                return Err(ctx(format!(
                    "SECTION={other} is not supported (RECT: a, b; GENERAL: A, I11, I12, I22, J)"
                )));
            }
        }
        .map_err(|e| ctx(e.to_string()))?;
        let material = match s.moduli {
            Some([e, g]) => BeamMaterial {
                youngs_modulus: e,
                shear_modulus: g,
            },
            None => {
                let m = self
                    .materials
                    .get(&s.material)
                    .ok_or_else(|| ctx(format!("undefined material `{}`", s.material)))?;
                let (e, nu) = m
                    .elastic
                    .ok_or_else(|| ctx(format!("material {} has no *ELASTIC", s.material)))?;
                BeamMaterial::isotropic(e, nu)
            }
        };
        let p = nodes.map(|n| self.nodes[n].1);
        Beam::new(p[0], p[1], s.direction, props, material).map_err(|e| ctx(e.to_string()))
    }

    fn element_thickness(&self) -> Result<HashMap<u64, f64>, GateError> {
        let mut t = HashMap::new();
        for s in &self.shell_sections {
            if !(s.thickness > 0.0) {
                return Err(build_err(format!(
                    "*SHELL SECTION of {} (line {}): thickness {} must be > 0",
                    s.elset, s.line, s.thickness
                )));
            }
            let ids = self.elsets.get(&s.elset).ok_or_else(|| {
                build_err(format!(
                    "*SHELL SECTION (line {}) names undefined element set {}",
                    s.line, s.elset
                ))
            })?;
            for &e in ids {
                if t.insert(e, s.thickness).is_some() {
                    return Err(build_err(format!(
                        "element {e} is in two shell sections (second: {}, line {})",
                        s.elset, s.line
                    )));
                }
            }
        }
        Ok(t)
    }

    fn shell_material(&self) -> Result<ShellMaterial, GateError> {
        let mut found: Option<(f64, f64, &str)> = None;
        for s in &self.shell_sections {
            let m = self.materials.get(&s.material).ok_or_else(|| {
                build_err(format!(
                    "*SHELL SECTION (line {}) names undefined material {}",
                    s.line, s.material
                ))
            })?;
            let (e, nu) = m
                .elastic
                .ok_or_else(|| build_err(format!("material {} has no *ELASTIC", s.material)))?;
            match found {
                None => found = Some((e, nu, &s.material)),
                Some((e0, nu0, name)) if (e0, nu0) != (e, nu) => {
                    return Err(build_err(format!(
                        "shell sections use different materials ({name}, {}); the shell model \
                         supports one material",
                        s.material
                    )));
                }
                Some(_) => {}
            }
        }
        let Some((e, nu, _)) = found else {
            if self.beam_sections.is_empty() {
                return Err(build_err("the deck has no *SHELL SECTION or *BEAM SECTION"));
            }
            // beams only: the shell material is never used
            return Ok(ShellMaterial {
                youngs_modulus: 1.0,
                poisson_ratio: 0.0,
            });
        };
        if !(e > 0.0 && nu > -1.0 && nu < 0.5) {
            return Err(build_err(format!(
                "material constants E = {e}, nu = {nu} are not admissible"
            )));
        }
        Ok(ShellMaterial {
            youngs_modulus: e,
            poisson_ratio: nu,
        })
    }

    /// Mesh-node indices of a node or node set.
    fn resolve(&self, r: &NodeRef, index: &HashMap<u64, usize>) -> Result<Vec<usize>, GateError> {
        let ids: Vec<u64> = match r {
            NodeRef::Node(n) => vec![*n],
            NodeRef::Set(s) => self
                .nsets
                .get(s)
                .ok_or_else(|| build_err(format!("undefined node set {s}")))?
                .clone(),
        };
        ids.iter()
            .map(|n| {
                index
                    .get(n)
                    .copied()
                    .ok_or_else(|| build_err(format!("undefined node {n}")))
            })
            .collect()
    }

    /// Local axes of transformed nodes (mesh index → rows `x, y, z`).
    fn node_axes(
        &self,
        index: &HashMap<u64, usize>,
    ) -> Result<HashMap<usize, [[f64; 3]; 3]>, GateError> {
        let mut axes = HashMap::new();
        for t in &self.transforms {
            let r = t.axes().ok_or_else(|| {
                build_err(format!(
                    "*TRANSFORM of {} (line {}): a and b must be non-zero and not parallel",
                    t.nset, t.line
                ))
            })?;
            for n in self.resolve(&NodeRef::Set(t.nset.clone()), index)? {
                axes.insert(n, r);
            }
        }
        Ok(axes)
    }

    /// Supports of the model level and of step `step` (if it exists), for the shell model.
    ///
    /// ```
    /// use mitergate::inp::InpModel;
    /// use mitergate::fe::Support;
    /// let deck = "*NODE,NSET=R\n1,0,0,0\n*TRANSFORM,NSET=R\n0,1,0,-1,0,0\n*BOUNDARY\nR,1\n";
    /// let m = InpModel::parse(deck).unwrap();
    /// let s = m.supports(0).unwrap();
    /// assert_eq!(s, vec![Support::Roller { node: 0, normal: [0.0, 1.0, 0.0] }]);
    /// ```
    pub fn supports(&self, step: usize) -> Result<Vec<Support>, GateError> {
        let index = self.node_index()?;
        let axes = self.node_axes(&index)?;
        // per node: which DOFs are fixed (global, or local for transformed nodes)
        let mut fixed: BTreeMap<usize, [bool; 6]> = BTreeMap::new();
        let step_bcs = self
            .steps
            .get(step)
            .map(|s| &s.boundaries[..])
            .unwrap_or(&[]);
        for b in self.boundaries.iter().chain(step_bcs) {
            if b.value != 0.0 {
                return Err(build_err(format!(
                    "*BOUNDARY line {}: prescribed value {} != 0 is not supported",
                    b.line, b.value
                )));
            }
            for n in self.resolve(&b.target, &index)? {
                let f = fixed.entry(n).or_insert([false; 6]);
                for d in b.first_dof..=b.last_dof {
                    f[d - 1] = true;
                }
            }
        }
        let mut supports = Vec::new();
        let mut rollers: HashMap<usize, usize> = HashMap::new();
        for (&node, f) in &fixed {
            let local = axes.get(&node);
            let n_trans = f[..3].iter().filter(|&&v| v).count();
            let n_rot = f[3..].iter().filter(|&&v| v).count();
            match (local, n_trans) {
                (Some(_), 0 | 3) | (None, _) => {
                    for d in (0..6).filter(|&d| f[d] && (local.is_none() || d < 3)) {
                        supports.push(Support::Fixed { node, dof: d });
                    }
                }
                (Some(r), 1) => {
                    let k = f[..3].iter().position(|&v| v).expect("one fixed");
                    supports.push(Support::Roller { node, normal: r[k] });
                    rollers.insert(node, 0);
                }
                (Some(_), _) => {
                    return Err(build_err(format!(
                        "node {} fixes two translations in a *TRANSFORM frame; only one \
                         (a roller) or all three are supported",
                        self.nodes[node].0
                    )));
                }
            }
            if local.is_some() {
                match n_rot {
                    0 => {}
                    3 => supports.extend((3..6).map(|dof| Support::Fixed { node, dof })),
                    _ => {
                        return Err(build_err(format!(
                            "node {} fixes some rotations in a *TRANSFORM frame; only all \
                             three are supported",
                            self.nodes[node].0
                        )));
                    }
                }
            }
        }
        for eq in &self.equations {
            let (node, normal) = self.equation_roller(eq, &index, &axes)?;
            if rollers.insert(node, 0).is_some() {
                return Err(build_err(format!(
                    "node {} has two roller constraints (*EQUATION line {})",
                    self.nodes[node].0, eq.line
                )));
            }
            supports.push(Support::Roller { node, normal });
        }
        Ok(supports)
    }

    /// An equation `a ux + b uy + c uz = 0` of one node as a roller with normal `(a, b, c)`.
    fn equation_roller(
        &self,
        eq: &super::Equation,
        index: &HashMap<u64, usize>,
        axes: &HashMap<usize, [[f64; 3]; 3]>,
    ) -> Result<(usize, [f64; 3]), GateError> {
        let unsupported = || {
            build_err(format!(
                "*EQUATION line {}: only `a ux + b uy + c uz = 0` of a single node (a roller) \
                 is supported",
                eq.line
            ))
        };
        let mut node = None;
        let mut coef = [0.0; 3];
        for (r, d, c) in &eq.terms {
            let nodes = self.resolve(r, index)?;
            if nodes.len() != 1 || *d > 3 || node.is_some_and(|n| n != nodes[0]) {
                return Err(unsupported());
            }
            node = Some(nodes[0]);
            coef[d - 1] += c;
        }
        let node = node.ok_or_else(unsupported)?;
        let local = Vector3::from(coef);
        let normal = match axes.get(&node) {
            Some(r) => (0..3).map(|k| Vector3::from(r[k]) * local[k]).sum(),
            None => local,
        };
        if !(normal.norm() > 0.0) {
            return Err(unsupported());
        }
        Ok((node, normal.into()))
    }

    /// Full load vector (lbf, lbf·in; 6 per node, deck node order) of the `*CLOAD`s of step
    /// `step` (0-based); loads on transformed nodes act along the local axes.
    ///
    /// ```
    /// use mitergate::inp::InpModel;
    /// let deck = "*NODE\n1,0,0,0\n*STEP\n*STATIC\n*CLOAD\n1, 2, 5.0\n*END STEP\n";
    /// let f = InpModel::parse(deck).unwrap().step_load(0).unwrap();
    /// assert_eq!(f, vec![0.0, 5.0, 0.0, 0.0, 0.0, 0.0]);
    /// ```
    pub fn step_load(&self, step: usize) -> Result<Vec<f64>, GateError> {
        let s = self.steps.get(step).ok_or_else(|| {
            build_err(format!(
                "step {step} requested but the deck has {} steps",
                self.steps.len()
            ))
        })?;
        let index = self.node_index()?;
        let axes = self.node_axes(&index)?;
        let mut f = vec![0.0; 6 * self.nodes.len()];
        for c in &s.cloads {
            for n in self.resolve(&c.target, &index)? {
                let (block, k) = ((c.dof - 1) / 3, (c.dof - 1) % 3);
                match axes.get(&n) {
                    Some(r) => {
                        for (j, v) in r[k].iter().enumerate() {
                            f[6 * n + 3 * block + j] += c.value * v;
                        }
                    }
                    None => f[6 * n + c.dof - 1] += c.value,
                }
            }
        }
        Ok(f)
    }

    /// Builds the supported, factored shell model (supports of the model level and of the
    /// first step) with drilling penalty factor `drilling_penalty` (see [`crate::fe::shell`];
    /// `1e-3` is the gate default).
    ///
    /// ```
    /// use mitergate::inp::InpModel;
    /// let deck = "*NODE\n1,0,0,0\n2,10,0,0\n3,10,1,0\n4,0,1,0\n*ELEMENT,TYPE=S4,ELSET=P\n1,1,2,3,4\n\
    ///   *MATERIAL,NAME=STEEL\n*ELASTIC\n29e6,0.3\n*SHELL SECTION,ELSET=P,MATERIAL=STEEL\n0.5\n\
    ///   *BOUNDARY\n1,ENCASTRE\n4,ENCASTRE\n*STEP\n*STATIC\n*CLOAD\n2,3,1.\n3,3,1.\n*END STEP\n";
    /// let m = InpModel::parse(deck).unwrap().build(1e-3).unwrap();
    /// let u = m.solve(&m.step_load(0).unwrap()).unwrap();
    /// assert!(u[6 + 2] > 0.0);
    /// ```
    pub fn build(&self, drilling_penalty: f64) -> Result<ImportedModel, GateError> {
        let mesh = self.to_shell_mesh()?;
        let supports = self.supports(0)?;
        let triangles = mesh
            .triangles
            .iter()
            .zip(&mesh.triangle_ids)
            .map(|(&(nodes, t), id)| {
                ShellTriangle::new(
                    &nodes.map(|n| mesh.mesh.nodes[n]),
                    t,
                    mesh.material,
                    drilling_penalty,
                )
                .map_err(|e| build_err(format!("S3 element {id}: {e}")))
            })
            .collect::<Result<Vec<_>, _>>()?;
        let mut general = Vec::with_capacity(triangles.len() + mesh.beams.len());
        for (tri, &(nodes, _)) in triangles.iter().zip(&mesh.triangles) {
            let k = tri.stiffness();
            general.push(GeneralElement::new(
                nodes.to_vec(),
                DMatrix::from_iterator(18, 18, k.iter().copied()),
            )?);
        }
        for (nodes, beam) in &mesh.beams {
            let k = beam.stiffness();
            general.push(GeneralElement::new(
                nodes.to_vec(),
                DMatrix::from_iterator(12, 12, k.iter().copied()),
            )?);
        }
        let model = ShellModel::build_with_elements(
            mesh.mesh.clone(),
            mesh.material,
            drilling_penalty,
            supports,
            general,
        )?;
        let triangle_index = mesh
            .triangle_ids
            .iter()
            .enumerate()
            .map(|(e, &id)| (id, e))
            .collect();
        let element_index = mesh
            .element_ids
            .iter()
            .enumerate()
            .map(|(e, &id)| (id, e))
            .collect();
        Ok(ImportedModel {
            deck: self.clone(),
            index: self.node_index()?,
            element_index,
            triangles,
            triangle_index,
            mesh,
            model,
        })
    }
}

impl ImportedModel {
    /// The deck the model was built from.
    ///
    /// ```
    /// # use mitergate::inp::InpModel;
    /// # let deck = "*NODE\n1,0,0,0\n2,10,0,0\n3,10,1,0\n4,0,1,0\n*ELEMENT,TYPE=S4,ELSET=P\n1,1,2,3,4\n\
    /// #  *MATERIAL,NAME=STEEL\n*ELASTIC\n29e6,0.3\n*SHELL SECTION,ELSET=P,MATERIAL=STEEL\n0.5\n\
    /// #  *BOUNDARY\n1,ENCASTRE\n4,ENCASTRE\n";
    /// let m = InpModel::parse(deck).unwrap().build(1e-3).unwrap();
    /// assert_eq!(m.deck().nodes.len(), 4);
    /// ```
    pub fn deck(&self) -> &InpModel {
        &self.deck
    }

    /// The shell mesh with deck ids.
    ///
    /// ```
    /// # use mitergate::inp::InpModel;
    /// # let deck = "*NODE\n1,0,0,0\n2,10,0,0\n3,10,1,0\n4,0,1,0\n*ELEMENT,TYPE=S4,ELSET=P\n1,1,2,3,4\n\
    /// #  *MATERIAL,NAME=STEEL\n*ELASTIC\n29e6,0.3\n*SHELL SECTION,ELSET=P,MATERIAL=STEEL\n0.5\n\
    /// #  *BOUNDARY\n1,ENCASTRE\n4,ENCASTRE\n";
    /// let m = InpModel::parse(deck).unwrap().build(1e-3).unwrap();
    /// assert_eq!(m.mesh().node_ids, vec![1, 2, 3, 4]);
    /// ```
    pub fn mesh(&self) -> &ImportedMesh {
        &self.mesh
    }

    /// The assembled, supported, factored shell model.
    ///
    /// ```
    /// # use mitergate::inp::InpModel;
    /// # let deck = "*NODE\n1,0,0,0\n2,10,0,0\n3,10,1,0\n4,0,1,0\n*ELEMENT,TYPE=S4,ELSET=P\n1,1,2,3,4\n\
    /// #  *MATERIAL,NAME=STEEL\n*ELASTIC\n29e6,0.3\n*SHELL SECTION,ELSET=P,MATERIAL=STEEL\n0.5\n\
    /// #  *BOUNDARY\n1,ENCASTRE\n4,ENCASTRE\n";
    /// let m = InpModel::parse(deck).unwrap().build(1e-3).unwrap();
    /// assert_eq!(m.shell_model().n_reduced(), 12);
    /// ```
    pub fn shell_model(&self) -> &ShellModel {
        &self.model
    }

    /// Mesh-node indices of the deck node set `name` (case-insensitive), in set order.
    ///
    /// ```
    /// # use mitergate::inp::InpModel;
    /// # let deck = "*NODE,NSET=all\n1,0,0,0\n2,10,0,0\n3,10,1,0\n4,0,1,0\n*ELEMENT,TYPE=S4,ELSET=P\n1,1,2,3,4\n\
    /// #  *MATERIAL,NAME=STEEL\n*ELASTIC\n29e6,0.3\n*SHELL SECTION,ELSET=P,MATERIAL=STEEL\n0.5\n\
    /// #  *NSET,NSET=Fix\n1,4\n*BOUNDARY\nFIX,ENCASTRE\n";
    /// let m = InpModel::parse(deck).unwrap().build(1e-3).unwrap();
    /// assert_eq!(m.node_set("fix").unwrap(), vec![0, 3]);
    /// ```
    pub fn node_set(&self, name: &str) -> Result<Vec<usize>, GateError> {
        self.deck
            .resolve(&NodeRef::Set(name.to_uppercase()), &self.index)
    }

    /// Mesh-node index of deck node `id`.
    ///
    /// ```
    /// # use mitergate::inp::InpModel;
    /// # let deck = "*NODE\n1,0,0,0\n2,10,0,0\n3,10,1,0\n4,0,1,0\n*ELEMENT,TYPE=S4,ELSET=P\n1,1,2,3,4\n\
    /// #  *MATERIAL,NAME=STEEL\n*ELASTIC\n29e6,0.3\n*SHELL SECTION,ELSET=P,MATERIAL=STEEL\n0.5\n\
    /// #  *BOUNDARY\n1,ENCASTRE\n4,ENCASTRE\n";
    /// let m = InpModel::parse(deck).unwrap().build(1e-3).unwrap();
    /// assert_eq!(m.node_index(3), Some(2));
    /// ```
    pub fn node_index(&self, id: u64) -> Option<usize> {
        self.index.get(&id).copied()
    }

    /// Full load vector of the `*CLOAD`s of step `step` (see [`InpModel::step_load`]).
    ///
    /// ```
    /// # use mitergate::inp::InpModel;
    /// # let deck = "*NODE\n1,0,0,0\n2,10,0,0\n3,10,1,0\n4,0,1,0\n*ELEMENT,TYPE=S4,ELSET=P\n1,1,2,3,4\n\
    /// #  *MATERIAL,NAME=STEEL\n*ELASTIC\n29e6,0.3\n*SHELL SECTION,ELSET=P,MATERIAL=STEEL\n0.5\n\
    /// #  *BOUNDARY\n1,ENCASTRE\n4,ENCASTRE\n";
    /// let m = InpModel::parse(deck).unwrap().build(1e-3).unwrap();
    /// assert!(m.step_load(0).is_err()); // no step in this deck
    /// ```
    pub fn step_load(&self, step: usize) -> Result<Vec<f64>, GateError> {
        self.deck.step_load(step)
    }

    /// Solves `K u = f` (full DOFs, 6 per node in deck node order).
    ///
    /// ```
    /// # use mitergate::inp::InpModel;
    /// # let deck = "*NODE\n1,0,0,0\n2,10,0,0\n3,10,1,0\n4,0,1,0\n*ELEMENT,TYPE=S4,ELSET=P\n1,1,2,3,4\n\
    /// #  *MATERIAL,NAME=STEEL\n*ELASTIC\n29e6,0.3\n*SHELL SECTION,ELSET=P,MATERIAL=STEEL\n0.5\n\
    /// #  *BOUNDARY\n1,ENCASTRE\n4,ENCASTRE\n";
    /// let m = InpModel::parse(deck).unwrap().build(1e-3).unwrap();
    /// let u = m.solve(&vec![0.0; 24]).unwrap();
    /// assert!(u.iter().all(|&v| v == 0.0));
    /// ```
    pub fn solve(&self, f: &[f64]) -> Result<Vec<f64>, GateError> {
        self.model.solve(f)
    }

    /// Quadrilaterals containing a gauge point on their mid-plane, with normal parallel to
    /// `side`: `(element index, ξ, η, ζ)` with `ζ = ±t/2` the instrumented face. A
    /// comparison with another solver (the CalculiX cross-check of `xtask`) interpolates that
    /// solver's nodal strains on the same sites.
    ///
    /// ```
    /// # use mitergate::inp::InpModel;
    /// # let deck = "*NODE\n1,0,0,0\n2,10,0,0\n3,10,1,0\n4,0,1,0\n*ELEMENT,TYPE=S4,ELSET=P\n1,1,2,3,4\n\
    /// #  *MATERIAL,NAME=STEEL\n*ELASTIC\n29e6,0.3\n*SHELL SECTION,ELSET=P,MATERIAL=STEEL\n0.5\n\
    /// #  *BOUNDARY\n1,ENCASTRE\n4,ENCASTRE\n";
    /// let m = InpModel::parse(deck).unwrap().build(1e-3).unwrap();
    /// let sites = m.gauge_sites([5.0, 0.5, 0.0], [0.0, 0.0, 1.0]);
    /// assert_eq!(sites.len(), 1);
    /// assert!((sites[0].1 - 0.0).abs() < 1e-12 && (sites[0].3 - 0.25).abs() < 1e-12);
    /// ```
    pub fn gauge_sites(&self, point: [f64; 3], side: [f64; 3]) -> Vec<(usize, f64, f64, f64)> {
        let s = Vector3::from(side).normalize();
        let mut out = Vec::new();
        for (e, quad) in self.model.quads().iter().enumerate() {
            let along = Vector3::from(quad.normal()).dot(&s);
            if along.abs() < 0.99 {
                continue;
            }
            let (xi, eta, dist) = quad.natural_coordinates(point);
            let size = quad.area().sqrt();
            if dist.abs() > 1e-6 * size || xi.abs() > 1.0 + 1e-9 || eta.abs() > 1.0 + 1e-9 {
                continue;
            }
            out.push((e, xi, eta, 0.5 * quad.thickness() * along.signum()));
        }
        out
    }

    /// Shell elements (quadrilaterals and triangles) containing a gauge point on their
    /// mid-plane, with normal parallel to `side`, as `(deck id, element dofs, strain operator)` of the instrumented face
    /// `ζ = ±t/2` along `direction`.
    fn gauge_site_operators(
        &self,
        point: [f64; 3],
        side: [f64; 3],
        direction: [f64; 3],
    ) -> Vec<(u64, Vec<usize>, Vec<f64>)> {
        let mut out = Vec::new();
        for (e, xi, eta, zeta) in self.gauge_sites(point, side) {
            let op = self.model.quads()[e].strain_operator(xi, eta, zeta, direction);
            let dofs = element_dofs(&self.mesh.mesh.elements[e]).to_vec();
            out.push((self.mesh.element_ids[e], dofs, op.iter().copied().collect()));
        }
        let s = Vector3::from(side).normalize();
        for (e, tri) in self.triangles.iter().enumerate() {
            let along = Vector3::from(tri.normal()).dot(&s);
            if along.abs() < 0.99 {
                continue;
            }
            let (l2, l3, dist) = tri.natural_coordinates(point);
            let size = tri.area().sqrt();
            let tol = 1e-9;
            if dist.abs() > 1e-6 * size || l2 < -tol || l3 < -tol || l2 + l3 > 1.0 + tol {
                continue;
            }
            let zeta = 0.5 * tri.thickness() * along.signum();
            let op = tri.strain_operator(l2, l3, zeta, direction);
            let nodes = self.mesh.triangles[e].0;
            let dofs = nodes
                .iter()
                .flat_map(|&n| (0..6).map(move |k| 6 * n + k))
                .collect();
            out.push((
                self.mesh.triangle_ids[e],
                dofs,
                op.iter().copied().collect(),
            ));
        }
        out
    }

    /// Strain gauge functional (microstrain per unit full DOF, as `(dof, coefficient)`) of a
    /// gauge at `point` (on a plate mid-surface, in) on the face towards `side`, measuring
    /// along the in-plane `direction`; a point on an element edge averages the elements that
    /// share it (as [`crate::gate::GateModel`] gauges do).
    ///
    /// ```
    /// # use mitergate::inp::InpModel;
    /// # let deck = "*NODE\n1,0,0,0\n2,10,0,0\n3,10,1,0\n4,0,1,0\n*ELEMENT,TYPE=S4,ELSET=P\n1,1,2,3,4\n\
    /// #  *MATERIAL,NAME=STEEL\n*ELASTIC\n29e6,0.3\n*SHELL SECTION,ELSET=P,MATERIAL=STEEL\n0.5\n\
    /// #  *BOUNDARY\n1,ENCASTRE\n4,ENCASTRE\n";
    /// let m = InpModel::parse(deck).unwrap().build(1e-3).unwrap();
    /// let g = m.gauge_strain_operator([5.0, 0.5, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]).unwrap();
    /// assert!(!g.is_empty());
    /// assert!(m.gauge_strain_operator([50.0, 0.5, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]).is_err());
    /// ```
    pub fn gauge_strain_operator(
        &self,
        point: [f64; 3],
        side: [f64; 3],
        direction: [f64; 3],
    ) -> Result<Vec<(usize, f64)>, GateError> {
        self.gauge_operator_in(point, side, direction, None)
            .ok_or(GateError::GaugeNotOnMesh {
                name: "imported gauge".into(),
                point,
                side,
            })
    }

    /// [`ImportedModel::gauge_strain_operator`] restricted to the elements whose deck ids are
    /// in `allowed` (all shell elements if `None`); `None` if no element carries the point.
    pub(crate) fn gauge_operator_in(
        &self,
        point: [f64; 3],
        side: [f64; 3],
        direction: [f64; 3],
        allowed: Option<&HashSet<u64>>,
    ) -> Option<Vec<(usize, f64)>> {
        let sites: Vec<_> = self
            .gauge_site_operators(point, side, direction)
            .into_iter()
            .filter(|s| allowed.is_none_or(|a| a.contains(&s.0)))
            .collect();
        if sites.is_empty() {
            return None;
        }
        let mut acc: BTreeMap<usize, f64> = BTreeMap::new();
        for (_, dofs, op) in &sites {
            for (&dof, c) in dofs.iter().zip(op) {
                *acc.entry(dof).or_insert(0.0) += c / sites.len() as f64;
            }
        }
        Some(acc.into_iter().collect())
    }

    /// Node indices and unit normal of the shell element with deck id `id`.
    pub(crate) fn shell_face(&self, id: u64) -> Option<(Vec<usize>, Vector3<f64>)> {
        if let Some(&e) = self.element_index.get(&id) {
            let normal = Vector3::from(self.model.quads()[e].normal());
            return Some((self.mesh.mesh.elements[e].nodes.to_vec(), normal));
        }
        let e = *self.triangle_index.get(&id)?;
        let normal = Vector3::from(self.triangles[e].normal());
        Some((self.mesh.triangles[e].0.to_vec(), normal))
    }
}
