//! The numerics, free of Bevy: ODE abstraction, integrators, the particle model and its
//! forces, collisions, scene layouts and the headless driver. Everything here can be tested,
//! benchmarked and charted without a window or an App.

pub mod auto;
pub mod body_contact;
pub mod build;
pub mod collide;
pub mod detail;
pub mod driver;
pub mod fem;
pub mod forces;
pub mod integrate;
pub mod jacobian;
pub mod kernels;
pub mod layout;
pub mod motion;
pub mod ode;
pub mod particles;
pub mod scene;
pub mod self_contact;
pub mod solve;
pub mod study;
pub mod tear;

/// Room in `v` for `want` entries in all (`Vec::reserve` asks for room beyond the length):
/// nothing is allocated where there is room already. The scratch lists that steps keep grow
/// so, once, to what their body may need.
pub(crate) fn room<T>(v: &mut Vec<T>, want: usize) {
    v.reserve(want.saturating_sub(v.len()));
}
