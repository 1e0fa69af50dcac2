//! `cargo xtask calculix-check`: the gate model against CalculiX (`ccx`). Exports the gate
//! with the quoin held (`mitergate::inp::export_gate`), runs `ccx`, reads its results and
//! compares gauge strains and displacements with our shell model solved from the same deck
//! (`mitergate::inp::InpModel::build`).
//!
//! CalculiX expands every `S4` shell into a layer of 3-D `C3D8I` bricks (incompatible-mode
//! hexahedra, nodes at `±t/2`) and joins plates meeting at an angle through rigid "knots",
//! so the two models share the mesh, loads and supports but not the element formulation.
//! The gauge strain on the CalculiX side is the total strain `E` at the expanded surface
//! nodes of the gauge's elements (extrapolated from the integration points and averaged over
//! the adjacent bricks by CalculiX), interpolated bilinearly to the gauge point
//! (`ImportedModel::gauge_sites`). Displacements are read at the original shell nodes from
//! the `.dat` file. Results: `docs/verification.md`.

use anyhow::{Context, Result, anyhow, bail};
use mitergate::inp::{ExportOptions, ImportedModel, InpModel, MiterConstraint, export_gate};
use mitergate::{GateConfig, GateModel};
use nalgebra::Vector3;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

/// Options of the `calculix-check` task.
pub struct CalculixCheck {
    /// Mesh element size (in).
    pub element_size: f64,
    /// Working directory for the deck and the CalculiX results.
    pub work_dir: PathBuf,
    /// CalculiX executable.
    pub ccx: String,
    /// Write the miter roller as `*EQUATION`s instead of a `*TRANSFORM`.
    pub equation: bool,
    /// Also write the Markdown report to this file.
    pub report: Option<PathBuf>,
}

/// Exports the default gate at `element_size`, runs `ccx` and prints the comparison.
pub fn run(opts: &CalculixCheck) -> Result<()> {
    if !ccx_available(&opts.ccx) {
        bail!(
            "`{}` (CalculiX) not found; install it, e.g. `apt-get install calculix-ccx`",
            opts.ccx
        );
    }
    let mut cfg = GateConfig::default();
    cfg.mesh.element_size = opts.element_size;
    let miter = if opts.equation {
        MiterConstraint::Equation
    } else {
        MiterConstraint::Transform
    };
    let check = CrossCheckOptions {
        ccx: opts.ccx.clone(),
        miter,
        ..CrossCheckOptions::new(&opts.work_dir)
    };
    let report = cross_check(&cfg, &check)?;
    let md = report.to_markdown();
    println!("{md}");
    eprintln!("deck: {}", report.deck.display());
    if let Some(path) = &opts.report {
        bamudi::data::write_atomic(path, md.as_bytes())?;
    }
    Ok(())
}

/// Whether the CalculiX executable `ccx` runs (`ccx -v`).
fn ccx_available(ccx: &str) -> bool {
    Command::new(ccx)
        .arg("-v")
        .output()
        .map(|o| String::from_utf8_lossy(&o.stdout).contains("Version"))
        .unwrap_or(false)
}

/// Options of [`cross_check`].
#[derive(Debug, Clone, PartialEq)]
struct CrossCheckOptions {
    /// Directory for the deck and the CalculiX outputs (created if missing).
    work_dir: PathBuf,
    /// The CalculiX executable.
    ccx: String,
    /// Upstream water level (in).
    h_up: f64,
    /// Downstream water level (in).
    h_down: f64,
    /// Miter roller representation in the deck.
    miter: MiterConstraint,
}

impl CrossCheckOptions {
    /// Defaults: `ccx` from `PATH`, `h_up = 744`, `h_down = 24` in, `*TRANSFORM` miter roller.
    fn new(work_dir: impl Into<PathBuf>) -> Self {
        Self {
            work_dir: work_dir.into(),
            ccx: "ccx".into(),
            h_up: 744.0,
            h_down: 24.0,
            miter: MiterConstraint::Transform,
        }
    }
}

/// One gauge in both models.
#[derive(Debug, Clone, PartialEq)]
struct GaugeComparison {
    /// Gauge name.
    name: String,
    /// Gauge point (in).
    point: [f64; 3],
    /// Our shell model (microstrain).
    ours: f64,
    /// CalculiX (microstrain).
    calculix: f64,
}

/// Result of [`cross_check`].
#[derive(Debug, Clone, PartialEq)]
struct CrossCheckReport {
    /// Element size of the mesh (in).
    element_size: f64,
    /// Shell nodes.
    n_nodes: usize,
    /// Shell elements.
    n_elements: usize,
    /// Gauges.
    gauges: Vec<GaugeComparison>,
    /// `‖u_ccx − u_ours‖ / ‖u_ours‖` over all compared shell nodes (translations).
    displacement_rel_rms: f64,
    /// The same over the quoin region (nodes with `x ≤ L/4`, up to the first diaphragm).
    quoin_region_rel_rms: f64,
    /// The same over the framing away from the skin plate (nodes with `y ≥ bearing_offset`:
    /// girder webs and flanges at and behind the thrust line), whose motion is the global
    /// girder response rather than the plate bending of the skin panels.
    framing_rel_rms: f64,
    /// Largest nodal displacement magnitude (in), ours.
    max_displacement_ours: f64,
    /// Largest nodal displacement magnitude (in), CalculiX.
    max_displacement_calculix: f64,
    /// Nodes compared (nodes printed in a local frame by CalculiX are left out).
    n_compared: usize,
    /// Wall-clock time of the `ccx` run (s).
    ccx_seconds: f64,
    /// The deck that was run.
    deck: PathBuf,
}

impl CrossCheckReport {
    /// A Markdown summary (tables of gauges and displacement measures).
    fn to_markdown(&self) -> String {
        let mut s = format!(
            "CalculiX cross-check, {} in mesh ({} shell nodes, {} S4 elements), ccx {:.1} s\n\n\
             | gauge | point (in) | ours µε | CalculiX µε | difference |\n|---|---|---|---|---|\n",
            self.element_size, self.n_nodes, self.n_elements, self.ccx_seconds
        );
        for g in &self.gauges {
            s.push_str(&format!(
                "| {} | ({}, {}, {}) | {:.2} | {:.2} | {:+.2} % |\n",
                g.name,
                g.point[0],
                g.point[1],
                g.point[2],
                g.ours,
                g.calculix,
                100.0 * (g.calculix - g.ours) / g.ours.abs().max(1e-300)
            ));
        }
        s.push_str(&format!(
            "\nDisplacements ({} nodes): max |u| ours {:.5} in, CalculiX {:.5} in ({:+.2} %); \
             relative RMS difference {:.2} % overall, {:.2} % in the quoin region (x <= L/4), \
             {:.2} % on the framing (y >= bearing line).\n",
            self.n_compared,
            self.max_displacement_ours,
            self.max_displacement_calculix,
            100.0 * (self.max_displacement_calculix / self.max_displacement_ours - 1.0),
            100.0 * self.displacement_rel_rms,
            100.0 * self.quoin_region_rel_rms,
            100.0 * self.framing_rel_rms
        ));
        s
    }
}

/// Exports the gate of `cfg` with the quoin held (`n` and `t` fixed at every quoin node) under
/// the water levels of `opts`, runs CalculiX on it, solves the same deck with our shell model
/// and compares gauge strains and nodal displacements.
fn cross_check(cfg: &GateConfig, opts: &CrossCheckOptions) -> Result<CrossCheckReport> {
    let gate = GateModel::build(cfg)?;
    let export = ExportOptions::default()
        .with_levels(opts.h_up, opts.h_down)
        .with_hold_quoin(true)
        .with_miter(opts.miter);
    let deck_text = export_gate(&gate, &export)?;
    std::fs::create_dir_all(&opts.work_dir)
        .with_context(|| format!("creating {}", opts.work_dir.display()))?;
    let job = "gate";
    let deck = opts.work_dir.join(format!("{job}.inp"));
    std::fs::write(&deck, &deck_text).with_context(|| format!("writing {}", deck.display()))?;
    let model = InpModel::parse(&deck_text)?.build(cfg.mesh.drilling_penalty)?;
    let u = model.solve(&model.step_load(0)?)?;
    let start = Instant::now();
    run_ccx(&opts.ccx, &opts.work_dir, job)?;
    let ccx_seconds = start.elapsed().as_secs_f64();
    let read = |ext: &str| {
        let p = opts.work_dir.join(format!("{job}.{ext}"));
        std::fs::read_to_string(&p).with_context(|| format!("reading {}", p.display()))
    };
    let frd = parse_frd(&read("frd")?)?;
    let dat = parse_dat_displacements(&read("dat")?)?;
    let gauges = compare_gauges(&gate, &model, &u, &frd)?;
    let mut report = compare_displacements(
        &model,
        &u,
        &dat,
        0.25 * cfg.geometry.leaf_length,
        cfg.geometry.bearing_offset,
    )?;
    report.element_size = cfg.mesh.element_size;
    report.gauges = gauges;
    report.ccx_seconds = ccx_seconds;
    report.deck = deck;
    Ok(report)
}

/// Runs `ccx -i job` in `dir` and checks that the job finished without `*ERROR`.
fn run_ccx(ccx: &str, dir: &Path, job: &str) -> Result<()> {
    let out = Command::new(ccx)
        .arg("-i")
        .arg(job)
        .current_dir(dir)
        .env("OMP_NUM_THREADS", "1")
        .output()
        .with_context(|| format!("cannot run `{ccx}`"))?;
    let stdout = String::from_utf8_lossy(&out.stdout);
    if !out.status.success() || stdout.contains("*ERROR") || !stdout.contains("Job finished") {
        let tail: Vec<&str> = stdout.lines().rev().take(15).collect();
        bail!(
            "`{ccx} -i {job}` in {} failed ({}): ...{}",
            dir.display(),
            out.status,
            tail.into_iter().rev().collect::<Vec<_>>().join("\n")
        );
    }
    Ok(())
}

/// Nodal results of a CalculiX `.frd` file.
#[derive(Debug, Clone, Default, PartialEq)]
struct FrdResults {
    /// Node coordinates (in) by node id.
    nodes: HashMap<u64, [f64; 3]>,
    /// Result blocks by name (`DISP`, `STRESS`, `TOSTRAIN`, ...): node id → components.
    fields: HashMap<String, HashMap<u64, Vec<f64>>>,
}

/// Node id (`I10`, columns 4-13) and values (`E12.5`) of a `-1` / `-2` record.
fn frd_values(line: &str, lineno: usize) -> Result<(u64, Vec<f64>)> {
    let bad = || anyhow!(".frd line {lineno}: cannot read `{line}`");
    let id = line
        .get(3..13)
        .ok_or_else(bad)?
        .trim()
        .parse()
        .map_err(|_| bad())?;
    let mut vals = Vec::new();
    let mut pos = 13;
    while pos + 12 <= line.len() {
        vals.push(line[pos..pos + 12].trim().parse().map_err(|_| bad())?);
        pos += 12;
    }
    Ok((id, vals))
}

/// Parses the node block and the nodal result blocks of an ASCII `.frd` file (fixed columns:
/// `I10` ids and `E12.5` values).
fn parse_frd(text: &str) -> Result<FrdResults> {
    let mut res = FrdResults::default();
    let mut current: Option<String> = None;
    let mut in_nodes = false;
    let mut last_id = 0;
    for (i, line) in text.lines().enumerate() {
        if line.starts_with("    2C") {
            in_nodes = true;
        } else if let Some(rest) = line.strip_prefix(" -4") {
            let name = rest.split_whitespace().next().unwrap_or("").to_string();
            res.fields.entry(name.clone()).or_default();
            current = Some(name);
        } else if line.starts_with(" -3") {
            in_nodes = false;
            current = None;
        } else if line.starts_with(" -1") && (in_nodes || current.is_some()) {
            let (id, vals) = frd_values(line, i + 1)?;
            if in_nodes {
                if vals.len() < 3 {
                    bail!(".frd line {}: node needs 3 coordinates", i + 1);
                }
                res.nodes.insert(id, [vals[0], vals[1], vals[2]]);
            } else if let Some(name) = &current {
                res.fields.get_mut(name).expect("created").insert(id, vals);
                last_id = id;
            }
        } else if let (true, Some(name)) = (line.starts_with(" -2"), &current) {
            // continuation of the previous node's components
            let (_, vals) = frd_values(
                &format!(" -2{:>10}{}", 0, line.get(13..).unwrap_or("")),
                i + 1,
            )?;
            if let Some(v) = res.fields.get_mut(name).and_then(|f| f.get_mut(&last_id)) {
                v.extend(vals);
            }
        }
    }
    Ok(res)
}

/// Displacements of a CalculiX `.dat` file (`*NODE PRINT` of `U`): node id → (`[ux, uy, uz]`
/// in, printed in a local `*TRANSFORM` frame).
fn parse_dat_displacements(text: &str) -> Result<HashMap<u64, ([f64; 3], bool)>> {
    let mut out = HashMap::new();
    let mut active = false;
    for (i, line) in text.lines().enumerate() {
        let t = line.trim();
        if t.starts_with("displacements") {
            active = true;
            continue;
        }
        if !active || t.is_empty() {
            continue;
        }
        let tok: Vec<&str> = t.split_whitespace().collect();
        let Ok(id) = tok[0].parse::<u64>() else {
            active = false; // the next table starts
            continue;
        };
        if tok.len() < 4 {
            bail!(".dat line {}: expected node and 3 displacements", i + 1);
        }
        let mut u = [0.0; 3];
        for k in 0..3 {
            u[k] = tok[k + 1]
                .parse()
                .map_err(|_| anyhow!(".dat line {}: bad number `{}`", i + 1, tok[k + 1]))?;
        }
        out.insert(id, (u, tok.get(4) == Some(&"L")));
    }
    if out.is_empty() {
        bail!(".dat file has no displacement table");
    }
    Ok(out)
}

/// Gauge strains of both models; CalculiX's from the expanded surface nodes of the gauge
/// elements, interpolated bilinearly.
fn compare_gauges(
    gate: &GateModel,
    model: &ImportedModel,
    u: &[f64],
    frd: &FrdResults,
) -> Result<Vec<GaugeComparison>> {
    let strain = frd
        .fields
        .get("TOSTRAIN")
        .ok_or_else(|| anyhow!(".frd has no TOSTRAIN block (request E in *EL FILE)"))?;
    let frd_nodes: Vec<(u64, [f64; 3])> = frd.nodes.iter().map(|(k, v)| (*k, *v)).collect();
    let cfg = gate.config();
    let mut out = Vec::new();
    for (spec, point) in cfg.gauges.iter().zip(gate.gauge_points()) {
        let side = spec.location.instrumented_side();
        let op = model.gauge_strain_operator(point, side, spec.direction)?;
        let ours: f64 = op.iter().map(|&(d, c)| c * u[d]).sum();
        let site = GaugeSite {
            name: &spec.name,
            point,
            side,
            direction: spec.direction,
        };
        out.push(GaugeComparison {
            name: spec.name.clone(),
            point,
            ours,
            calculix: calculix_gauge_strain(model, &site, &frd_nodes, strain)?,
        });
    }
    Ok(out)
}

/// A gauge as the comparison needs it.
struct GaugeSite<'a> {
    name: &'a str,
    point: [f64; 3],
    side: [f64; 3],
    direction: [f64; 3],
}

/// CalculiX's strain (microstrain) at a gauge: the total strain tensor at the expanded
/// surface nodes of every element carrying the gauge, projected on the gauge direction,
/// interpolated bilinearly to the gauge point and averaged over the elements.
fn calculix_gauge_strain(
    model: &ImportedModel,
    gauge: &GaugeSite,
    frd_nodes: &[(u64, [f64; 3])],
    strain: &HashMap<u64, Vec<f64>>,
) -> Result<f64> {
    let sites = model.gauge_sites(gauge.point, gauge.side);
    let d = Vector3::from(gauge.direction).normalize();
    let mut ccx = 0.0;
    for &(e, xi, eta, zeta) in &sites {
        let quad = &model.shell_model().quads()[e];
        let n = Vector3::from(quad.normal());
        let el = &model.mesh().mesh.elements[e];
        let shape = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
            .map(|(a, b)| 0.25 * (1.0 + a * xi) * (1.0 + b * eta));
        for (k, &node) in el.nodes.iter().enumerate() {
            let p = Vector3::from(model.mesh().mesh.nodes[node]) + n * zeta;
            let (id, dist) = nearest(frd_nodes, p.into());
            if dist > 0.05 * zeta.abs() {
                bail!(
                    "gauge {}: no expanded CalculiX node at {:?} (nearest {dist} in away)",
                    gauge.name,
                    p
                );
            }
            let e6 = strain
                .get(&id)
                .filter(|v| v.len() >= 6)
                .ok_or_else(|| anyhow!("no strain at CalculiX node {id}"))?;
            // tensor components exx eyy ezz exy eyz ezx
            let eps = e6[0] * d.x * d.x
                + e6[1] * d.y * d.y
                + e6[2] * d.z * d.z
                + 2.0 * (e6[3] * d.x * d.y + e6[4] * d.y * d.z + e6[5] * d.z * d.x);
            ccx += shape[k] * eps * 1e6 / sites.len() as f64;
        }
    }
    Ok(ccx)
}

/// The node nearest to `p` and its distance (in).
fn nearest(nodes: &[(u64, [f64; 3])], p: [f64; 3]) -> (u64, f64) {
    nodes
        .iter()
        .map(|(id, q)| {
            let d2 = (0..3).map(|k| (q[k] - p[k]).powi(2)).sum::<f64>();
            (*id, d2)
        })
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(id, d2)| (id, d2.sqrt()))
        .unwrap_or((0, f64::INFINITY))
}

/// Relative RMS differences of the nodal translations overall, in the quoin region
/// (`x <= quoin_region_x`) and on the framing (`y >= framing_y`), and the largest
/// displacements; the other report fields are filled in by [`cross_check`].
fn compare_displacements(
    model: &ImportedModel,
    u: &[f64],
    dat: &HashMap<u64, ([f64; 3], bool)>,
    quoin_region_x: f64,
    framing_y: f64,
) -> Result<CrossCheckReport> {
    let (mut fnum, mut fden) = (0.0, 0.0);
    let mesh = &model.mesh().mesh;
    let (mut num, mut den, mut qnum, mut qden) = (0.0, 0.0, 0.0, 0.0);
    let (mut max_ours, mut max_ccx) = (0.0f64, 0.0f64);
    let mut n_compared = 0;
    for (i, &id) in model.mesh().node_ids.iter().enumerate() {
        let (uc, local) = dat
            .get(&id)
            .ok_or_else(|| anyhow!("node {id} missing from the .dat displacements"))?;
        if *local {
            continue;
        }
        let uo = [u[6 * i], u[6 * i + 1], u[6 * i + 2]];
        let diff2: f64 = (0..3).map(|k| (uc[k] - uo[k]).powi(2)).sum();
        let norm2: f64 = uo.iter().map(|v| v * v).sum();
        num += diff2;
        den += norm2;
        if mesh.nodes[i][1] >= framing_y {
            fnum += diff2;
            fden += norm2;
        }
        if mesh.nodes[i][0] <= quoin_region_x {
            qnum += diff2;
            qden += norm2;
        }
        max_ours = max_ours.max(norm2.sqrt());
        max_ccx = max_ccx.max(uc.iter().map(|v| v * v).sum::<f64>().sqrt());
        n_compared += 1;
    }
    Ok(CrossCheckReport {
        element_size: f64::NAN,
        n_nodes: mesh.nodes.len(),
        n_elements: mesh.elements.len(),
        gauges: Vec::new(),
        displacement_rel_rms: (num / den.max(f64::MIN_POSITIVE)).sqrt(),
        quoin_region_rel_rms: (qnum / qden.max(f64::MIN_POSITIVE)).sqrt(),
        framing_rel_rms: (fnum / fden.max(f64::MIN_POSITIVE)).sqrt(),
        max_displacement_ours: max_ours,
        max_displacement_calculix: max_ccx,
        n_compared,
        ccx_seconds: f64::NAN,
        deck: PathBuf::new(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_missing_executable_is_reported() {
        assert!(!ccx_available("/no/such/ccx"));
    }

    #[test]
    fn options_default_to_full_head_and_a_transform_roller() {
        let o = CrossCheckOptions::new("/tmp/ccx");
        assert_eq!((o.h_up, o.h_down), (744.0, 24.0));
        assert_eq!(
            (o.ccx.as_str(), o.miter),
            ("ccx", MiterConstraint::Transform)
        );
    }

    #[test]
    fn frd_nodes_are_read_from_fixed_columns() {
        let text = "    2C                             1                                     1\n -1         1 1.00000E+00 2.00000E+00-3.00000E+00\n -3\n";
        let r = parse_frd(text).unwrap();
        assert_eq!(r.nodes[&1], [1.0, 2.0, -3.0]);
    }

    #[test]
    fn dat_displacements_flag_local_frames() {
        let text = " displacements (vx,vy,vz) for set NALL and time  0.1E+01\n\n   3  1.0E-03 -2.0E-03  0.0E+00 L\n";
        let d = parse_dat_displacements(text).unwrap();
        assert_eq!(d[&3], ([1.0e-3, -2.0e-3, 0.0], true));
        assert!(parse_dat_displacements("nothing here\n").is_err());
    }

    #[test]
    fn the_report_tabulates_the_gauges() {
        let r = CrossCheckReport {
            element_size: 24.0,
            n_nodes: 1,
            n_elements: 1,
            gauges: vec![GaugeComparison {
                name: "SG1".into(),
                point: [0.0; 3],
                ours: -100.0,
                calculix: -98.0,
            }],
            displacement_rel_rms: 0.01,
            quoin_region_rel_rms: 0.02,
            framing_rel_rms: 0.01,
            max_displacement_ours: 1.0,
            max_displacement_calculix: 1.01,
            n_compared: 1,
            ccx_seconds: 1.0,
            deck: "g.inp".into(),
        };
        assert!(r.to_markdown().contains("| SG1 |"));
    }

    /// The cross-check itself (24 in mesh; skipped with a message when `ccx` is not on PATH).
    #[test]
    fn calculix_cross_check() {
        if !ccx_available("ccx") {
            eprintln!("calculix_cross_check skipped: `ccx` (CalculiX) is not on PATH");
            return;
        }
        let mut cfg = GateConfig::default();
        cfg.mesh.element_size = 24.0;
        let dir = std::env::temp_dir().join(format!("mitergate-ccx-test-{}", std::process::id()));
        let r = cross_check(&cfg, &CrossCheckOptions::new(&dir)).unwrap();
        eprintln!("{}", r.to_markdown());
        // SG1-SG5 read the girder thrust near the quoin (membrane strain), which shells and
        // CalculiX's expanded bricks both represent well: within 6 % on this 24 in mesh
        // (measured 0.5-3.7 %). SG6 and SG7 sit on girders loaded through skin panels whose
        // bending CalculiX's C3D8I expansion locks (docs/verification.md), so they are only
        // reported.
        for g in &r.gauges[..5] {
            assert!(
                (g.ours - g.calculix).abs() < 0.06 * g.ours.abs(),
                "{}: ours {} vs ccx {}",
                g.name,
                g.ours,
                g.calculix
            );
        }
        // the framing (girders behind the thrust line) moves with the global girder response,
        // insensitive to the skin-plate bending: 5 % (measured 2.6 %)
        assert!(r.framing_rel_rms < 0.05, "{}", r.framing_rel_rms);
        let _ = std::fs::remove_dir_all(&dir);
    }
}
