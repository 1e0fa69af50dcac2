//! The floating-point abstraction shared by the f32 and f64 kernels.

use serde::{Deserialize, Serialize};

/// Arithmetic precision of the network's weights and kernels.
///
/// Training data and predictions are always `f64` at the API boundary; the precision only selects
/// the type used inside the forward/backward kernels and for the stored weights.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
pub enum Precision {
    /// Single precision: roughly twice the GEMM throughput, about 7 significant digits.
    #[default]
    F32,
    /// Double precision: use for gradient checks and when the loss must be resolved below ~1e-6.
    F64,
}

/// A real scalar the LSTM kernels can run on: `f32` or `f64` (the trait is sealed).
///
/// Besides the conversions and the few transcendental functions the gates need, the kernels
/// require what faer's matrix multiply needs; that requirement sits on a private supertrait,
/// so no faer type is part of this crate's public API.
pub trait Float:
    sealed::Kernel
    + Copy
    + Default
    + Send
    + Sync
    + Serialize
    + for<'de> Deserialize<'de>
    + std::ops::Neg<Output = Self>
    + 'static
{
    /// The [`Precision`] tag of this type.
    const PRECISION: Precision;
    /// Converts from `f64` (rounding to nearest for `f32`).
    fn of(v: f64) -> Self;
    /// Converts to `f64` (exact).
    fn f64(self) -> f64;
    /// Natural exponential.
    fn exp(self) -> Self;
    /// Hyperbolic tangent.
    fn tanh(self) -> Self;
    /// Square root.
    fn sqrt(self) -> Self;
    /// Branch-free exponential for the gate kernels (see [`fast_exp_f32`], [`fast_exp_f64`]).
    fn exp_fast(self) -> Self;
    /// Logistic sigmoid `1 / (1 + exp(-x))` on the branch-free exponential.
    #[inline(always)]
    fn sigmoid(self) -> Self {
        let one = Self::of(1.0);
        one / (one + (-self).exp_fast())
    }
    /// Hyperbolic tangent `1 - 2 / (1 + exp(2x))` on the branch-free exponential (absolute error
    /// a few units of `Self::EPSILON`, exact limits +-1).
    #[inline(always)]
    fn tanh_fast(self) -> Self {
        let one = Self::of(1.0);
        one - Self::of(2.0) / (one + (self + self).exp_fast())
    }
}

/// `exp(x)` for f32 without branches or library calls, so loops over slices auto-vectorise.
///
/// Cody-Waite reduction `x = n ln2 + r`, `|r| <= ln2 / 2`, a degree-7 Taylor polynomial for
/// `exp(r)` (truncation error below 5e-9 relative, under half an f32 ulp) and `2^n` assembled in
/// the exponent bits. `n` is rounded with the `1.5 * 2^23` trick, which also leaves `n` in the low
/// mantissa bits, so no float-to-int conversion is needed. The argument is clamped to
/// `[-87, 88]` (results stay normal and finite).
///
/// ```
/// for x in [-20.0f32, -1.0, 0.0, 0.3, 5.0, 80.0] {
///     let rel = (seqnet::fast_exp_f32(x) - x.exp()).abs() / x.exp();
///     assert!(rel < 4.0 * f32::EPSILON, "{x}: {rel}");
/// }
/// ```
#[inline(always)]
pub fn fast_exp_f32(x: f32) -> f32 {
    const MAGIC: f32 = 12_582_912.0; // 1.5 * 2^23
    const LN2_HI: f32 = 0.693_359_4;
    const LN2_LO: f32 = -2.121_944_4e-4;
    let x = x.clamp(-87.0, 88.0);
    let v = x * std::f32::consts::LOG2_E + MAGIC;
    let n = v - MAGIC;
    let r = x - n * LN2_HI - n * LN2_LO;
    let mut p = 1.0 / 5040.0;
    for c in [
        1.0 / 720.0,
        1.0 / 120.0,
        1.0 / 24.0,
        1.0 / 6.0,
        0.5,
        1.0,
        1.0,
    ] {
        p = p * r + c;
    }
    let scale = f32::from_bits(v.to_bits().wrapping_sub(MAGIC.to_bits()).wrapping_add(127) << 23);
    p * scale
}

/// `exp(x)` for f64 without branches or library calls: as [`fast_exp_f32`] with the `1.5 * 2^52`
/// rounding constant and a degree-13 Taylor polynomial (truncation error below 1e-17 relative);
/// the argument is clamped to `[-708, 709]`.
///
/// ```
/// for x in [-300.0f64, -1.0, 0.0, 0.3, 5.0, 700.0] {
///     let rel = (seqnet::fast_exp_f64(x) - x.exp()).abs() / x.exp();
///     assert!(rel < 4.0 * f64::EPSILON, "{x}: {rel}");
/// }
/// ```
#[inline(always)]
pub fn fast_exp_f64(x: f64) -> f64 {
    const MAGIC: f64 = 6_755_399_441_055_744.0; // 1.5 * 2^52
    // fdlibm's split of ln 2: the high part has trailing zero bits so n * LN2_HI is exact.
    const LN2_HI: f64 = f64::from_bits(0x3fe6_2e42_fee0_0000);
    const LN2_LO: f64 = f64::from_bits(0x3dea_39ef_3579_3c76);
    let x = x.clamp(-708.0, 709.0);
    let v = x * std::f64::consts::LOG2_E + MAGIC;
    let n = v - MAGIC;
    let r = x - n * LN2_HI - n * LN2_LO;
    // Taylor coefficients 1/k!, k = 12 down to 0 (Horner), after the leading 1/13!.
    const C: [f64; 13] = [
        1.0 / 479_001_600.0,
        1.0 / 39_916_800.0,
        1.0 / 3_628_800.0,
        1.0 / 362_880.0,
        1.0 / 40_320.0,
        1.0 / 5_040.0,
        1.0 / 720.0,
        1.0 / 120.0,
        1.0 / 24.0,
        1.0 / 6.0,
        0.5,
        1.0,
        1.0,
    ];
    let mut p = 1.0 / 6_227_020_800.0;
    for c in C {
        p = p * r + c;
    }
    let scale = f64::from_bits(v.to_bits().wrapping_sub(MAGIC.to_bits()).wrapping_add(1023) << 52);
    p * scale
}

mod sealed {
    /// The faer bound of the GEMM kernels; implemented for `f32` and `f64` only, and not
    /// nameable outside the crate, which seals [`super::Float`].
    pub trait Kernel: faer::traits::RealField {}
    impl Kernel for f32 {}
    impl Kernel for f64 {}
}

macro_rules! impl_float {
    ($t:ty, $p:expr, $fast:ident) => {
        impl Float for $t {
            const PRECISION: Precision = $p;
            #[inline(always)]
            fn of(v: f64) -> Self {
                v as $t
            }
            #[inline(always)]
            fn f64(self) -> f64 {
                self as f64
            }
            #[inline(always)]
            fn exp(self) -> Self {
                <$t>::exp(self)
            }
            #[inline(always)]
            fn tanh(self) -> Self {
                <$t>::tanh(self)
            }
            #[inline(always)]
            fn sqrt(self) -> Self {
                <$t>::sqrt(self)
            }
            #[inline(always)]
            fn exp_fast(self) -> Self {
                $fast(self)
            }
        }
    };
}
impl_float!(f32, Precision::F32, fast_exp_f32);
impl_float!(f64, Precision::F64, fast_exp_f64);
