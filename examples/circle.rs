//! The circle system `dx/dt = (−y, x, 0)` from (1, 0, 0), whose exact solution is the unit
//! circle: the drift of |x| from 1 shows each method's character — forward Euler spirals
//! out, symplectic Euler and the trapezoid stay close, RK4 holds it to plotting precision.
//! `cargo run --release --example circle -- e 0.0167` (letter and h as the sample solution;
//! steps never exceed the 1/60 s frame).
//!
//! Keys: E/S/T/M/K/A switch method (K = RK4; implicit methods need particles), Space pause,
//! N single step, R reset; right drag or arrows orbit, wheel zoom.

#[path = "common/mod.rs"]
mod common;

use bevy::prelude::*;
use bevy_soft_body::prelude::*;

fn main() {
    let args = common::args("circle");
    let mut app = common::app("circle", &args);
    let kind = args.integrator.unwrap_or(IntegratorKind::ForwardEuler);
    common::circle::add(
        &mut app,
        kind,
        args.h.unwrap_or(1.0 / 60.0),
        Vec3::ZERO,
        1.0,
    );
    app.add_systems(Startup, |mut c: Commands| {
        common::stage(&mut c, Vec3::ZERO, 4.0);
    });
    app.run();
}
