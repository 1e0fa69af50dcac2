//! Robust location and scale.

/// Median (sorts `v` in place; 0 when `v` is empty).
///
/// ```
/// assert_eq!(numerics::robust::median(&mut [3.0, 1.0, 2.0, 10.0]), 2.5);
/// assert_eq!(numerics::robust::median(&mut []), 0.0);
/// ```
pub fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Median absolute deviation from the median, unscaled (sorts `v` in place; 0 when `v` is
/// empty). Divide by 0.6745 for a normal sd.
///
/// ```
/// assert_eq!(numerics::robust::mad(&mut [1.0, 2.0, 3.0, 4.0, 100.0]), 1.0);
/// assert_eq!(numerics::robust::mad(&mut []), 0.0);
/// ```
pub fn mad(v: &mut [f64]) -> f64 {
    let med = median(v);
    let mut dev: Vec<f64> = v.iter().map(|x| (x - med).abs()).collect();
    median(&mut dev)
}

/// Robust white-noise standard deviation of a series: the median absolute deviation of its
/// first differences over `0.6745 √2`. Slow effects (drift, seasons) barely change first
/// differences, and rare jumps are outliers the median ignores.
///
/// ```
/// // a steady trend is not noise; a zig-zag of ±0.5 is
/// let trend: Vec<f64> = (0..50).map(|i| 0.1 * i as f64).collect();
/// assert!(numerics::robust::noise_sd_from_differences(&trend) < 1e-12);
/// let zigzag: Vec<f64> = (0..51).map(|i| if i % 2 == 0 { 0.5 } else { -0.5 }).collect();
/// let sd = numerics::robust::noise_sd_from_differences(&zigzag);
/// assert!((sd - 1.0 / (0.6745 * 2f64.sqrt())).abs() < 1e-12);
/// ```
pub fn noise_sd_from_differences(r: &[f64]) -> f64 {
    let mut d: Vec<f64> = r.windows(2).map(|w| w[1] - w[0]).collect();
    if d.is_empty() {
        return 0.0;
    }
    mad(&mut d) / 0.6745 / std::f64::consts::SQRT_2
}
