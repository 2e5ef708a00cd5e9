//! Soft-body measurements in Bevy's [`DiagnosticsStore`]: step time, substeps, linear-solver
//! (conjugate-gradient) and Newton iterations, bodies and particles, and self-collision's
//! passes, searches, candidates and broad- and narrow-phase times — per fixed frame, summed
//! over every body. Read them as any other diagnostic (`LogDiagnosticsPlugin`, the panel).

use super::components::{BodyState, SoftBodyStatus};
use bevy::diagnostic::{Diagnostic, DiagnosticPath, Diagnostics, RegisterDiagnostic};
use bevy::prelude::*;

/// Paths of the soft-body diagnostics (the namespace of this crate's measurements).
pub struct SoftBodyDiagnostics;

impl SoftBodyDiagnostics {
    /// Wall time of the last fixed frame's [`Step`](super::SoftBodySystems::Step) set, every
    /// body included (ms).
    pub const STEP_TIME: DiagnosticPath = DiagnosticPath::const_new("soft_body/step_time");
    /// Substeps in the last fixed frame, summed over bodies.
    pub const SUBSTEPS: DiagnosticPath = DiagnosticPath::const_new("soft_body/substeps");
    /// Iterations of the iterative linear solver (preconditioned conjugate gradients) in the
    /// last fixed frame, summed over bodies (direct solves count none).
    pub const LINEAR_ITERATIONS: DiagnosticPath =
        DiagnosticPath::const_new("soft_body/linear_iterations");
    /// Newton iterations (backward Euler) in the last fixed frame, summed over bodies.
    pub const NEWTON_ITERATIONS: DiagnosticPath =
        DiagnosticPath::const_new("soft_body/newton_iterations");
    /// Bodies being simulated (built, not left out for bad input).
    pub const BODIES: DiagnosticPath = DiagnosticPath::const_new("soft_body/bodies");
    /// Particles in the simulated bodies.
    pub const PARTICLES: DiagnosticPath = DiagnosticPath::const_new("soft_body/particles");
    /// Self-collision passes in the last fixed frame, summed over bodies (a pass of the
    /// contact between bodies counts once for each body in it; see
    /// [`SoftBodyStatus::contact_passes`]).
    pub const CONTACT_PASSES: DiagnosticPath =
        DiagnosticPath::const_new("soft_body/contact_passes");
    /// Self-collision's broad-phase searches in the last fixed frame, summed over bodies
    /// (counted as the passes are).
    pub const CONTACT_SEARCHES: DiagnosticPath =
        DiagnosticPath::const_new("soft_body/contact_searches");
    /// Candidate pairs the bodies' self-collision holds after the last fixed frame.
    pub const CONTACT_CANDIDATES: DiagnosticPath =
        DiagnosticPath::const_new("soft_body/contact_candidates");
    /// Wall time of self-collision's broad phase in the last fixed frame, summed over bodies
    /// (ms).
    pub const CONTACT_BROAD_TIME: DiagnosticPath =
        DiagnosticPath::const_new("soft_body/contact_broad_time");
    /// Wall time of self-collision's narrow phase and responses in the last fixed frame,
    /// summed over bodies (ms).
    pub const CONTACT_NARROW_TIME: DiagnosticPath =
        DiagnosticPath::const_new("soft_body/contact_narrow_time");

    /// Every path, in the order above.
    pub const ALL: [DiagnosticPath; 11] = [
        Self::STEP_TIME,
        Self::SUBSTEPS,
        Self::LINEAR_ITERATIONS,
        Self::NEWTON_ITERATIONS,
        Self::BODIES,
        Self::PARTICLES,
        Self::CONTACT_PASSES,
        Self::CONTACT_SEARCHES,
        Self::CONTACT_CANDIDATES,
        Self::CONTACT_BROAD_TIME,
        Self::CONTACT_NARROW_TIME,
    ];
}

/// Wall time of the last fixed frame's step set (internal; written by the step system).
#[derive(Resource, Default)]
pub(crate) struct StepTiming {
    pub(crate) ms: Option<f64>,
}

pub(crate) fn register(app: &mut App) {
    app.init_resource::<StepTiming>();
    let timed = [
        SoftBodyDiagnostics::STEP_TIME,
        SoftBodyDiagnostics::CONTACT_BROAD_TIME,
        SoftBodyDiagnostics::CONTACT_NARROW_TIME,
    ];
    for path in SoftBodyDiagnostics::ALL {
        let suffix = if timed.contains(&path) { "ms" } else { "" };
        app.register_diagnostic(Diagnostic::new(path).with_suffix(suffix));
    }
}

/// Adds one measurement of each diagnostic per fixed frame that stepped.
pub(crate) fn measure(
    mut timing: ResMut<StepTiming>,
    mut diagnostics: Diagnostics,
    bodies: Query<&SoftBodyStatus>,
) {
    let Some(ms) = timing.ms.take() else { return };
    let (mut n, mut particles, mut substeps, mut linear, mut newton) = (0u32, 0u64, 0, 0, 0);
    let (mut passes, mut searches, mut candidates) = (0u64, 0u64, 0u64);
    let (mut broad, mut narrow) = (0.0, 0.0);
    for s in &bodies {
        if matches!(s.state, BodyState::Invalid(_) | BodyState::Pending) {
            continue;
        }
        n += 1;
        particles += s.particles as u64;
        if s.state != BodyState::Running {
            continue; // paused or stopped: took no substeps this frame
        }
        substeps += s.substeps as u64;
        linear += s.linear_iterations as u64;
        newton += s.newton_iterations as u64;
        passes += s.contact_passes as u64;
        searches += s.contact_searches as u64;
        candidates += s.contact_candidates as u64;
        broad += s.contact_broad_ms as f64;
        narrow += s.contact_narrow_ms as f64;
    }
    diagnostics.add_measurement(&SoftBodyDiagnostics::STEP_TIME, || ms);
    diagnostics.add_measurement(&SoftBodyDiagnostics::SUBSTEPS, || substeps as f64);
    diagnostics.add_measurement(&SoftBodyDiagnostics::LINEAR_ITERATIONS, || linear as f64);
    diagnostics.add_measurement(&SoftBodyDiagnostics::NEWTON_ITERATIONS, || newton as f64);
    diagnostics.add_measurement(&SoftBodyDiagnostics::BODIES, || n as f64);
    diagnostics.add_measurement(&SoftBodyDiagnostics::PARTICLES, || particles as f64);
    diagnostics.add_measurement(&SoftBodyDiagnostics::CONTACT_PASSES, || passes as f64);
    diagnostics.add_measurement(&SoftBodyDiagnostics::CONTACT_SEARCHES, || searches as f64);
    diagnostics.add_measurement(&SoftBodyDiagnostics::CONTACT_CANDIDATES, || {
        candidates as f64
    });
    diagnostics.add_measurement(&SoftBodyDiagnostics::CONTACT_BROAD_TIME, || broad);
    diagnostics.add_measurement(&SoftBodyDiagnostics::CONTACT_NARROW_TIME, || narrow);
}
