//! Field-data simulator: months of lock operation recorded by the 7 strain gauges of the
//! downstream miter gate, with the environmental and instrument effects that a linear
//! hydrostatic calibration model does not contain.
//!
//! # What is simulated
//!
//! * **Pools** (inches above the gate sill): the upper pool and the lower pool each follow a mean
//!   level plus a seasonal cosine plus an AR(1) "river" fluctuation with a 48 h correlation time.
//! * **Lockages**: vessels arrive as a Poisson process (`lockages_per_day`, seeded). Each lockage
//!   moves the chamber to the other pool: *filling* (chamber rises from the lower to the upper
//!   pool) or *emptying* (the reverse), each following a smooth `½(1 − cos πs)` valve curve over
//!   `fill_minutes` / `empty_minutes`. Between lockages the chamber stays where the last vessel left it.
//! * **Gate loading**: the modelled gate is the *downstream* miter gate, so `h_up` = chamber level
//!   and `h_down` = lower pool. When the chamber is down the gate opens: `h_up = h_down`, zero head.
//! * **Temperatures** (°F): air = mean + seasonal cosine (warmest near 20 July) + daily cosine
//!   (warmest at 15:00) + AR(1) weather noise (12 h correlation); water = air passed through a
//!   first-order lag of `water_lag_hours` (large thermal inertia, so its daily cycle is tiny).
//! * **Strain** (microstrain) at each gauge = the caller's TRUE strain function
//!   `f(h_up, h_down, gap_in)` + the switched-on [`FieldEffects`] + white Gaussian noise
//!   (`noise_sd_microstrain`).
//!
//! # CSV layout ([`FieldRecord::to_csv_string`])
//!
//! `time` (ISO 8601 UTC, `YYYY-MM-DDTHH:MM:SSZ`), `h_up`, `h_down` (in), covariates
//! `upper_pool` (in), `chamber` (in), `air_temp_f`, `water_temp_f` (°F), `lockage_phase`, then
//! `g1`..`gN` (microstrain; an empty cell is a missing value).
//! `lockage_phase` codes: `0` chamber down, gate open (zero head); `1` filling; `2` chamber up,
//! gate holding the full lift; `3` emptying.
//!
//! The true gap (in) is kept in [`FieldRecord::gap_in`] for test oracles and is not written.

use crate::error::GateError;
use crate::gate::WATER_LEVEL_RANGE;
use rand::{RngExt, SeedableRng, rngs::StdRng};
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};
use std::fmt::Write as _;

/// Seconds in an hour.
const HOUR_S: f64 = 3600.0;

/// Thermal strain: `coefficient_g × (T_steel − reference_f)` with `T_steel` the source
/// temperature passed through a first-order lag of `lag_hours`.
///
/// Physical magnitude: temperature-compensated foil gauges on restrained steel typically show
/// 0.5–3 microstrain/°F of apparent strain (differential expansion between skin plate, girders
/// and the quoin/miter contacts); coefficients may differ in sign between gauges.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ThermalEffect {
    /// Microstrain per °F, one per gauge.
    pub coefficients: Vec<f64>,
    /// Time constant (hours) of the steel temperature lagging the source temperature.
    pub lag_hours: f64,
    /// Which temperature drives the steel.
    pub source: TemperatureSource,
    /// Temperature (°F) at which the gauges were zeroed.
    pub reference_f: f64,
}

/// The temperature that drives a thermal effect.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum TemperatureSource {
    /// Air temperature (gauges above water, sun-exposed steel).
    Air,
    /// Water temperature (submerged gauges).
    Water,
}

/// Gauge zero drift, linear in time: `rate_g × days since start`.
///
/// Physical magnitude: bonded foil gauges with ageing adhesive or moisture ingress drift
/// 0.05–1 microstrain/day.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DriftEffect {
    /// Microstrain per day, one per gauge.
    pub rates_per_day: Vec<f64>,
}

/// A step in one gauge's zero (e.g. a data-logger reset, a lightning transient, a re-bonded
/// gauge): `size_microstrain` added from `at_day` on. Typical size 5–50 microstrain.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OffsetJump {
    /// Zero-based gauge index.
    pub gauge: usize,
    /// Day (since the start of the record) of the step.
    pub at_day: f64,
    /// Size of the step (microstrain).
    pub size_microstrain: f64,
}

/// A bottom gap that grows linearly during the record from [`FieldConfig::gap_in`] to
/// `final_gap_in` (progressive loss of quoin contact, e.g. a failing quoin block).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GapGrowth {
    /// Gap length (in) at the end of the record.
    pub final_gap_in: f64,
}

/// Load-path hysteresis at each lockage: friction at the quoin and miter contacts makes the
/// gate lag the load while filling and hold it while emptying. At valve fraction `s ∈ [0, 1]`
/// the strain changes by `amplitude_g × 4 s (1 − s)`, negative while filling, positive while
/// emptying (zero with the chamber at rest). Typical amplitude 2–15 microstrain.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LoadPathHysteresis {
    /// Peak strain change (microstrain), one per gauge.
    pub amplitude: Vec<f64>,
}

/// The units of the covariate columns of the CSV layout (see the module docs); `lockage_phase`
/// is a code (`1`, dimensionless).
pub const COVARIATE_UNITS: [(&str, &str); 5] = [
    ("upper_pool", "in"),
    ("chamber", "in"),
    ("air_temp_f", "degF"),
    ("water_temp_f", "degF"),
    ("lockage_phase", "1"),
];

/// Lock-wall flexure under the upper pool transmitted to the gauges through the quoin:
/// `coefficient_g × (upper_pool − mean upper pool)`. It depends on a covariate that is not a
/// gate load input, so it stands in for "an effect nobody declared". Typical 0.1–1
/// microstrain per inch.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WallFlexure {
    /// Microstrain per inch of upper pool above its mean, one per gauge.
    pub coefficients: Vec<f64>,
}

/// Occasional missing gauge values (telemetry drop-outs): each gauge value is independently
/// missing with `probability`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MissingValues {
    /// Probability in `[0, 1)` that one gauge value is missing.
    pub probability: f64,
}

/// Effects a linear hydrostatic calibration model lacks; each is off (`None`) by default.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct FieldEffects {
    /// Thermal strain.
    pub thermal: Option<ThermalEffect>,
    /// Gauge zero drift.
    pub drift: Option<DriftEffect>,
    /// Gauge zero step.
    pub offset_jump: Option<OffsetJump>,
    /// Growing bottom gap.
    pub gap_growth: Option<GapGrowth>,
    /// Filling / emptying load-path hysteresis.
    pub hysteresis: Option<LoadPathHysteresis>,
    /// Lock-wall flexure driven by the upper pool.
    pub wall_flexure: Option<WallFlexure>,
    /// Missing gauge values.
    pub missing: Option<MissingValues>,
}

/// Names accepted by [`FieldEffects::with_preset`].
pub const EFFECT_PRESETS: [&str; 7] = [
    "thermal",
    "drift",
    "offset-jump",
    "gap-growth",
    "hysteresis",
    "wall-flexure",
    "none",
];

/// Gap (in) at the end of the record for the `gap-growth` preset when none is given.
pub const DEFAULT_FINAL_GAP_IN: f64 = 130.0;

impl FieldEffects {
    /// The effects named in `names` (the presets of [`with_preset`](Self::with_preset)), with
    /// `final_gap_in` for `gap-growth` ([`DEFAULT_FINAL_GAP_IN`] when `None`). A list that
    /// contradicts itself is refused, naming the effect: `none` beside another effect, an
    /// effect named twice, an empty or unknown name, or a final gap given without `gap-growth`
    /// (it would be silently unused). Errors are [`GateError::InvalidInput`] with `what`
    /// `effect` or `final_gap`.
    ///
    /// ```
    /// use mitergate::data::field::FieldEffects;
    /// let names = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
    /// assert!(FieldEffects::from_presets(&names(&["thermal", "drift"]), None).is_ok());
    /// let e = FieldEffects::from_presets(&names(&["none", "thermal"]), None).unwrap_err();
    /// assert!(e.to_string().contains("`none`"), "{e}");
    /// assert!(FieldEffects::from_presets(&names(&["drift", "drift"]), None).is_err());
    /// assert!(FieldEffects::from_presets(&names(&["thermal"]), Some(120.0)).is_err());
    /// ```
    pub fn from_presets(names: &[String], final_gap_in: Option<f64>) -> Result<Self, GateError> {
        let bad = |reason: String| GateError::InvalidInput {
            what: "effect".into(),
            reason,
        };
        let names: Vec<&str> = names.iter().map(|n| n.trim()).collect();
        if let Some(i) = names.iter().position(|n| n.is_empty()) {
            return Err(bad(format!(
                "effect {} of {:?} is empty (a stray comma?); expected one of {}",
                i + 1,
                names,
                EFFECT_PRESETS.join(", ")
            )));
        }
        if let Some(n) = names.iter().find(|n| !EFFECT_PRESETS.contains(n)) {
            return Err(bad(format!(
                "unknown effect `{n}`; expected one of {}",
                EFFECT_PRESETS.join(", ")
            )));
        }
        if names.len() > 1 && names.contains(&"none") {
            return Err(bad(format!(
                "`none` cannot be combined with other effects (got {}): name the effects to \
                 switch on, or `none` alone",
                names.join(", ")
            )));
        }
        if let Some((i, n)) = names
            .iter()
            .enumerate()
            .find(|(i, n)| names[..*i].contains(n))
        {
            return Err(bad(format!(
                "`{n}` is named twice (positions {} and {})",
                names[..i].iter().position(|m| m == n).unwrap_or(0) + 1,
                i + 1
            )));
        }
        if final_gap_in.is_some() && !names.contains(&"gap-growth") {
            return Err(GateError::InvalidInput {
                what: "final_gap".into(),
                reason: "the final gap is used only by the `gap-growth` effect; add it to the \
                         effects or leave the final gap out"
                    .into(),
            });
        }
        let final_gap = final_gap_in.unwrap_or(DEFAULT_FINAL_GAP_IN);
        names
            .iter()
            .try_fold(Self::default(), |fx, n| fx.with_preset(n, final_gap))
    }

    /// Switches on one effect with the magnitudes used in `docs/closeloop.md` for 7 gauges:
    /// `thermal` (air temperature, 6 h lag, 0.6-2 microstrain/°F of both signs, zero strain
    /// at 60 °F), `drift` (0.1-0.3 microstrain/day), `offset-jump` (+20 microstrain on gauge 3
    /// from day 15), `gap-growth` (to `final_gap_in` at the end of the record),
    /// `hysteresis` (4-8 microstrain), `wall-flexure` (0.3-0.6 microstrain per inch of upper
    /// pool), `none` (no change). Effects combine: call it once per effect.
    ///
    /// ```
    /// use mitergate::data::field::FieldEffects;
    /// let fx = FieldEffects::default().with_preset("thermal", 130.0).unwrap()
    ///     .with_preset("drift", 130.0).unwrap();
    /// assert!(fx.thermal.is_some() && fx.drift.is_some() && fx.gap_growth.is_none());
    /// assert!(FieldEffects::default().with_preset("rain", 130.0).is_err());
    /// ```
    pub fn with_preset(mut self, name: &str, final_gap_in: f64) -> Result<Self, GateError> {
        match name {
            "thermal" => {
                self.thermal = Some(ThermalEffect {
                    coefficients: vec![1.5, -1.0, 2.0, 0.8, -1.2, 1.0, 0.6],
                    lag_hours: 6.0,
                    source: TemperatureSource::Air,
                    reference_f: 60.0,
                })
            }
            "drift" => {
                self.drift = Some(DriftEffect {
                    rates_per_day: vec![0.3, -0.2, 0.25, 0.1, -0.3, 0.2, 0.15],
                })
            }
            "offset-jump" => {
                self.offset_jump = Some(OffsetJump {
                    gauge: 2,
                    at_day: 15.0,
                    size_microstrain: 20.0,
                })
            }
            "gap-growth" => self.gap_growth = Some(GapGrowth { final_gap_in }),
            "hysteresis" => {
                self.hysteresis = Some(LoadPathHysteresis {
                    amplitude: vec![8.0, -6.0, 7.0, 5.0, -6.0, 4.0, 4.0],
                })
            }
            "wall-flexure" => {
                self.wall_flexure = Some(WallFlexure {
                    coefficients: vec![0.6, -0.4, 0.5, 0.3, -0.5, 0.4, 0.3],
                })
            }
            "none" => {}
            other => {
                return Err(GateError::InvalidConfig {
                    parameter: "effect".into(),
                    reason: format!(
                        "unknown effect `{other}`; expected one of {}",
                        EFFECT_PRESETS.join(", ")
                    ),
                });
            }
        }
        Ok(self)
    }
}

/// Configuration of a simulated field record. Levels in inches above the sill, temperatures in
/// °F, strain in microstrain. Build with [`FieldConfig::default`] and chained setters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FieldConfig {
    /// Seed of every random draw.
    pub seed: u64,
    /// Start of the record, seconds since 1970-01-01T00:00:00Z.
    pub start_unix_s: i64,
    /// Record length (days).
    pub days: f64,
    /// Sampling interval (minutes).
    pub step_minutes: f64,
    /// Mean upper-pool level (in).
    pub upper_pool_in: f64,
    /// Mean lower-pool level (in).
    pub lower_pool_in: f64,
    /// Seasonal amplitude of both pools (in).
    pub pool_seasonal_amplitude_in: f64,
    /// Standard deviation of the AR(1) pool fluctuation (in).
    pub pool_noise_sd_in: f64,
    /// Mean number of lockages per day.
    pub lockages_per_day: f64,
    /// Duration of a chamber fill (minutes).
    pub fill_minutes: f64,
    /// Duration of a chamber emptying (minutes).
    pub empty_minutes: f64,
    /// Annual mean air temperature (°F).
    pub air_temp_mean_f: f64,
    /// Amplitude of the daily air-temperature cycle (°F).
    pub air_daily_amplitude_f: f64,
    /// Amplitude of the seasonal air-temperature cycle (°F).
    pub air_seasonal_amplitude_f: f64,
    /// Standard deviation of the AR(1) weather noise on air temperature (°F).
    pub weather_noise_sd_f: f64,
    /// Time constant (hours) of the water temperature following the air temperature.
    pub water_lag_hours: f64,
    /// Standard deviation of the white gauge noise (microstrain).
    pub noise_sd_microstrain: f64,
    /// Bottom gap length (in) at the start of the record.
    pub gap_in: f64,
    /// Lower / upper bound (in) of every level (the model domain; default
    /// [`WATER_LEVEL_RANGE`]).
    pub level_bounds_in: (f64, f64),
    /// Effects the calibration model lacks.
    pub effects: FieldEffects,
}

impl Default for FieldConfig {
    /// Two months (from 2024-06-01) sampled hourly, lift of 360 in, 8 lockages a day, summer
    /// temperatures, 1 microstrain noise, gap 90 in, no extra effects.
    fn default() -> Self {
        Self {
            seed: 0,
            start_unix_s: 1_717_200_000, // 2024-06-01T00:00:00Z
            days: 60.0,
            step_minutes: 60.0,
            upper_pool_in: 540.0,
            lower_pool_in: 180.0,
            pool_seasonal_amplitude_in: 12.0,
            pool_noise_sd_in: 4.0,
            lockages_per_day: 8.0,
            fill_minutes: 30.0,
            empty_minutes: 30.0,
            air_temp_mean_f: 58.0,
            air_daily_amplitude_f: 9.0,
            air_seasonal_amplitude_f: 22.0,
            weather_noise_sd_f: 4.0,
            water_lag_hours: 240.0,
            noise_sd_microstrain: 1.0,
            gap_in: 90.0,
            level_bounds_in: WATER_LEVEL_RANGE,
            effects: FieldEffects::default(),
        }
    }
}

impl FieldConfig {
    /// Sets the seed.
    ///
    /// ```
    /// let c = mitergate::data::field::FieldConfig::default().seed(7);
    /// assert_eq!(c.seed, 7);
    /// ```
    pub fn seed(mut self, seed: u64) -> Self {
        self.seed = seed;
        self
    }
    /// Sets the record length (days) and sampling interval (minutes).
    ///
    /// ```
    /// let c = mitergate::data::field::FieldConfig::default().duration(10.0, 30.0);
    /// assert_eq!((c.days, c.step_minutes), (10.0, 30.0));
    /// ```
    pub fn duration(mut self, days: f64, step_minutes: f64) -> Self {
        self.days = days;
        self.step_minutes = step_minutes;
        self
    }
    /// Sets the gauge noise standard deviation (microstrain).
    ///
    /// ```
    /// let c = mitergate::data::field::FieldConfig::default().noise_sd(2.0);
    /// assert_eq!(c.noise_sd_microstrain, 2.0);
    /// ```
    pub fn noise_sd(mut self, microstrain: f64) -> Self {
        self.noise_sd_microstrain = microstrain;
        self
    }
    /// Sets the initial bottom gap (in).
    ///
    /// ```
    /// let c = mitergate::data::field::FieldConfig::default().gap(120.0);
    /// assert_eq!(c.gap_in, 120.0);
    /// ```
    pub fn gap(mut self, gap_in: f64) -> Self {
        self.gap_in = gap_in;
        self
    }
    /// Sets the extra effects.
    ///
    /// ```
    /// use mitergate::data::field::{DriftEffect, FieldConfig, FieldEffects};
    /// let fx = FieldEffects { drift: Some(DriftEffect { rates_per_day: vec![0.2; 7] }), ..Default::default() };
    /// let c = FieldConfig::default().effects(fx);
    /// assert!(c.effects.drift.is_some());
    /// ```
    pub fn effects(mut self, effects: FieldEffects) -> Self {
        self.effects = effects;
        self
    }

    fn validate(&self) -> Result<(), GateError> {
        let bad = |name: &str, reason: String| {
            Err(GateError::InvalidConfig {
                parameter: name.to_string(),
                reason,
            })
        };
        let (lo, hi) = self.level_bounds_in;
        if !(self.days > 0.0 && self.days.is_finite()) {
            return bad("days", format!("must be positive, got {}", self.days));
        }
        if !(self.step_minutes > 0.0 && self.step_minutes.is_finite()) {
            return bad(
                "step_minutes",
                format!("must be positive, got {}", self.step_minutes),
            );
        }
        if lo.is_nan() || hi.is_nan() || lo >= hi {
            return bad("level_bounds_in", format!("need lo < hi, got ({lo}, {hi})"));
        }
        if !(self.lower_pool_in >= lo
            && self.upper_pool_in <= hi
            && self.lower_pool_in < self.upper_pool_in)
        {
            return bad(
                "upper_pool_in/lower_pool_in",
                format!(
                    "need {lo} <= lower ({}) < upper ({}) <= {hi}",
                    self.lower_pool_in, self.upper_pool_in
                ),
            );
        }
        for (name, v) in [
            ("lockages_per_day", self.lockages_per_day),
            ("fill_minutes", self.fill_minutes),
            ("empty_minutes", self.empty_minutes),
            ("water_lag_hours", self.water_lag_hours),
        ] {
            if !(v > 0.0 && v.is_finite()) {
                return bad(name, format!("must be positive, got {v}"));
            }
        }
        for (name, v) in [
            ("noise_sd_microstrain", self.noise_sd_microstrain),
            ("pool_noise_sd_in", self.pool_noise_sd_in),
            ("weather_noise_sd_f", self.weather_noise_sd_f),
            ("gap_in", self.gap_in),
        ] {
            if !(v >= 0.0 && v.is_finite()) {
                return bad(name, format!("must be finite and >= 0, got {v}"));
            }
        }
        if let Some(m) = &self.effects.missing
            && !(0.0..1.0).contains(&m.probability)
        {
            return bad(
                "effects.missing.probability",
                format!("must be in [0, 1), got {}", m.probability),
            );
        }
        if let Some(t) = &self.effects.thermal
            && (t.lag_hours.is_nan() || t.lag_hours < 0.0)
        {
            return bad(
                "effects.thermal.lag_hours",
                format!("must be >= 0, got {}", t.lag_hours),
            );
        }
        Ok(())
    }
}

/// A simulated record; every column has one entry per sample.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct FieldRecord {
    /// Sample times, seconds since 1970-01-01T00:00:00Z.
    pub time_unix_s: Vec<i64>,
    /// Water level on the loaded (chamber) side of the gate (in).
    pub h_up: Vec<f64>,
    /// Water level on the downstream side = lower pool (in).
    pub h_down: Vec<f64>,
    /// Upper pool level (in).
    pub upper_pool: Vec<f64>,
    /// Chamber level (in).
    pub chamber: Vec<f64>,
    /// Air temperature (°F).
    pub air_temp_f: Vec<f64>,
    /// Water temperature (°F).
    pub water_temp_f: Vec<f64>,
    /// Lockage phase code (see the module docs).
    pub lockage_phase: Vec<u8>,
    /// TRUE bottom gap (in), for test oracles; not written to the CSV.
    pub gap_in: Vec<f64>,
    /// Gauge names `g1`..`gN`.
    pub gauge_names: Vec<String>,
    /// Gauge strains (microstrain), `strains[row][gauge]`, `None` when missing.
    pub strains: Vec<Vec<Option<f64>>>,
}

impl FieldRecord {
    /// Number of samples.
    ///
    /// ```
    /// use mitergate::data::field::{simulate, FieldConfig};
    /// let r = simulate(&FieldConfig::default().duration(1.0, 60.0), &|_, _, _| vec![0.0; 7]).unwrap();
    /// assert_eq!(r.len(), 24);
    /// ```
    pub fn len(&self) -> usize {
        self.time_unix_s.len()
    }

    /// `true` when the record has no samples.
    ///
    /// ```
    /// use mitergate::data::field::{simulate, FieldConfig};
    /// let r = simulate(&FieldConfig::default().duration(1.0, 60.0), &|_, _, _| vec![0.0; 7]).unwrap();
    /// assert!(!r.is_empty());
    /// ```
    pub fn is_empty(&self) -> bool {
        self.time_unix_s.is_empty()
    }

    /// The record as CSV text (layout in the module docs).
    ///
    /// ```
    /// use mitergate::data::field::{simulate, FieldConfig};
    /// let r = simulate(&FieldConfig::default().duration(1.0, 60.0), &|_, _, _| vec![1.0; 7]).unwrap();
    /// let csv = r.to_csv_string();
    /// assert!(csv.starts_with("time,h_up,h_down,upper_pool,chamber,air_temp_f,water_temp_f,lockage_phase,g1,"));
    /// assert_eq!(csv.lines().count(), 25);
    /// ```
    pub fn to_csv_string(&self) -> String {
        let mut s = String::from(
            "time,h_up,h_down,upper_pool,chamber,air_temp_f,water_temp_f,lockage_phase",
        );
        for g in &self.gauge_names {
            s.push(',');
            s.push_str(g);
        }
        s.push('\n');
        for i in 0..self.len() {
            let _ = write!(
                s,
                "{},{:.4},{:.4},{:.4},{:.4},{:.3},{:.3},{}",
                iso8601_from_unix(self.time_unix_s[i]),
                self.h_up[i],
                self.h_down[i],
                self.upper_pool[i],
                self.chamber[i],
                self.air_temp_f[i],
                self.water_temp_f[i],
                self.lockage_phase[i]
            );
            for v in &self.strains[i] {
                match v {
                    Some(v) => {
                        let _ = write!(s, ",{v:.4}");
                    }
                    None => s.push(','),
                }
            }
            s.push('\n');
        }
        s
    }

    /// Writes [`Self::to_csv_string`] to `path`.
    ///
    /// ```
    /// use mitergate::data::field::{simulate, FieldConfig};
    /// let r = simulate(&FieldConfig::default().duration(1.0, 60.0), &|_, _, _| vec![0.0; 7]).unwrap();
    /// let p = std::env::temp_dir().join("mitergate_field_doc.csv");
    /// r.write_csv(&p).unwrap();
    /// assert!(std::fs::read_to_string(&p).unwrap().starts_with("time,"));
    /// ```
    pub fn write_csv(&self, path: &std::path::Path) -> Result<(), GateError> {
        std::fs::write(path, self.to_csv_string()).map_err(|source| GateError::Io {
            path: path.to_path_buf(),
            source,
        })
    }
}

/// One lockage: start time (hours since the record start) and direction.
#[derive(Debug, Clone, Copy)]
struct Lockage {
    start_h: f64,
    filling: bool,
}

/// Poisson lockage schedule; consecutive lockages alternate between filling and emptying and
/// never overlap (a 10 minute minimum dwell after each).
fn lockage_schedule(cfg: &FieldConfig, rng: &mut StdRng) -> Vec<Lockage> {
    let total_h = cfg.days * 24.0;
    let mean_gap_h = 24.0 / cfg.lockages_per_day;
    let mut out = Vec::new();
    let mut t = 0.0;
    let mut filling = true; // the record starts with the chamber down
    loop {
        let u: f64 = rng.random::<f64>();
        t += -mean_gap_h * (1.0 - u).ln();
        if t >= total_h {
            return out;
        }
        out.push(Lockage {
            start_h: t,
            filling,
        });
        let dur = if filling {
            cfg.fill_minutes
        } else {
            cfg.empty_minutes
        } / 60.0;
        t += dur + 10.0 / 60.0;
        filling = !filling;
    }
}

/// Chamber state at `t_h`: valve fraction toward the upper pool (`0` down, `1` up) and phase code.
fn chamber_state(cfg: &FieldConfig, schedule: &[Lockage], t_h: f64) -> (f64, u8) {
    let k = schedule.partition_point(|l| l.start_h <= t_h);
    if k == 0 {
        return (0.0, 0);
    }
    let l = schedule[k - 1];
    let dur_h = if l.filling {
        cfg.fill_minutes
    } else {
        cfg.empty_minutes
    } / 60.0;
    let s = (t_h - l.start_h) / dur_h;
    if s < 1.0 {
        let ramp = 0.5 - 0.5 * (std::f64::consts::PI * s).cos();
        if l.filling {
            (ramp, 1)
        } else {
            (1.0 - ramp, 3)
        }
    } else if l.filling {
        (1.0, 2)
    } else {
        (0.0, 0)
    }
}

/// AR(1) step with correlation time `tau_h` over `dt_h` and stationary sd `sd`.
fn ar1_step(prev: f64, dt_h: f64, tau_h: f64, sd: f64, rng: &mut StdRng) -> f64 {
    let rho = (-dt_h / tau_h).exp();
    let z: f64 = rng.sample(StandardNormal);
    rho * prev + sd * (1.0 - rho * rho).sqrt() * z
}

/// Day of year (0-based, fractional) of a Unix time.
fn day_of_year(unix_s: f64) -> f64 {
    let days = (unix_s / 86_400.0).floor() as i64;
    let (y, _, _) = civil_from_days(days);
    let jan1 = days_from_civil(y, 1, 1);
    unix_s / 86_400.0 - jan1 as f64
}

/// Simulates a field record. `true_strain(h_up, h_down, gap_in)` returns the noise-free gauge
/// strains (microstrain) of the gate model; its length sets the number of gauges.
///
/// ```
/// use mitergate::data::field::{simulate, FieldConfig};
/// // a toy "gate": strain proportional to the head
/// let truth = |hu: f64, hd: f64, _gap: f64| vec![0.1 * (hu - hd); 7];
/// let rec = simulate(&FieldConfig::default().duration(3.0, 60.0).seed(1), &truth).unwrap();
/// assert_eq!(rec.len(), 72);
/// assert!(rec.h_up.iter().zip(&rec.h_down).all(|(u, d)| u >= d));
/// // same seed, same numbers
/// let again = simulate(&FieldConfig::default().duration(3.0, 60.0).seed(1), &truth).unwrap();
/// assert_eq!(rec.strains, again.strains);
/// ```
pub fn simulate(
    cfg: &FieldConfig,
    true_strain: &dyn Fn(f64, f64, f64) -> Vec<f64>,
) -> Result<FieldRecord, GateError> {
    cfg.validate()?;
    let n_gauges = true_strain(cfg.upper_pool_in, cfg.lower_pool_in, cfg.gap_in).len();
    if n_gauges == 0 {
        return Err(GateError::InvalidConfig {
            parameter: "true_strain".into(),
            reason: "returned no gauge strains".into(),
        });
    }
    check_per_gauge(cfg, n_gauges)?;
    let mut rng = StdRng::seed_from_u64(cfg.seed);
    let schedule = lockage_schedule(cfg, &mut rng);
    let dt_h = cfg.step_minutes / 60.0;
    let n = (cfg.days * 24.0 / dt_h).round() as usize;
    let mut rec = FieldRecord::with_capacity(n, n_gauges);
    let mut env = Environment::default();
    for i in 0..n {
        let sample = env.step(cfg, &schedule, i as f64 * dt_h, dt_h, &mut rng);
        let mut strain = true_strain(sample.chamber, sample.lower, sample.gap);
        if strain.len() != n_gauges {
            return Err(GateError::InvalidConfig {
                parameter: "true_strain".into(),
                reason: format!(
                    "returned {} strains at row {i}, expected {n_gauges}",
                    strain.len()
                ),
            });
        }
        env.add_effects(cfg, &sample, dt_h, &mut strain);
        let row = noisy_row(cfg, &strain, &mut rng);
        rec.push(&sample, row);
    }
    Ok(rec)
}

/// The environment of one sample: time, levels, lockage state, temperatures and gap.
struct Sample {
    /// Seconds since the Unix epoch.
    unix: f64,
    /// Hours since the record start.
    t_h: f64,
    upper: f64,
    lower: f64,
    chamber: f64,
    /// Valve fraction towards the upper pool.
    frac: f64,
    phase: u8,
    air: f64,
    water: f64,
    gap: f64,
}

/// The slowly varying states of the simulation: the AR(1) pool and weather fluctuations and
/// the lagged water and steel temperatures.
#[derive(Default)]
struct Environment {
    up_noise: f64,
    low_noise: f64,
    weather: f64,
    water: Option<f64>,
    steel: Option<f64>,
}

impl Environment {
    /// Advances to `t_h` hours after the start (`dt_h` after the previous sample): three
    /// normal draws from `rng` (upper pool, lower pool, weather), in that order.
    fn step(
        &mut self,
        cfg: &FieldConfig,
        schedule: &[Lockage],
        t_h: f64,
        dt_h: f64,
        rng: &mut StdRng,
    ) -> Sample {
        let (lo, hi) = cfg.level_bounds_in;
        let unix = cfg.start_unix_s as f64 + t_h * HOUR_S;
        let doy = day_of_year(unix);
        let hour_of_day = (unix / HOUR_S).rem_euclid(24.0);
        let season = (2.0 * std::f64::consts::PI * (doy - 201.0) / 365.25).cos();
        self.up_noise = ar1_step(self.up_noise, dt_h, 48.0, cfg.pool_noise_sd_in, rng);
        self.low_noise = ar1_step(self.low_noise, dt_h, 48.0, cfg.pool_noise_sd_in, rng);
        self.weather = ar1_step(self.weather, dt_h, 12.0, cfg.weather_noise_sd_f, rng);
        let upper = (cfg.upper_pool_in + cfg.pool_seasonal_amplitude_in * season + self.up_noise)
            .clamp(lo, hi);
        let lower = (cfg.lower_pool_in + cfg.pool_seasonal_amplitude_in * season + self.low_noise)
            .clamp(lo, upper);
        let (frac, phase) = chamber_state(cfg, schedule, t_h);
        let chamber = lower + frac * (upper - lower);
        let air = cfg.air_temp_mean_f
            + cfg.air_seasonal_amplitude_f * season
            + cfg.air_daily_amplitude_f
                * (2.0 * std::f64::consts::PI * (hour_of_day - 15.0) / 24.0).cos()
            + self.weather;
        let water = lag_step(self.water, air, dt_h, cfg.water_lag_hours);
        self.water = Some(water);
        let gap = match &cfg.effects.gap_growth {
            Some(g) => cfg.gap_in + (g.final_gap_in - cfg.gap_in) * t_h / (cfg.days * 24.0),
            None => cfg.gap_in,
        };
        Sample {
            unix,
            t_h,
            upper,
            lower,
            chamber,
            frac,
            phase,
            air,
            water,
            gap,
        }
    }

    /// Adds the switched-on effects other than the gap growth (thermal, drift, offset jump,
    /// hysteresis, wall flexure) to the true strains of `sample`; the thermal effect advances
    /// the lagged steel temperature.
    fn add_effects(&mut self, cfg: &FieldConfig, sample: &Sample, dt_h: f64, strain: &mut [f64]) {
        let fx = &cfg.effects;
        let t_h = sample.t_h;
        if let Some(th) = &fx.thermal {
            let src = match th.source {
                TemperatureSource::Air => sample.air,
                TemperatureSource::Water => sample.water,
            };
            let s = lag_step(self.steel, src, dt_h, th.lag_hours);
            self.steel = Some(s);
            for (e, c) in strain.iter_mut().zip(&th.coefficients) {
                *e += c * (s - th.reference_f);
            }
        }
        if let Some(d) = &fx.drift {
            for (e, r) in strain.iter_mut().zip(&d.rates_per_day) {
                *e += r * t_h / 24.0;
            }
        }
        if let Some(j) = &fx.offset_jump
            && t_h / 24.0 >= j.at_day
        {
            strain[j.gauge] += j.size_microstrain;
        }
        if let Some(h) = &fx.hysteresis {
            let sign = match sample.phase {
                1 => -1.0,
                3 => 1.0,
                _ => 0.0,
            };
            let frac = sample.frac;
            for (e, a) in strain.iter_mut().zip(&h.amplitude) {
                *e += sign * a * 4.0 * frac * (1.0 - frac);
            }
        }
        if let Some(wf) = &fx.wall_flexure {
            for (e, c) in strain.iter_mut().zip(&wf.coefficients) {
                *e += c * (sample.upper - cfg.upper_pool_in);
            }
        }
    }
}

/// The measured row: each strain plus white noise (one normal draw per gauge, then, with
/// missing values switched on, one uniform draw deciding whether it is missing).
fn noisy_row(cfg: &FieldConfig, strain: &[f64], rng: &mut StdRng) -> Vec<Option<f64>> {
    strain
        .iter()
        .map(|e| {
            let z: f64 = rng.sample(StandardNormal);
            let missing = cfg
                .effects
                .missing
                .as_ref()
                .is_some_and(|m| rng.random::<f64>() < m.probability);
            (!missing).then_some(e + cfg.noise_sd_microstrain * z)
        })
        .collect()
}

impl FieldRecord {
    /// An empty record with room for `n` samples of `n_gauges` gauges `g1`..`gN`.
    fn with_capacity(n: usize, n_gauges: usize) -> Self {
        Self {
            time_unix_s: Vec::with_capacity(n),
            h_up: Vec::with_capacity(n),
            h_down: Vec::with_capacity(n),
            upper_pool: Vec::with_capacity(n),
            chamber: Vec::with_capacity(n),
            air_temp_f: Vec::with_capacity(n),
            water_temp_f: Vec::with_capacity(n),
            lockage_phase: Vec::with_capacity(n),
            gap_in: Vec::with_capacity(n),
            gauge_names: (1..=n_gauges).map(|g| format!("g{g}")).collect(),
            strains: Vec::with_capacity(n),
        }
    }

    /// Appends one sample (the gate's `h_up` is the chamber, `h_down` the lower pool).
    fn push(&mut self, sample: &Sample, strains: Vec<Option<f64>>) {
        self.time_unix_s.push(sample.unix.round() as i64);
        self.h_up.push(sample.chamber);
        self.h_down.push(sample.lower);
        self.upper_pool.push(sample.upper);
        self.chamber.push(sample.chamber);
        self.air_temp_f.push(sample.air);
        self.water_temp_f.push(sample.water);
        self.lockage_phase.push(sample.phase);
        self.gap_in.push(sample.gap);
        self.strains.push(strains);
    }
}

/// One step of a first-order lag (time constant `tau_h`, exact for a piecewise-constant input).
fn lag_step(prev: Option<f64>, input: f64, dt_h: f64, tau_h: f64) -> f64 {
    match prev {
        None => input,
        Some(_) if tau_h <= 0.0 => input,
        Some(p) => {
            let a = (-dt_h / tau_h).exp();
            a * p + (1.0 - a) * input
        }
    }
}

fn check_per_gauge(cfg: &FieldConfig, n_gauges: usize) -> Result<(), GateError> {
    let fx = &cfg.effects;
    let lens: [(&'static str, Option<usize>); 4] = [
        (
            "effects.thermal.coefficients",
            fx.thermal.as_ref().map(|t| t.coefficients.len()),
        ),
        (
            "effects.drift.rates_per_day",
            fx.drift.as_ref().map(|d| d.rates_per_day.len()),
        ),
        (
            "effects.hysteresis.amplitude",
            fx.hysteresis.as_ref().map(|h| h.amplitude.len()),
        ),
        (
            "effects.wall_flexure.coefficients",
            fx.wall_flexure.as_ref().map(|w| w.coefficients.len()),
        ),
    ];
    for (name, len) in lens {
        if let Some(len) = len
            && len != n_gauges
        {
            return Err(GateError::InvalidConfig {
                parameter: name.into(),
                reason: format!("need one value per gauge ({n_gauges}), got {len}"),
            });
        }
    }
    if let Some(j) = &fx.offset_jump
        && j.gauge >= n_gauges
    {
        return Err(GateError::InvalidConfig {
            parameter: "effects.offset_jump.gauge".into(),
            reason: format!("gauge index {} >= number of gauges {n_gauges}", j.gauge),
        });
    }
    Ok(())
}

/// Days since 1970-01-01 of a proleptic Gregorian date (H. Hinnant's algorithm).
fn days_from_civil(y: i64, m: i64, d: i64) -> i64 {
    let y = if m <= 2 { y - 1 } else { y };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let mp = (m + 9) % 12;
    let doy = (153 * mp + 2) / 5 + d - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

/// Date `(year, month, day)` of a day count since 1970-01-01.
fn civil_from_days(z: i64) -> (i64, i64, i64) {
    let z = z + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    (yoe + era * 400 + i64::from(m <= 2), m, d)
}

/// Formats seconds since the Unix epoch as ISO 8601 UTC, `YYYY-MM-DDTHH:MM:SSZ`.
///
/// ```
/// assert_eq!(mitergate::data::field::iso8601_from_unix(1_717_200_000), "2024-06-01T00:00:00Z");
/// ```
pub fn iso8601_from_unix(unix_s: i64) -> String {
    let days = unix_s.div_euclid(86_400);
    let secs = unix_s.rem_euclid(86_400);
    let (y, m, d) = civil_from_days(days);
    format!(
        "{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}Z",
        secs / 3600,
        (secs % 3600) / 60,
        secs % 60
    )
}

/// Parses ISO 8601 `YYYY-MM-DDTHH:MM[:SS[.fff]]` with an optional `Z` or `±HH:MM` offset (a
/// space may replace the `T`) into seconds since the Unix epoch. `None` when malformed.
///
/// ```
/// use mitergate::data::field::unix_from_iso8601;
/// assert_eq!(unix_from_iso8601("2024-06-01T00:00:00Z"), Some(1_717_200_000.0));
/// assert_eq!(unix_from_iso8601("2024-06-01 02:00:00+02:00"), Some(1_717_200_000.0));
/// assert_eq!(unix_from_iso8601("2024-13-01T00:00:00Z"), None);
/// ```
pub fn unix_from_iso8601(s: &str) -> Option<f64> {
    let s = s.trim();
    let b = s.as_bytes();
    if b.len() < 16
        || b[4] != b'-'
        || b[7] != b'-'
        || !(b[10] == b'T' || b[10] == b' ')
        || b[13] != b':'
    {
        return None;
    }
    let num = |r: std::ops::Range<usize>| -> Option<i64> {
        let t = s.get(r)?;
        if t.bytes().all(|c| c.is_ascii_digit()) {
            t.parse().ok()
        } else {
            None
        }
    };
    let (y, mo, d, h, mi) = (
        num(0..4)?,
        num(5..7)?,
        num(8..10)?,
        num(11..13)?,
        num(14..16)?,
    );
    let mut rest = &s[16..];
    let mut sec = 0.0;
    if let Some(r) = rest.strip_prefix(':') {
        let end = r
            .find(|c: char| !(c.is_ascii_digit() || c == '.'))
            .unwrap_or(r.len());
        sec = r[..end].parse::<f64>().ok()?;
        rest = &r[end..];
    }
    let offset_s = match rest {
        "" | "Z" => 0,
        _ => {
            let sign = match rest.as_bytes()[0] {
                b'+' => 1,
                b'-' => -1,
                _ => return None,
            };
            let r = &rest[1..];
            if r.len() != 5 || r.as_bytes()[2] != b':' {
                return None;
            }
            let oh: i64 = r[..2].parse().ok()?;
            let om: i64 = r[3..].parse().ok()?;
            sign * (oh * 3600 + om * 60)
        }
    };
    if !(1..=12).contains(&mo)
        || !(1..=31).contains(&d)
        || h > 23
        || mi > 59
        || !(0.0..61.0).contains(&sec)
    {
        return None;
    }
    let days = days_from_civil(y, mo, d);
    Some((days * 86_400 + h * 3600 + mi * 60 - offset_s) as f64 + sec)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn iso_round_trip_over_leap_years() {
        for unix in [0_i64, 951_782_400, 1_709_164_800, 4_107_542_399, -86_400] {
            let s = iso8601_from_unix(unix);
            assert_eq!(unix_from_iso8601(&s), Some(unix as f64), "{s}");
        }
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig { cases: 64, ..Default::default() })]
        #[test]
        fn iso_round_trip_any_second(unix in -2_000_000_000_i64..8_000_000_000) {
            proptest::prop_assert_eq!(unix_from_iso8601(&iso8601_from_unix(unix)), Some(unix as f64));
        }
    }

    #[test]
    fn zero_head_when_chamber_down_and_phases_consistent() {
        let cfg = FieldConfig::default().duration(5.0, 10.0).seed(3);
        let r = simulate(&cfg, &|hu, hd, _| vec![hu - hd; 7]).unwrap();
        for i in 0..r.len() {
            let head = r.h_up[i] - r.h_down[i];
            match r.lockage_phase[i] {
                0 => assert_eq!(head, 0.0),
                2 => assert!((r.h_up[i] - r.upper_pool[i]).abs() < 1e-9),
                _ => assert!(head >= 0.0 && r.h_up[i] <= r.upper_pool[i] + 1e-9),
            }
        }
        // both transitions occur in 5 days at 8 lockages a day
        assert!(r.lockage_phase.contains(&1) && r.lockage_phase.contains(&3));
    }

    #[test]
    fn per_gauge_length_mismatch_is_an_error() {
        let fx = FieldEffects {
            drift: Some(DriftEffect {
                rates_per_day: vec![0.1; 3],
            }),
            ..Default::default()
        };
        let err =
            simulate(&FieldConfig::default().effects(fx), &|_, _, _| vec![0.0; 7]).unwrap_err();
        assert!(err.to_string().contains("rates_per_day"), "{err}");
    }

    #[test]
    fn missing_values_appear_at_the_requested_rate() {
        let fx = FieldEffects {
            missing: Some(MissingValues { probability: 0.1 }),
            ..Default::default()
        };
        let r = simulate(
            &FieldConfig::default().effects(fx).duration(20.0, 60.0),
            &|_, _, _| vec![0.0; 7],
        )
        .unwrap();
        let n_missing = r.strains.iter().flatten().filter(|v| v.is_none()).count();
        let frac = n_missing as f64 / (r.len() * 7) as f64;
        // 3360 Bernoulli(0.1) draws: sd of the fraction is 0.005, allow 4 sd
        assert!((frac - 0.1).abs() < 0.02, "{frac}");
    }
}
