//! Precision switch: `Scalar`/`Vector` are `f32`/`Vec3A` by default (Bevy's precision) and
//! `f64`/`DVec3` with the `f64` feature, for accuracy studies.

#[cfg(not(feature = "f64"))]
mod prec {
    /// The floating-point type of every simulated quantity.
    pub type Scalar = f32;
    /// A 3-vector of [`Scalar`]: glam's 16-byte SIMD `Vec3A`, which made the spring kernel
    /// 12–18 % faster than the 12-byte `Vec3` (docs/BENCHMARKS.md). Bevy's `Vec3` converts with
    /// [`VectorExt::to_f32`](super::VectorExt::to_f32) and
    /// [`ToScalar::to_scalar`](super::ToScalar::to_scalar).
    pub type Vector = glam::Vec3A;
    /// A 3×3 matrix of [`Scalar`] (blocks of sparse Jacobians).
    pub type Matrix3 = glam::Mat3A;
    /// Name of the precision, printed on charts and tables.
    pub const PRECISION: &str = "f32";
}

#[cfg(feature = "f64")]
mod prec {
    /// The floating-point type of every simulated quantity.
    pub type Scalar = f64;
    /// A 3-vector of [`Scalar`].
    pub type Vector = glam::DVec3;
    /// A 3×3 matrix of [`Scalar`] (blocks of sparse Jacobians).
    pub type Matrix3 = glam::DMat3;
    /// Name of the precision, printed on charts and tables.
    pub const PRECISION: &str = "f64";
}

pub use prec::*;

/// Machine epsilon of [`Scalar`].
pub const EPS: Scalar = Scalar::EPSILON;

/// Conversion into the simulation's precision: `f64` and `[f64; 3]` (how layouts are
/// described), `f32` and `glam::Vec3` (Bevy's and parry's precision) become [`Scalar`] and
/// [`Vector`] with `.to_scalar()`.
pub trait ToScalar {
    /// [`Scalar`] or [`Vector`].
    type Output;
    /// The value in the simulation's precision.
    fn to_scalar(self) -> Self::Output;
}

impl ToScalar for f64 {
    type Output = Scalar;
    #[inline(always)]
    fn to_scalar(self) -> Scalar {
        self as Scalar
    }
}

impl ToScalar for f32 {
    type Output = Scalar;
    #[inline(always)]
    #[allow(clippy::unnecessary_cast)] // a no-op in the f32 build, a widening in the f64 one
    fn to_scalar(self) -> Scalar {
        self as Scalar
    }
}

impl ToScalar for [f64; 3] {
    type Output = Vector;
    #[inline(always)]
    fn to_scalar(self) -> Vector {
        Vector::new(self[0] as Scalar, self[1] as Scalar, self[2] as Scalar)
    }
}

impl ToScalar for glam::Vec3 {
    type Output = Vector;
    #[inline(always)]
    #[allow(clippy::unnecessary_cast)] // a no-op in the f32 build, a widening in the f64 one
    fn to_scalar(self) -> Vector {
        Vector::new(self.x as Scalar, self.y as Scalar, self.z as Scalar)
    }
}

/// Conversion of a simulation [`Vector`] out to the world's forms: `.to_f32()` (Bevy's and
/// parry's `Vec3`) and `.to_f64()` (`[f64; 3]`, how layouts are described).
pub trait VectorExt {
    /// As Bevy's / parry's `f32` vector.
    fn to_f32(self) -> glam::Vec3;
    /// As `[f64; 3]`.
    fn to_f64(self) -> [f64; 3];
}

impl VectorExt for Vector {
    #[inline(always)]
    #[allow(clippy::unnecessary_cast)] // a no-op in the f32 build, a narrowing in the f64 one
    fn to_f32(self) -> glam::Vec3 {
        glam::Vec3::new(self.x as f32, self.y as f32, self.z as f32)
    }

    #[inline(always)]
    #[allow(clippy::unnecessary_cast)] // a widening in the f32 build, a no-op in the f64 one
    fn to_f64(self) -> [f64; 3] {
        [self.x as f64, self.y as f64, self.z as f64]
    }
}

/// The unit tests' random numbers: Marsaglia's xorshift64 (*Xorshift RNGs*, 2003) from
/// `seed`, each call a uniform number in [−1, 1) with 53 random bits.
#[cfg(test)]
pub(crate) fn test_rng(mut seed: u64) -> impl FnMut() -> f64 {
    move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    }
}
