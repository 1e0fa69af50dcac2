//! Parametric description of a horizontally framed miter gate leaf ([`GateConfig`]).
//!
//! Every length is in inches, the modulus in psi, the water unit weight in lbf/in³. The
//! default (see `data/default_gate.toml`, embedded in the crate) is a leaf of the size of an
//! Ohio River lock gate such as Greenup (110 ft chamber): see `docs/mitergate.md` for where
//! each default comes from.

use crate::error::GateError;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The embedded default gate description (TOML).
pub const DEFAULT_GATE_TOML: &str = include_str!("../../data/default_gate.toml");

/// Overall leaf geometry (in, degrees).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Geometry {
    /// Quoin height `H` (in): the leaf spans `z` in `[0, H]`.
    pub quoin_height: f64,
    /// Leaf length `L` from quoin to miter end (in).
    pub leaf_length: f64,
    /// Angle of the closed leaf from the line normal to the lock axis (degrees); the miter
    /// bearing reaction acts along `m = (cos φ, sin φ, 0)` in the leaf frame.
    pub miter_angle_deg: f64,
    /// Framing depth (in): distance from the skin plate (`y = 0`) to the downstream girder
    /// flanges (`y = depth`).
    pub depth: f64,
    /// `y` (in) of the quoin and miter bearing lines (the contact lines of the end posts).
    pub bearing_offset: f64,
    /// `y` (in) of the pivot axis (pintle at the bottom, gudgeon at the top) on the quoin end
    /// plate `x = 0`; must differ from `bearing_offset` so that quoin nodes stay free.
    pub pivot_offset: f64,
    /// Angle (degrees) of the quoin normal force direction `n` from the leaf axis `+x`,
    /// towards `+y`; `t` is `n` turned by +90 degrees about `z` (downstream).
    pub quoin_normal_angle_deg: f64,
}

/// Coarsest mesh element size (in) any path accepts (a gate TOML's `mesh.element_size`, the
/// command line's `--element-size`, Python's `element_size`, a reality's
/// `mesh_element_size_in`): 240 in (20 ft) leaves the default leaf (762 in high, 696 in long)
/// three to four elements along each edge, the coarsest mesh that still bends its skin plate
/// between girders and diaphragms at all; anything coarser is not a discretisation of the gate.
pub const MAX_ELEMENT_SIZE_IN: f64 = 240.0;

/// Largest strain magnitude (microstrain) a gauge reading may have, on every path that reads
/// gauge values (the experiments of `calibrate`, the records of the close loop, from a file
/// or from Python) and every path that makes them (a reality's sensor offsets and drifts).
/// 100,000 µε is 10 % strain: general-purpose foil strain gauges are rated to 3-5 %
/// (30,000-50,000 µε) before their grid or bond fails, and even post-yield gauges, made for
/// tests to rupture, stop at 10-20 %; a gate's structural steel yields near 1,200-1,700 µε
/// (36-50 ksi at 29,000 ksi). A larger value is not a strain a gauge reported but a unit
/// mix-up (strain instead of microstrain inverted, a raw count), an overflow or a placeholder
/// such as 1e300.
pub const MAX_GAUGE_READING_MICROSTRAIN: f64 = 1e5;

/// The skin plate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SkinPlate {
    /// Thickness (in).
    pub thickness: f64,
}

/// Horizontal girders: a web in the plane `z = height` from the skin plate to `y = depth`
/// and a downstream flange in the plane `y = depth`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Girders {
    /// Girder heights `z` (in), strictly increasing. See [`equal_load_girder_heights`].
    pub heights: Vec<f64>,
    /// Web thickness (in).
    pub web_thickness: f64,
    /// Flange width (in), centred on the web.
    pub flange_width: f64,
    /// Flange thickness (in).
    pub flange_thickness: f64,
}

/// Vertical diaphragms: full-height plates in the planes `x = position`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Diaphragms {
    /// Positions `x` (in), strictly increasing, inside the leaf.
    pub positions: Vec<f64>,
    /// Thickness (in).
    pub thickness: f64,
}

/// The quoin and miter end posts: an end plate (plane `x = 0` or `x = L`, full depth and
/// height) stiffened by a bearing web (plane `y = bearing_offset`, full height) that carries
/// the bearing line load into the girders.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EndPosts {
    /// Quoin end plate thickness (in).
    pub quoin_plate_thickness: f64,
    /// Miter end plate thickness (in).
    pub miter_plate_thickness: f64,
    /// Width (in, along `x`) of each bearing web.
    pub bearing_web_width: f64,
    /// Thickness (in) of each bearing web.
    pub bearing_web_thickness: f64,
}

/// Linear elastic isotropic material.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Material {
    /// Young's modulus (psi).
    pub youngs_modulus: f64,
    /// Poisson's ratio.
    pub poisson_ratio: f64,
}

/// Water.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Water {
    /// Unit weight γ (lbf/in³); fresh water 62.4 lbf/ft³ = 0.0361 lbf/in³.
    pub unit_weight: f64,
}

/// Mesh density and element options.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MeshOptions {
    /// Target element edge length (in); every segment between structural lines is divided
    /// into `ceil(length / element_size)` equal elements.
    pub element_size: f64,
    /// Drilling penalty factor α: the drilling stiffness is `α G t` times the squared
    /// mismatch between the drilling rotation and the membrane rotation (see [`crate::fe::shell`]).
    pub drilling_penalty: f64,
}

/// Where a strain gauge sits.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged, deny_unknown_fields)]
pub enum GaugeLocation {
    /// On the top surface (`+z`) of a girder web at distance `x` (in) from the quoin and `y`
    /// (in) from the skin plate.
    GirderWeb {
        /// Girder index (0 = bottom girder).
        girder_web: usize,
        /// Distance from the quoin (in).
        x: f64,
        /// Distance from the skin plate (in), inside `(0, depth)`.
        y: f64,
    },
    /// On the downstream surface of a girder's downstream flange, at the flange centre line
    /// (height of the girder), at distance `x` (in) from the quoin.
    GirderFlange {
        /// Girder index (0 = bottom girder).
        girder: usize,
        /// Distance from the quoin (in).
        x: f64,
    },
    /// A general point on a plate surface.
    Point {
        /// The point (in), on a plate's mid-surface.
        point: [f64; 3],
        /// Unit vector pointing to the instrumented surface (the gauge is on the face of the
        /// plate towards `side`).
        side: [f64; 3],
    },
}

impl GaugeLocation {
    /// Unit vector towards the instrumented face: `+z` for a girder web gauge, `+y` for a
    /// flange gauge, the given `side` for a general point.
    ///
    /// ```
    /// use mitergate::gate::GaugeLocation;
    /// let g = GaugeLocation::GirderFlange { girder: 0, x: 96.0 };
    /// assert_eq!(g.instrumented_side(), [0.0, 1.0, 0.0]);
    /// ```
    pub fn instrumented_side(&self) -> [f64; 3] {
        match self {
            Self::GirderWeb { .. } => [0.0, 0.0, 1.0],
            Self::GirderFlange { .. } => [0.0, 1.0, 0.0],
            Self::Point { side, .. } => *side,
        }
    }
}

/// A strain gauge: a point on a plate surface and a measuring direction.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GaugeSpec {
    /// Name (used in outputs).
    pub name: String,
    /// Location.
    pub location: GaugeLocation,
    /// Measuring direction (unit vector in the plate plane); default `+x`.
    #[serde(default = "default_direction")]
    pub direction: [f64; 3],
}

fn default_direction() -> [f64; 3] {
    [1.0, 0.0, 0.0]
}

/// Complete, validated description of a miter gate leaf. Build the FE model with
/// [`crate::gate::GateModel::build`].
///
/// ```
/// use mitergate::GateConfig;
/// let cfg = GateConfig::default();
/// assert_eq!(cfg.geometry.quoin_height, 762.0);
/// cfg.validate().unwrap();
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GateConfig {
    /// Overall geometry.
    pub geometry: Geometry,
    /// Skin plate.
    pub skin_plate: SkinPlate,
    /// Horizontal girders.
    pub girders: Girders,
    /// Vertical diaphragms.
    pub diaphragms: Diaphragms,
    /// End posts.
    pub end_posts: EndPosts,
    /// Material.
    pub material: Material,
    /// Water.
    pub water: Water,
    /// Mesh options.
    pub mesh: MeshOptions,
    /// Strain gauges.
    pub gauges: Vec<GaugeSpec>,
}

impl Default for GateConfig {
    /// The embedded Ohio-River-lock-like leaf (`data/default_gate.toml`).
    fn default() -> Self {
        Self::from_toml_str(DEFAULT_GATE_TOML).expect("embedded default gate TOML is valid")
    }
}

impl GateConfig {
    /// Parses and validates a configuration from TOML text.
    ///
    /// ```
    /// use mitergate::GateConfig;
    /// let text = mitergate::gate::config::DEFAULT_GATE_TOML.replace(
    ///     "element_size = 12.0", "element_size = 24.0");
    /// let cfg = GateConfig::from_toml_str(&text).unwrap();
    /// assert_eq!(cfg.mesh.element_size, 24.0);
    /// ```
    pub fn from_toml_str(s: &str) -> Result<Self, GateError> {
        let cfg: Self = toml::from_str(s).map_err(|e| GateError::ConfigParse {
            path: None,
            message: e.to_string(),
        })?;
        cfg.validate()?;
        Ok(cfg)
    }

    /// Reads, parses and validates a configuration file.
    ///
    /// ```
    /// use mitergate::GateConfig;
    /// let err = GateConfig::from_file(std::path::Path::new("/no/such/gate.toml")).unwrap_err();
    /// assert!(err.to_string().contains("/no/such/gate.toml"));
    /// ```
    pub fn from_file(p: &Path) -> Result<Self, GateError> {
        let text = std::fs::read_to_string(p).map_err(|source| GateError::Io {
            path: p.to_path_buf(),
            source,
        })?;
        let cfg: Self = toml::from_str(&text).map_err(|e| GateError::ConfigParse {
            path: Some(p.to_path_buf()),
            message: e.to_string(),
        })?;
        cfg.validate()?;
        Ok(cfg)
    }

    /// Serialises to TOML text.
    ///
    /// ```
    /// use mitergate::GateConfig;
    /// let cfg = GateConfig::default();
    /// let back = GateConfig::from_toml_str(&cfg.to_toml_string().unwrap()).unwrap();
    /// assert_eq!(cfg, back);
    /// ```
    pub fn to_toml_string(&self) -> Result<String, GateError> {
        toml::to_string(self).map_err(|e| GateError::ConfigParse {
            path: None,
            message: e.to_string(),
        })
    }

    /// Checks every parameter; the error names the first offending one.
    ///
    /// ```
    /// use mitergate::GateConfig;
    /// let mut cfg = GateConfig::default();
    /// cfg.skin_plate.thickness = -1.0;
    /// let err = cfg.validate().unwrap_err();
    /// assert!(err.to_string().contains("skin_plate.thickness"));
    /// ```
    pub fn validate(&self) -> Result<(), GateError> {
        let g = &self.geometry;
        positive("geometry.quoin_height", g.quoin_height)?;
        positive("geometry.leaf_length", g.leaf_length)?;
        positive("geometry.depth", g.depth)?;
        in_range("geometry.miter_angle_deg", g.miter_angle_deg, 0.0, 60.0)?;
        in_range(
            "geometry.quoin_normal_angle_deg",
            g.quoin_normal_angle_deg,
            -60.0,
            60.0,
        )?;
        open_range("geometry.bearing_offset", g.bearing_offset, 0.0, g.depth)?;
        open_range("geometry.pivot_offset", g.pivot_offset, 0.0, g.depth)?;
        if (g.pivot_offset - g.bearing_offset).abs() < 1e-6 * g.depth {
            return invalid(
                "geometry.pivot_offset",
                "must differ from geometry.bearing_offset (the pintle and gudgeon would \
                 otherwise fix the end quoin nodes and make the quoin flexibility singular)",
            );
        }
        positive("skin_plate.thickness", self.skin_plate.thickness)?;
        self.validate_girders()?;
        self.validate_diaphragms()?;
        let e = &self.end_posts;
        positive("end_posts.quoin_plate_thickness", e.quoin_plate_thickness)?;
        positive("end_posts.miter_plate_thickness", e.miter_plate_thickness)?;
        positive("end_posts.bearing_web_thickness", e.bearing_web_thickness)?;
        open_range(
            "end_posts.bearing_web_width",
            e.bearing_web_width,
            0.0,
            0.5 * g.leaf_length,
        )?;
        positive("material.youngs_modulus", self.material.youngs_modulus)?;
        open_range(
            "material.poisson_ratio",
            self.material.poisson_ratio,
            -1.0,
            0.5,
        )?;
        positive("water.unit_weight", self.water.unit_weight)?;
        let m = &self.mesh;
        positive("mesh.element_size", m.element_size)?;
        let min_size = g.quoin_height.max(g.leaf_length) / 2000.0;
        if !(min_size..=MAX_ELEMENT_SIZE_IN).contains(&m.element_size) {
            return invalid(
                "mesh.element_size",
                &format!(
                    "{} in must lie in [{min_size}, {MAX_ELEMENT_SIZE_IN}] in (finer than 1/2000 \
                     of the leaf is not supported; coarser than {MAX_ELEMENT_SIZE_IN} in is no \
                     discretisation of the gate)",
                    m.element_size
                ),
            );
        }
        open_range("mesh.drilling_penalty", m.drilling_penalty, 0.0, 10.0)?;
        self.validate_gauges()
    }

    fn validate_girders(&self) -> Result<(), GateError> {
        let gd = &self.girders;
        let h = self.geometry.quoin_height;
        positive("girders.web_thickness", gd.web_thickness)?;
        positive("girders.flange_width", gd.flange_width)?;
        positive("girders.flange_thickness", gd.flange_thickness)?;
        if gd.heights.is_empty() {
            return invalid("girders.heights", "at least one girder is needed");
        }
        let half = 0.5 * gd.flange_width;
        for (i, &z) in gd.heights.iter().enumerate() {
            let name = format!("girders.heights[{i}]");
            if !(z.is_finite() && z - half >= 0.0 && z + half <= h) {
                return invalid(
                    &name,
                    &format!("{z} in: the flange [z - w/2, z + w/2] must lie within [0, {h}] in"),
                );
            }
            if i > 0 && z - gd.heights[i - 1] < gd.flange_width {
                return invalid(
                    &name,
                    &format!(
                        "{z} in is closer than one flange width to the girder below ({} in)",
                        gd.heights[i - 1]
                    ),
                );
            }
        }
        Ok(())
    }

    fn validate_diaphragms(&self) -> Result<(), GateError> {
        let d = &self.diaphragms;
        let l = self.geometry.leaf_length;
        let w = self.end_posts.bearing_web_width;
        positive("diaphragms.thickness", d.thickness)?;
        for (i, &x) in d.positions.iter().enumerate() {
            let name = format!("diaphragms.positions[{i}]");
            if !(x.is_finite() && x > w && x < l - w) {
                return invalid(
                    &name,
                    &format!(
                        "{x} in must lie strictly between the bearing webs ({w}, {})",
                        l - w
                    ),
                );
            }
            if i > 0 && x <= d.positions[i - 1] {
                return invalid(&name, "positions must be strictly increasing");
            }
        }
        Ok(())
    }

    fn validate_gauges(&self) -> Result<(), GateError> {
        let l = self.geometry.leaf_length;
        for (i, g) in self.gauges.iter().enumerate() {
            let base = format!("gauges[{i}]");
            if g.name.is_empty() {
                return invalid(&format!("{base}.name"), "must not be empty");
            }
            if let Some(j) = self.gauges[..i].iter().position(|o| o.name == g.name) {
                return invalid(
                    &format!("{base}.name"),
                    &format!(
                        "`{}` is also the name of gauges[{j}]: gauge names are CSV column names and must be unique",
                        g.name
                    ),
                );
            }
            let n = norm(g.direction);
            if !(n.is_finite() && n > 0.0) {
                return invalid(&format!("{base}.direction"), "must be a non-zero vector");
            }
            match &g.location {
                GaugeLocation::GirderWeb { girder_web, x, y } => {
                    if *girder_web >= self.girders.heights.len() {
                        return invalid(
                            &format!("{base}.location.girder_web"),
                            &format!(
                                "{girder_web} but there are {} girders",
                                self.girders.heights.len()
                            ),
                        );
                    }
                    open_range(&format!("{base}.location.x"), *x, 0.0, l)?;
                    open_range(&format!("{base}.location.y"), *y, 0.0, self.geometry.depth)?;
                }
                GaugeLocation::GirderFlange { girder, x } => {
                    if *girder >= self.girders.heights.len() {
                        return invalid(
                            &format!("{base}.location.girder"),
                            &format!(
                                "{girder} but there are {} girders",
                                self.girders.heights.len()
                            ),
                        );
                    }
                    open_range(&format!("{base}.location.x"), *x, 0.0, l)?;
                }
                GaugeLocation::Point { point, side } => {
                    if point.iter().any(|v| !v.is_finite()) {
                        return invalid(&format!("{base}.location.point"), "must be finite");
                    }
                    let s = norm(*side);
                    if !(s.is_finite() && s > 0.0) {
                        return invalid(&format!("{base}.location.side"), "must be non-zero");
                    }
                }
            }
        }
        Ok(())
    }

    /// Unit quoin normal `n` and tangential `t` directions in the leaf frame.
    ///
    /// ```
    /// let (n, t) = mitergate::GateConfig::default().quoin_directions();
    /// assert_eq!(n, [1.0, 0.0, 0.0]);
    /// assert_eq!(t, [0.0, 1.0, 0.0]);
    /// ```
    pub fn quoin_directions(&self) -> ([f64; 3], [f64; 3]) {
        let a = self.geometry.quoin_normal_angle_deg.to_radians();
        let (s, c) = if a == 0.0 { (0.0, 1.0) } else { a.sin_cos() };
        ([c, s, 0.0], [-s, c, 0.0])
    }

    /// Unit direction `m = (cos φ, sin φ, 0)` of the miter bearing constraint `u·m = 0`.
    ///
    /// ```
    /// let m = mitergate::GateConfig::default().miter_direction();
    /// assert!((m[1] / m[0] - 1.0 / 3.0).abs() < 1e-3); // 1:3 leaf
    /// ```
    pub fn miter_direction(&self) -> [f64; 3] {
        let (s, c) = self.geometry.miter_angle_deg.to_radians().sin_cos();
        [c, s, 0.0]
    }
}

/// Girder heights (in) such that the hydrostatic load between consecutive girders is equal
/// when the water stands at the top of the quoin (`h = H`), the lowest girder at `z_bottom`
/// and the highest at `z_top`, then pushed apart from the bottom up to respect
/// `min_spacing` and pulled down from the top to respect `max_spacing`.
///
/// With the load above the sill `F(z) = γ (H z - z²/2)`, the equal-load positions are
/// `z_i = H (1 - sqrt(1 - s_i))` for `s_i` evenly spaced between `F(z_bottom)/F(H)` and
/// `F(z_top)/F(H)`; spacing grows upwards, as in real horizontally framed leaves.
///
/// ```
/// use mitergate::gate::config::equal_load_girder_heights;
/// let z = equal_load_girder_heights(762.0, 12, 18.0, 744.0, 30.0, 120.0);
/// assert_eq!(z.len(), 12);
/// assert!(z.windows(2).all(|w| w[1] - w[0] >= 30.0 - 1e-9 && w[1] - w[0] <= 120.0 + 1e-9));
/// ```
pub fn equal_load_girder_heights(
    quoin_height: f64,
    n: usize,
    z_bottom: f64,
    z_top: f64,
    min_spacing: f64,
    max_spacing: f64,
) -> Vec<f64> {
    if n == 0 {
        return Vec::new();
    }
    if n == 1 {
        return vec![z_bottom];
    }
    let h = quoin_height;
    let frac = |z: f64| (h * z - 0.5 * z * z) / (0.5 * h * h);
    let (s0, s1) = (frac(z_bottom), frac(z_top));
    let mut z: Vec<f64> = (0..n)
        .map(|i| {
            let s = s0 + (s1 - s0) * i as f64 / (n - 1) as f64;
            h * (1.0 - (1.0 - s).max(0.0).sqrt())
        })
        .collect();
    for i in 1..n {
        z[i] = z[i].max(z[i - 1] + min_spacing);
    }
    for i in (0..n - 1).rev() {
        z[i] = z[i].max(z[i + 1] - max_spacing);
    }
    // round to 0.1 in so that the list reads well in TOML files
    z.iter().map(|v| (v * 10.0).round() / 10.0).collect()
}

fn norm(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

fn invalid(parameter: &str, reason: &str) -> Result<(), GateError> {
    Err(GateError::InvalidConfig {
        parameter: parameter.to_string(),
        reason: reason.to_string(),
    })
}

fn positive(name: &str, v: f64) -> Result<(), GateError> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        invalid(name, &format!("{v} must be finite and > 0"))
    }
}

fn in_range(name: &str, v: f64, lo: f64, hi: f64) -> Result<(), GateError> {
    if v.is_finite() && v >= lo && v <= hi {
        Ok(())
    } else {
        invalid(name, &format!("{v} must lie in [{lo}, {hi}]"))
    }
}

fn open_range(name: &str, v: f64, lo: f64, hi: f64) -> Result<(), GateError> {
    if v.is_finite() && v > lo && v < hi {
        Ok(())
    } else {
        invalid(
            name,
            &format!("{v} must lie strictly between {lo} and {hi}"),
        )
    }
}
