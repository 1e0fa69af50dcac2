//! The `.inp` reader: cards (keyword and data lines), then a small state machine per keyword.

use super::cards::{Card, cards, dof, err, field, id, node_ref, number, param, required};
use super::{
    BeamSection, Boundary, Cload, Equation, InpElement, InpElementType, InpMaterial, InpModel,
    InpStep, ShellSection, Transform,
};
use crate::error::GateError;
use std::path::Path;

/// Keyword blocks whose data lines are skipped (output requests do not change the model).
const SKIPPED_KEYWORDS: [&str; 7] = [
    "NODE PRINT",
    "EL PRINT",
    "NODE FILE",
    "EL FILE",
    "OUTPUT",
    "NODE OUTPUT",
    "ELEMENT OUTPUT",
];

/// What the data lines that follow belong to.
enum Block {
    None,
    Heading,
    Node(Option<String>),
    Element {
        kind: InpElementType,
        elset: Option<String>,
        pending: Option<(usize, Vec<String>)>,
    },
    Set {
        node: bool,
        name: String,
        generate: bool,
    },
    Elastic(String),
    Density(String),
    ShellSection(usize),
    BeamSection(usize, usize),
    Boundary,
    Transform(usize),
    Equation(Option<(Equation, usize)>),
    Cload,
    Ignored,
    NoData(String),
}

impl InpModel {
    /// Parses the text of a deck (see the [module docs](super) for the supported subset).
    ///
    /// ```
    /// use mitergate::inp::InpModel;
    /// let deck = "*NODE\n1, 0, 0, 0\n2, 1, 0, 0\n*Element, type=b31, elset=Beam\n1, 1, 2\n";
    /// let m = InpModel::parse(deck).unwrap();
    /// assert_eq!(m.elsets["BEAM"], vec![1]);
    /// let bad = InpModel::parse("*NODE\n1, 0, 0\n*DYNAMIC\n").unwrap_err();
    /// assert!(bad.to_string().contains("line 3") && bad.to_string().contains("*DYNAMIC"));
    /// ```
    pub fn parse(text: &str) -> Result<Self, GateError> {
        let mut parser = Parser {
            model: InpModel::default(),
            block: Block::None,
            material: None,
            step: None,
        };
        for card in cards(text)? {
            match card {
                Card::Keyword { line, name, params } => parser.keyword(line, &name, &params)?,
                Card::Data { line, fields } => parser.data(line, fields)?,
            }
        }
        parser.finish_block()?;
        if let Some(step) = parser.step {
            return Err(err(step.line, "*STEP without *END STEP"));
        }
        Ok(parser.model)
    }

    /// Reads and parses a deck file.
    ///
    /// ```
    /// use mitergate::inp::InpModel;
    /// let e = InpModel::from_file(std::path::Path::new("/no/such.inp")).unwrap_err();
    /// assert!(e.to_string().contains("/no/such.inp"));
    /// ```
    pub fn from_file(path: &Path) -> Result<Self, GateError> {
        let text = std::fs::read_to_string(path).map_err(|source| GateError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::parse(&text)
    }
}

struct Parser {
    model: InpModel,
    block: Block,
    material: Option<String>,
    step: Option<InpStep>,
}

impl Parser {
    /// Closes the current block and opens the block of keyword `name`.
    fn keyword(
        &mut self,
        line: usize,
        name: &str,
        params: &[(String, String)],
    ) -> Result<(), GateError> {
        self.finish_block()?;
        if !matches!(name, "ELASTIC" | "DENSITY") {
            self.material = None;
        }
        self.block = match name {
            "HEADING" => Block::Heading,
            "NODE" => Block::Node(param(params, "NSET").map(str::to_uppercase)),
            "ELEMENT" => element_block(line, params)?,
            "NSET" | "ELSET" => Block::Set {
                node: name == "NSET",
                name: required(params, name, name, line)?,
                generate: param(params, "GENERATE").is_some(),
            },
            "MATERIAL" | "ELASTIC" | "DENSITY" => self.material_block(line, name, params)?,
            "SHELL SECTION" | "BEAM SECTION" | "BEAM GENERAL SECTION" => {
                self.section_block(line, name, params)?
            }
            "BOUNDARY" => Block::Boundary,
            "TRANSFORM" => self.transform_block(line, name, params)?,
            "EQUATION" => Block::Equation(None),
            "STEP" | "STATIC" | "CLOAD" | "END STEP" => self.step_block(line, name)?,
            k if SKIPPED_KEYWORDS.contains(&k) => Block::Ignored,
            other => {
                return Err(err(line, format!("unsupported keyword *{other}")));
            }
        };
        Ok(())
    }

    /// `*MATERIAL` opens a material; `*ELASTIC` and `*DENSITY` fill the open one.
    fn material_block(
        &mut self,
        line: usize,
        name: &str,
        params: &[(String, String)],
    ) -> Result<Block, GateError> {
        if name == "MATERIAL" {
            let m = required(params, "NAME", name, line)?;
            self.model
                .materials
                .insert(m.clone(), InpMaterial::default());
            self.material = Some(m);
            return Ok(Block::NoData(name.into()));
        }
        let m = self
            .material
            .clone()
            .ok_or_else(|| err(line, format!("*{name} outside a *MATERIAL")))?;
        match param(params, "TYPE").map(str::to_uppercase) {
            Some(t) if name == "ELASTIC" && t != "ISOTROPIC" => {
                return Err(err(
                    line,
                    format!("*ELASTIC, TYPE={t}: only ISOTROPIC is supported"),
                ));
            }
            _ => {}
        }
        Ok(if name == "ELASTIC" {
            Block::Elastic(m)
        } else {
            Block::Density(m)
        })
    }

    /// `*SHELL SECTION`, `*BEAM SECTION` and `*BEAM GENERAL SECTION`: the section, whose data
    /// lines follow.
    fn section_block(
        &mut self,
        line: usize,
        name: &str,
        params: &[(String, String)],
    ) -> Result<Block, GateError> {
        if name == "SHELL SECTION" {
            if param(params, "COMPOSITE").is_some() {
                return Err(err(line, "*SHELL SECTION, COMPOSITE is not supported"));
            }
            self.model.shell_sections.push(ShellSection {
                elset: required(params, "ELSET", name, line)?,
                material: required(params, "MATERIAL", name, line)?,
                thickness: f64::NAN,
                line,
            });
            return Ok(Block::ShellSection(self.model.shell_sections.len() - 1));
        }
        let general_keyword = name == "BEAM GENERAL SECTION";
        let elset = required(params, "ELSET", name, line)?;
        let (material, section) = if general_keyword {
            (
                param(params, "MATERIAL")
                    .map(str::to_uppercase)
                    .unwrap_or_default(),
                param(params, "SECTION").unwrap_or("GENERAL").to_uppercase(),
            )
        } else {
            (
                required(params, "MATERIAL", name, line)?,
                required(params, "SECTION", name, line)?,
            )
        };
        self.model.beam_sections.push(BeamSection {
            elset,
            material,
            section,
            data: Vec::new(),
            direction: None,
            moduli: None,
            general_keyword,
            line,
        });
        Ok(Block::BeamSection(self.model.beam_sections.len() - 1, 0))
    }

    /// `*TRANSFORM, NSET=..., TYPE=R`: the frame, whose data line follows.
    fn transform_block(
        &mut self,
        line: usize,
        name: &str,
        params: &[(String, String)],
    ) -> Result<Block, GateError> {
        let t = param(params, "TYPE").unwrap_or("R").to_uppercase();
        if t != "R" {
            return Err(err(
                line,
                format!("*TRANSFORM, TYPE={t}: only TYPE=R (rectangular) is supported"),
            ));
        }
        self.model.transforms.push(Transform {
            nset: required(params, "NSET", name, line)?,
            a: [f64::NAN; 3],
            b: [f64::NAN; 3],
            line,
        });
        Ok(Block::Transform(self.model.transforms.len() - 1))
    }

    /// `*STEP`, `*STATIC`, `*CLOAD` and `*END STEP`: opens, fills and closes a step.
    fn step_block(&mut self, line: usize, name: &str) -> Result<Block, GateError> {
        Ok(match name {
            "STEP" => {
                if self.step.is_some() {
                    return Err(err(line, "*STEP inside a *STEP (missing *END STEP)"));
                }
                self.step = Some(InpStep {
                    line,
                    ..InpStep::default()
                });
                Block::NoData(name.into())
            }
            "STATIC" => {
                let step = self
                    .step
                    .as_mut()
                    .ok_or_else(|| err(line, "*STATIC outside a *STEP"))?;
                step.is_static = true;
                Block::Ignored
            }
            "CLOAD" => {
                if self.step.is_none() {
                    return Err(err(line, "*CLOAD outside a *STEP"));
                }
                Block::Cload
            }
            _ => {
                let step = self
                    .step
                    .take()
                    .ok_or_else(|| err(line, "*END STEP without *STEP"))?;
                self.model.steps.push(step);
                Block::NoData(name.into())
            }
        })
    }

    /// Reads one data line into the current block.
    fn data(&mut self, line: usize, fields: Vec<String>) -> Result<(), GateError> {
        match &mut self.block {
            Block::None => return Err(err(line, "data line before the first keyword")),
            Block::NoData(k) => return Err(err(line, format!("*{k} takes no data lines"))),
            Block::Ignored => {}
            Block::Heading => self.model.heading.push(fields.join(",")),
            Block::Node(nset) => {
                let nset = nset.clone();
                self.node_line(line, &fields, nset)?;
            }
            Block::Element { pending, .. } => {
                let (first, mut acc) = pending.take().unwrap_or((line, Vec::new()));
                acc.extend(fields.into_iter().filter(|f| !f.is_empty()));
                *pending = Some((first, acc));
                self.flush_element(false)?;
            }
            Block::Set {
                node,
                name,
                generate,
            } => {
                let (node, name, generate) = (*node, name.clone(), *generate);
                self.set_line(line, node, &name, generate, &fields)?;
            }
            Block::Elastic(m) | Block::Density(m) => {
                let (m, elastic) = (m.clone(), matches!(self.block, Block::Elastic(_)));
                self.material_line(line, &fields, &m, elastic)?;
            }
            Block::ShellSection(i) => {
                let s = &mut self.model.shell_sections[*i];
                if !s.thickness.is_nan() {
                    return Err(err(line, "*SHELL SECTION takes one data line (thickness)"));
                }
                s.thickness = number(
                    field(&fields, 0, line, "shell thickness")?,
                    line,
                    "shell thickness",
                )?;
            }
            Block::BeamSection(i, count) => {
                beam_section_line(line, &fields, &mut self.model.beam_sections[*i], *count)?;
                *count += 1;
            }
            Block::Boundary => {
                let b = boundary_line(line, &fields)?;
                match self.step.as_mut() {
                    Some(step) => step.boundaries.push(b),
                    None => self.model.boundaries.push(b),
                }
            }
            Block::Transform(i) => transform_line(line, &fields, &mut self.model.transforms[*i])?,
            Block::Equation(state) => {
                equation_line(line, &fields, state, &mut self.model.equations)?
            }
            Block::Cload => {
                let c = cload_line(line, &fields)?;
                self.step
                    .as_mut()
                    .expect("checked at *CLOAD")
                    .cloads
                    .push(c);
            }
        }
        Ok(())
    }

    /// A `*NODE` line: id and coordinates (missing ones are 0), added to `nset` if given.
    fn node_line(
        &mut self,
        line: usize,
        fields: &[String],
        nset: Option<String>,
    ) -> Result<(), GateError> {
        let n = id(field(fields, 0, line, "node id")?, line, "node id")?;
        let mut x = [0.0; 3];
        for (k, v) in x.iter_mut().enumerate() {
            if let Some(f) = fields.get(k + 1).filter(|f| !f.is_empty()) {
                *v = number(f, line, "node coordinate")?;
            }
        }
        self.model.nodes.push((n, x));
        if let Some(s) = nset {
            self.model.nsets.entry(s).or_default().push(n);
        }
        Ok(())
    }

    /// An `*ELASTIC` (`E, ν`) or `*DENSITY` line of material `m`.
    fn material_line(
        &mut self,
        line: usize,
        fields: &[String],
        m: &str,
        elastic: bool,
    ) -> Result<(), GateError> {
        let mat = self.model.materials.get_mut(m).expect("material exists");
        if elastic {
            let e = number(
                field(fields, 0, line, "Young's modulus")?,
                line,
                "Young's modulus",
            )?;
            let nu = number(
                field(fields, 1, line, "Poisson's ratio")?,
                line,
                "Poisson's ratio",
            )?;
            mat.elastic = Some((e, nu));
        } else {
            let rho = number(field(fields, 0, line, "density")?, line, "density")?;
            mat.density = Some(rho);
        }
        Ok(())
    }

    /// Completes an element whose node list is complete (or, at the end of the block, fails
    /// on an incomplete one).
    fn flush_element(&mut self, end: bool) -> Result<(), GateError> {
        let Block::Element {
            kind,
            elset,
            pending,
        } = &mut self.block
        else {
            return Ok(());
        };
        let Some((line, fields)) = pending.take() else {
            return Ok(());
        };
        let need = kind.n_nodes() + 1;
        if fields.len() < need {
            if end {
                return Err(err(
                    line,
                    format!(
                        "{} element needs {} nodes, got {}",
                        kind.name(),
                        need - 1,
                        fields.len().saturating_sub(1)
                    ),
                ));
            }
            *pending = Some((line, fields));
            return Ok(());
        }
        if fields.len() > need {
            return Err(err(
                line,
                format!(
                    "{} element needs {} nodes, got {}",
                    kind.name(),
                    need - 1,
                    fields.len() - 1
                ),
            ));
        }
        let eid = id(&fields[0], line, "element id")?;
        let nodes = fields[1..]
            .iter()
            .map(|f| id(f, line, "element node"))
            .collect::<Result<Vec<_>, _>>()?;
        self.model.elements.push(InpElement {
            id: eid,
            kind: *kind,
            nodes,
            line,
        });
        if let Some(s) = elset.clone() {
            self.model.elsets.entry(s).or_default().push(eid);
        }
        Ok(())
    }

    fn finish_block(&mut self) -> Result<(), GateError> {
        self.flush_element(true)?;
        match &self.block {
            Block::Equation(Some((eq, _))) => Err(err(eq.line, "incomplete *EQUATION")),
            Block::ShellSection(i) if self.model.shell_sections[*i].thickness.is_nan() => Err(err(
                self.model.shell_sections[*i].line,
                "*SHELL SECTION without a thickness line",
            )),
            Block::Transform(i) if self.model.transforms[*i].a[0].is_nan() => Err(err(
                self.model.transforms[*i].line,
                "*TRANSFORM without its data line",
            )),
            _ => Ok(()),
        }
    }

    fn set_line(
        &mut self,
        line: usize,
        node: bool,
        name: &str,
        generate: bool,
        fields: &[String],
    ) -> Result<(), GateError> {
        let mut ids = Vec::new();
        if generate {
            let a = id(
                field(fields, 0, line, "GENERATE start")?,
                line,
                "GENERATE start",
            )?;
            let b = id(
                field(fields, 1, line, "GENERATE end")?,
                line,
                "GENERATE end",
            )?;
            let inc = match fields.get(2).filter(|f| !f.is_empty()) {
                Some(f) => id(f, line, "GENERATE increment")?,
                None => 1,
            };
            if inc == 0 || b < a {
                return Err(err(
                    line,
                    format!("GENERATE {a}, {b}, {inc}: need start <= end and increment > 0"),
                ));
            }
            ids.extend((a..=b).step_by(inc as usize));
        } else {
            for f in fields.iter().filter(|f| !f.is_empty()) {
                match f.parse::<u64>() {
                    Ok(n) => ids.push(n),
                    Err(_) => {
                        let sets = if node {
                            &self.model.nsets
                        } else {
                            &self.model.elsets
                        };
                        let other = sets.get(&f.to_uppercase()).ok_or_else(|| {
                            err(
                                line,
                                format!(
                                    "`{f}` is neither an id nor a defined {} set",
                                    if node { "node" } else { "element" }
                                ),
                            )
                        })?;
                        ids.extend(other.iter().copied());
                    }
                }
            }
        }
        let sets = if node {
            &mut self.model.nsets
        } else {
            &mut self.model.elsets
        };
        let set = sets.entry(name.to_string()).or_default();
        for i in ids {
            if !set.contains(&i) {
                set.push(i);
            }
        }
        Ok(())
    }
}

/// `*ELEMENT, TYPE=..., ELSET=...`: the element block of a supported type.
fn element_block(line: usize, params: &[(String, String)]) -> Result<Block, GateError> {
    let t = required(params, "TYPE", "ELEMENT", line)?;
    let kind = InpElementType::from_name(&t).ok_or_else(|| {
        err(
            line,
            format!("element TYPE={t} is not supported (S4, S4R, S3, B31)"),
        )
    })?;
    Ok(Block::Element {
        kind,
        elset: param(params, "ELSET").map(str::to_uppercase),
        pending: None,
    })
}

/// Data line number `count` (0-based) of a beam section: dimensions, then the first section
/// axis, then (`*BEAM GENERAL SECTION` only) the moduli `E, G`.
fn beam_section_line(
    line: usize,
    fields: &[String],
    s: &mut BeamSection,
    count: usize,
) -> Result<(), GateError> {
    let vals = fields
        .iter()
        .filter(|f| !f.is_empty())
        .map(|f| number(f, line, "beam section data"))
        .collect::<Result<Vec<_>, _>>()?;
    match count {
        0 => s.data = vals,
        1 if vals.len() == 3 => s.direction = Some([vals[0], vals[1], vals[2]]),
        1 => return Err(err(line, "beam section direction needs 3 components")),
        2 if s.general_keyword && vals.len() >= 2 => {
            s.moduli = Some([vals[0], vals[1]]);
        }
        2 if s.general_keyword => {
            return Err(err(line, "*BEAM GENERAL SECTION moduli line needs E, G"));
        }
        _ if s.general_keyword => {
            return Err(err(
                line,
                "*BEAM GENERAL SECTION takes at most 3 data lines here",
            ));
        }
        _ => return Err(err(line, "*BEAM SECTION takes at most 2 data lines")),
    }
    Ok(())
}

/// The data line of a `*TRANSFORM`: points `a` and `b`.
fn transform_line(line: usize, fields: &[String], t: &mut Transform) -> Result<(), GateError> {
    if !t.a[0].is_nan() {
        return Err(err(line, "*TRANSFORM takes one data line"));
    }
    if fields.len() < 6 {
        return Err(err(line, "*TRANSFORM needs 6 numbers (a, b)"));
    }
    for k in 0..3 {
        t.a[k] = number(&fields[k], line, "transform point a")?;
        t.b[k] = number(&fields[k + 3], line, "transform point b")?;
    }
    Ok(())
}

/// A `*CLOAD` line: node or node set, DOF, magnitude.
fn cload_line(line: usize, fields: &[String]) -> Result<Cload, GateError> {
    let target = node_ref(field(fields, 0, line, "node or node set")?);
    Ok(Cload {
        target,
        dof: dof(field(fields, 1, line, "degree of freedom")?, line)?,
        value: number(field(fields, 2, line, "load value")?, line, "load value")?,
        line,
    })
}

fn boundary_line(line: usize, fields: &[String]) -> Result<Boundary, GateError> {
    let target = node_ref(field(fields, 0, line, "node or node set")?);
    let second = field(fields, 1, line, "first degree of freedom")?;
    let (first_dof, last_dof, value) = match second.to_uppercase().as_str() {
        "ENCASTRE" => (1, 6, 0.0),
        "PINNED" => (1, 3, 0.0),
        _ => {
            let first = dof(second, line)?;
            let last = match fields.get(2).filter(|f| !f.is_empty()) {
                Some(f) => dof(f, line)?,
                None => first,
            };
            if last < first {
                return Err(err(line, format!("last DOF {last} < first DOF {first}")));
            }
            let value = match fields.get(3).filter(|f| !f.is_empty()) {
                Some(f) => number(f, line, "boundary value")?,
                None => 0.0,
            };
            (first, last, value)
        }
    };
    Ok(Boundary {
        target,
        first_dof,
        last_dof,
        value,
        line,
    })
}

fn equation_line(
    line: usize,
    fields: &[String],
    state: &mut Option<(Equation, usize)>,
    out: &mut Vec<Equation>,
) -> Result<(), GateError> {
    let Some((eq, n)) = state.as_mut() else {
        let n = id(
            field(fields, 0, line, "number of terms")?,
            line,
            "number of equation terms",
        )? as usize;
        if n < 2 {
            return Err(err(line, "an *EQUATION needs at least 2 terms"));
        }
        *state = Some((
            Equation {
                terms: Vec::new(),
                line,
            },
            n,
        ));
        return Ok(());
    };
    let fields: Vec<&String> = fields.iter().filter(|f| !f.is_empty()).collect();
    if !fields.len().is_multiple_of(3) {
        return Err(err(
            line,
            "equation terms come in triples (node, dof, coefficient)",
        ));
    }
    for t in fields.chunks(3) {
        eq.terms.push((
            node_ref(t[0]),
            dof(t[1], line)?,
            number(t[2], line, "equation coefficient")?,
        ));
    }
    if eq.terms.len() > *n {
        return Err(err(
            line,
            format!("equation has more than the announced {n} terms"),
        ));
    }
    if eq.terms.len() == *n {
        out.push(state.take().expect("some").0);
    }
    Ok(())
}
