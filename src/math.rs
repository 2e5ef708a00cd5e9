//! Precision switch: `Scalar`/`Vector` are `f32`/`Vec3A` by default (Bevy's precision) and
//! `f64`/`DVec3` with the `f64` feature, for accuracy studies.

#[cfg(not(feature = "f64"))]
mod prec {
    /// The floating-point type of every simulated quantity.
    pub type Scalar = f32;
    /// A 3-vector of [`Scalar`]: glam's 16-byte SIMD `Vec3A`, which made the spring kernel
    /// 12–18 % faster than the 12-byte `Vec3` (docs/BENCHMARKS.md). Bevy's `Vec3` converts with
    /// [`to_f32`](super::to_f32) / [`from_f32`](super::from_f32).
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

/// Converts an `f64` (how layouts are described) to [`Scalar`].
#[inline(always)]
pub fn sc(x: f64) -> Scalar {
    x as Scalar
}

/// Converts a `[f64; 3]` (how layouts are described) to a [`Vector`].
#[inline(always)]
pub fn vec3(a: [f64; 3]) -> Vector {
    Vector::new(a[0] as Scalar, a[1] as Scalar, a[2] as Scalar)
}

/// Converts a [`Vector`] to `[f64; 3]`.
#[inline(always)]
pub fn to_f64(v: Vector) -> [f64; 3] {
    [v.x as f64, v.y as f64, v.z as f64]
}

/// Converts a [`Vector`] to Bevy's / parry's `f32` vector.
#[inline(always)]
#[allow(clippy::unnecessary_cast)] // a no-op in the f32 build, a narrowing in the f64 one
pub fn to_f32(v: Vector) -> glam::Vec3 {
    glam::Vec3::new(v.x as f32, v.y as f32, v.z as f32)
}

/// Converts an `f32` vector (Bevy's, parry's) to a [`Vector`].
#[inline(always)]
#[allow(clippy::unnecessary_cast)] // a no-op in the f32 build, a widening in the f64 one
pub fn from_f32(v: glam::Vec3) -> Vector {
    Vector::new(v.x as Scalar, v.y as Scalar, v.z as Scalar)
}
