//! A true discrepancy a user supplies (`cargo xtask coverage --discrepancy-file FILE`), to
//! test the calibration on a shape of their own. Two forms, told apart by the extension:
//!
//! * **a table** (`.csv`): columns `h_up,h_down,d_u,normal,tangential` (in, in, in, lbf/in,
//!   lbf/in) on a full grid: every combination of the listed `h_up`, `h_down` and `d_u`
//!   values exactly once, in any order. `δ` at other levels and quoin points is interpolated
//!   (multilinear); the grid must span the water-level range `[24, 744]` in of both levels
//!   and the quoin `[0, H]`;
//! * **coefficients** (`.toml`): `δ_c(x, d) = load(x) Σ_k c_k P_k(2 d / H − 1)` with `P_k` the
//!   Legendre polynomials (`P_0 = 1`, `P_1(t) = t`, ...), keys `normal = [c_0, c_1, ...]` and
//!   `tangential = [...]` (lbf/in per unit load; either may be left out) and `load`: `"head"`
//!   (`h_up − h_down` in inches, the default), `"head2"` (`((h_up − h_down)/100)²`) or `"one"`.
//!
//! Either way the discrepancy is zero below the true gap `θ*`, as the true force is
//! (Eq. 45). Errors name the file, the line or key, and what is allowed.

use crate::error::{GateAppError, Result};
use mitergate::ContactModel;
use mitergate::gate::WATER_LEVEL_RANGE;
use serde::Deserialize;
use std::path::Path;

/// A user's true discrepancy.
#[derive(Debug, Clone)]
pub struct DeltaFile {
    /// The file's name, for reports.
    pub name: String,
    form: Form,
}

#[derive(Debug, Clone)]
enum Form {
    Table(Table),
    Coefficients(Coefficients),
}

/// A full grid over `(h_up, h_down, d_u)`, values `[normal, tangential]` per node.
#[derive(Debug, Clone)]
struct Table {
    axes: [Vec<f64>; 3],
    values: Vec<[f64; 2]>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct Coefficients {
    #[serde(default)]
    load: Load,
    #[serde(default)]
    normal: Vec<f64>,
    #[serde(default)]
    tangential: Vec<f64>,
}

#[derive(Debug, Clone, Copy, Default, Deserialize)]
#[serde(rename_all = "snake_case")]
enum Load {
    #[default]
    Head,
    Head2,
    One,
}

/// Most grid values per axis, and most Legendre terms, accepted (a table of 1e6 rows reads in
/// a second; more is a mistake, not a shape).
const MAX_AXIS: usize = 1_000;

/// The table's columns, in order.
const COLUMNS: [&str; 5] = ["h_up", "h_down", "d_u", "normal", "tangential"];
const MAX_TERMS: usize = 64;

impl DeltaFile {
    /// Reads `path` (`.csv` table or `.toml` coefficients) for a quoin of height `height` (in).
    pub fn read(path: &Path, height: f64) -> Result<Self> {
        let name = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|source| GateAppError::Io {
            path: name.clone(),
            source,
        })?;
        let form = match path.extension().and_then(|e| e.to_str()) {
            Some("csv") => Form::Table(Table::parse(&text, &name, height)?),
            Some("toml") => Form::Coefficients(Coefficients::parse(&text, &name)?),
            _ => {
                return Err(GateAppError::Invalid(format!(
                    "{name}: a discrepancy file is a table (.csv: h_up,h_down,d_u,normal,tangential) \
                     or coefficients (.toml: load, normal, tangential)"
                )));
            }
        };
        Ok(Self { name, form })
    }

    /// `δ` at levels `x` on `contact`'s quoin points, zero below `theta_star` (blocked).
    pub fn delta(&self, contact: &ContactModel, x: [f64; 2], theta_star: f64) -> Result<Vec<f64>> {
        let gate = contact.gate();
        let (d_u, height) = (&gate.nu_points, gate.quoin_height);
        let n = d_u.len();
        let mut out = vec![0.0; 2 * n];
        for (b, &d) in d_u.iter().enumerate() {
            if d < theta_star {
                continue;
            }
            let v = match &self.form {
                Form::Table(t) => t.at([x[0], x[1], d]),
                Form::Coefficients(c) => c.at(x, d, height),
            };
            (out[b], out[n + b]) = (v[0], v[1]);
        }
        Ok(out)
    }
}

impl Table {
    fn parse(text: &str, name: &str, height: f64) -> Result<Self> {
        let bad =
            |line: usize, why: String| GateAppError::Invalid(format!("{name}: line {line}: {why}"));
        let mut lines = text
            .lines()
            .enumerate()
            .filter(|(_, l)| !l.trim().is_empty());
        let (_, header) = lines
            .next()
            .ok_or_else(|| GateAppError::Invalid(format!("{name}: empty discrepancy table")))?;
        let cols: Vec<&str> = header.split(',').map(str::trim).collect();
        const WANT: [&str; 5] = ["h_up", "h_down", "d_u", "normal", "tangential"];
        if cols != WANT {
            return Err(bad(
                1,
                format!(
                    "header must be `{}`, got `{}`",
                    WANT.join(","),
                    header.trim()
                ),
            ));
        }
        let mut rows: Vec<[f64; 5]> = Vec::new();
        for (i, line) in lines {
            let cells: Vec<&str> = line.split(',').map(str::trim).collect();
            if cells.len() != 5 {
                return Err(bad(
                    i + 1,
                    format!("expected 5 values, got {}", cells.len()),
                ));
            }
            let mut row = [0.0; 5];
            for (c, cell) in cells.iter().enumerate() {
                row[c] = cell
                    .parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| {
                        bad(
                            i + 1,
                            format!("column `{}`: `{cell}` is not a finite number", COLUMNS[c]),
                        )
                    })?;
            }
            rows.push(row);
        }
        let axes = Self::axes(&rows, name, height)?;
        let size = axes.iter().map(Vec::len).product::<usize>();
        if rows.len() != size {
            return Err(GateAppError::Invalid(format!(
                "{name}: a full grid of {} x {} x {} values has {size} rows, got {}",
                axes[0].len(),
                axes[1].len(),
                axes[2].len(),
                rows.len()
            )));
        }
        let mut values = vec![[f64::NAN; 2]; size];
        for (i, r) in rows.iter().enumerate() {
            let idx = |c: usize| axes[c].partition_point(|v| *v < r[c]);
            let k = (idx(0) * axes[1].len() + idx(1)) * axes[2].len() + idx(2);
            if !values[k][0].is_nan() {
                return Err(bad(
                    i + 2,
                    format!("the node ({}, {}, {}) is listed twice", r[0], r[1], r[2]),
                ));
            }
            values[k] = [r[3], r[4]];
        }
        Ok(Self { axes, values })
    }

    /// The sorted distinct values of each level and height column, checked to span the water
    /// levels and the quoin.
    fn axes(rows: &[[f64; 5]], name: &str, height: f64) -> Result<[Vec<f64>; 3]> {
        let axis = |c: usize| -> Vec<f64> {
            let mut v: Vec<f64> = rows.iter().map(|r| r[c]).collect();
            v.sort_by(f64::total_cmp);
            v.dedup();
            v
        };
        let axes = [axis(0), axis(1), axis(2)];
        let (lo, hi) = WATER_LEVEL_RANGE;
        for (c, (need_lo, need_hi)) in [(0, (lo, hi)), (1, (lo, hi)), (2, (0.0, height))] {
            let a = &axes[c];
            if a.len() < 2 || a.len() > MAX_AXIS || a[0] > need_lo || a[a.len() - 1] < need_hi {
                return Err(GateAppError::Invalid(format!(
                    "{name}: column `{}` must take 2 to {MAX_AXIS} values spanning [{need_lo}, {need_hi}] in, \
                     got {} values in [{}, {}]",
                    COLUMNS[c],
                    a.len(),
                    a.first().copied().unwrap_or(f64::NAN),
                    a.last().copied().unwrap_or(f64::NAN),
                )));
            }
        }
        Ok(axes)
    }

    /// Multilinear interpolation at `p` (clamped to the grid).
    fn at(&self, p: [f64; 3]) -> [f64; 2] {
        let mut cell = [(0usize, 0.0f64); 3];
        for c in 0..3 {
            let a = &self.axes[c];
            let v = p[c].clamp(a[0], a[a.len() - 1]);
            let j = (a.partition_point(|x| *x <= v).max(1) - 1).min(a.len() - 2);
            cell[c] = (j, (v - a[j]) / (a[j + 1] - a[j]));
        }
        let mut out = [0.0; 2];
        for corner in 0..8 {
            let (mut w, mut k) = (1.0, 0usize);
            for c in 0..3 {
                let up = (corner >> c) & 1;
                let (j, t) = cell[c];
                w *= if up == 1 { t } else { 1.0 - t };
                k = k * self.axes[c].len() + j + up;
            }
            if w != 0.0 {
                out[0] += w * self.values[k][0];
                out[1] += w * self.values[k][1];
            }
        }
        out
    }
}

impl Coefficients {
    fn parse(text: &str, name: &str) -> Result<Self> {
        let c: Self = toml::from_str(text)
            .map_err(|e| GateAppError::Invalid(format!("{name}: {}", e.message())))?;
        for (key, v) in [("normal", &c.normal), ("tangential", &c.tangential)] {
            if v.len() > MAX_TERMS {
                return Err(GateAppError::Invalid(format!(
                    "{name}: `{key}` has {} coefficients, at most {MAX_TERMS} allowed",
                    v.len()
                )));
            }
            if let Some(k) = v.iter().position(|x| !x.is_finite()) {
                return Err(GateAppError::Invalid(format!(
                    "{name}: `{key}[{k}]` must be a finite number"
                )));
            }
        }
        if c.normal.is_empty() && c.tangential.is_empty() {
            return Err(GateAppError::Invalid(format!(
                "{name}: give `normal` or `tangential` coefficients (or both)"
            )));
        }
        Ok(c)
    }

    fn at(&self, x: [f64; 2], d: f64, height: f64) -> [f64; 2] {
        let head = x[0] - x[1];
        let load = match self.load {
            Load::Head => head,
            Load::Head2 => (head / 100.0).powi(2),
            Load::One => 1.0,
        };
        let t = 2.0 * d / height - 1.0;
        let series = |c: &[f64]| {
            // Legendre by the three-term recurrence
            let (mut p0, mut p1, mut sum) = (1.0, t, 0.0);
            for (k, ck) in c.iter().enumerate() {
                let pk = match k {
                    0 => 1.0,
                    1 => t,
                    _ => {
                        let kf = k as f64;
                        let p2 = ((2.0 * kf - 1.0) * t * p1 - (kf - 1.0) * p0) / kf;
                        (p0, p1) = (p1, p2);
                        p2
                    }
                };
                sum += ck * pk;
            }
            sum
        };
        [load * series(&self.normal), load * series(&self.tangential)]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(name: &str, text: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("bamudi-delta-file-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p
    }

    /// A table that is linear in every axis is interpolated exactly; a node listed twice, a
    /// grid with a hole, a range that does not span the levels, and a non-number are refused
    /// with the file and line or column named.
    #[test]
    fn tables_interpolate_and_refuse_bad_grids() {
        let f = |u: f64, w: f64, d: f64| [2.0 * u - w + 0.5 * d, u + d];
        let mut text = String::from("h_up,h_down,d_u,normal,tangential\n");
        for u in [0.0, 800.0] {
            for w in [0.0, 400.0, 800.0] {
                for d in [0.0, 762.0] {
                    let v = f(u, w, d);
                    text.push_str(&format!("{u},{w},{d},{},{}\n", v[0], v[1]));
                }
            }
        }
        let p = write("ok.csv", &text);
        let t = DeltaFile::read(&p, 762.0).unwrap();
        let Form::Table(table) = &t.form else {
            panic!()
        };
        let got = table.at([500.0, 123.0, 300.0]);
        let want = f(500.0, 123.0, 300.0);
        // multilinear interpolation of a multilinear function: exact up to rounding
        assert!(
            (got[0] - want[0]).abs() < 1e-9 && (got[1] - want[1]).abs() < 1e-9,
            "{got:?}"
        );
        let twice = text.clone() + "0,0,0,1,1\n";
        let e = DeltaFile::read(&write("twice.csv", &twice), 762.0)
            .unwrap_err()
            .to_string();
        assert!(e.contains("twice.csv") && e.contains("rows"), "{e}");
        let hole: String = text.lines().take(12).collect::<Vec<_>>().join("\n");
        let e = DeltaFile::read(&write("hole.csv", &hole), 762.0)
            .unwrap_err()
            .to_string();
        assert!(e.contains("full grid"), "{e}");
        let short = text.replace("800,", "700,");
        let e = DeltaFile::read(&write("short.csv", &short), 762.0)
            .unwrap_err()
            .to_string();
        assert!(e.contains("`h_up`") && e.contains("[24, 744]"), "{e}");
        let nan = text.replacen("0,0,0,", "0,0,x,", 1);
        let e = DeltaFile::read(&write("nan.csv", &nan), 762.0)
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 2") && e.contains("`d_u`"), "{e}");
    }

    /// Coefficients: `P_2(t) = (3t² − 1)/2` at the quoin's middle (t = 0) is −1/2, times the
    /// head; unknown keys and infinite values are refused.
    #[test]
    fn coefficients_follow_the_legendre_series() {
        let p = write("c.toml", "load = \"head\"\nnormal = [1.0, 0.0, 2.0]\n");
        let c = DeltaFile::read(&p, 762.0).unwrap();
        let Form::Coefficients(co) = &c.form else {
            panic!()
        };
        let v = co.at([500.0, 100.0], 381.0, 762.0);
        assert!(
            (v[0] - 400.0 * (1.0 - 1.0)).abs() < 1e-9 && v[1] == 0.0,
            "{v:?}"
        );
        let e = DeltaFile::read(&write("k.toml", "normals = [1.0]\n"), 762.0)
            .unwrap_err()
            .to_string();
        assert!(e.contains("k.toml") && e.contains("normals"), "{e}");
        let e = DeltaFile::read(&write("x.txt", ""), 762.0)
            .unwrap_err()
            .to_string();
        assert!(e.contains(".csv") && e.contains(".toml"), "{e}");
    }
}
