//! Force units. Each is a separate piece a model composes; a model pays only for the forces it
//! has (an absent force is an empty list or `None`, skipped without a loop).

mod field;
mod spring;
pub(crate) mod wind;

pub use field::{Buoyancy, FieldJacobian, ForceField, RadialBlast, SharedField};
pub use spring::{PackedSpring, SpringLaw, Springs};
pub use wind::{Wind, WindField};
