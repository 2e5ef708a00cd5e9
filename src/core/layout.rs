//! One path from a body's description to its simulated model.
//!
//! A [`BodyLayout`] is a body as plain numbers with particle indices: masses, anchors, springs,
//! tets, forces, gravity, drag, wind. [`BodyLayout::validate`] holds every rule a body must
//! satisfy to be simulated, and [`BodyLayout::build`] is the only place that turns one into a
//! [`ParticleModel`] and its initial [`ParticleState`]. Both faces of the crate go through it:
//! [`Scene::build`](crate::core::scene::Scene::build) (the core driver, studies, charts) and the
//! plugin, which gathers a body's components into a layout. A body stepped by the plugin is
//! therefore the model the core driver steps, by construction, and a rule added here holds for
//! both; each face only translates [`LayoutError`]s into its own words (a field path like
//! `springs[3].b`, or the entity behind the index).

use crate::core::fem::{NeoHookean, Tets};
use crate::core::forces::{SpringLaw, Wind};
use crate::core::motion::Motion;
use crate::core::ode::ParticleState;
use crate::core::particles::ParticleModel;
use crate::core::self_contact::{ContactSurface, SelfContact, SelfContactParams};
use crate::math::ToScalar;
use glam::DVec3;
use std::fmt;

/// How a particle is held.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum Anchor {
    /// Moves under its forces.
    #[default]
    Free,
    /// Held at its initial position; starts at rest whatever velocity it was given.
    Pinned,
    /// Moved along a path (its initial position and velocity are the layout's).
    Moving(Motion),
}

/// One particle.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LayoutParticle {
    /// Initial position (m).
    pub position: [f64; 3],
    /// Initial velocity (m/s).
    pub velocity: [f64; 3],
    /// Mass (kg); may be zero for an anchored particle.
    pub mass: f64,
    /// Free, pinned or moved.
    pub anchor: Anchor,
}

/// One spring between particles `a` and `b`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LayoutSpring {
    /// First particle.
    pub a: usize,
    /// Second particle.
    pub b: usize,
    /// Rest length (m); the initial distance when absent.
    pub rest_length: Option<f64>,
    /// Stiffness: N/m for Hooke, N for strain.
    pub stiffness: f64,
    /// Damper along the spring (N·s/m).
    pub damping: f64,
    /// Force law.
    pub law: SpringLaw,
}

/// One linear tetrahedron.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LayoutTet {
    /// Particle indices.
    pub vertices: [usize; 4],
    /// Rest shape; the vertices' initial positions when absent.
    pub rest: Option<[DVec3; 4]>,
    /// Its own material; the layout's when absent.
    pub material: Option<NeoHookean>,
}

/// A body as plain numbers: what [`BodyLayout::build`] turns into a model.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BodyLayout {
    /// Particles.
    pub particles: Vec<LayoutParticle>,
    /// Springs.
    pub springs: Vec<LayoutSpring>,
    /// Tetrahedra.
    pub tets: Vec<LayoutTet>,
    /// Material of tets without their own.
    pub material: Option<NeoHookean>,
    /// Constant forces (N) on particles.
    pub forces: Vec<(usize, [f64; 3])>,
    /// Gravitational acceleration (m/s²).
    pub gravity: [f64; 3],
    /// Viscous drag coefficient (N·s/m).
    pub drag: f64,
    /// Wind.
    pub wind: Option<Wind>,
    /// Surface triangles (particle indices), for contact of the surface with colliders between
    /// its particles and with itself (empty: the tets' boundary, or none).
    pub surface: Vec<[u32; 3]>,
    /// Contact of the surface with itself (`None`: none).
    pub self_collision: Option<SelfContactParams>,
    /// For each particle, the particle it was split from by tearing (empty: none split); see
    /// [`ContactSurface::torn`].
    pub torn_from: Vec<u32>,
}

/// Which part of a layout a problem is in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LayoutItem {
    /// The body as a whole (gravity, drag, wind, material).
    Body,
    /// Particle `i`.
    Particle(usize),
    /// Spring `k`.
    Spring(usize),
    /// Tet `k`.
    Tet(usize),
    /// Force `k`.
    Force(usize),
}

/// One problem in a layout: where, which field, what.
#[derive(Clone, Debug, PartialEq)]
pub struct LayoutError {
    /// The part.
    pub item: LayoutItem,
    /// The field (`"mass"`, `"b"`, `"rest_length"`; empty for the part as a whole).
    pub field: &'static str,
    /// What is wrong.
    pub message: String,
}

impl fmt::Display for LayoutError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.item {
            LayoutItem::Body => write!(f, "body")?,
            LayoutItem::Particle(i) => write!(f, "particle {i}")?,
            LayoutItem::Spring(k) => write!(f, "spring {k}")?,
            LayoutItem::Tet(k) => write!(f, "tet {k}")?,
            LayoutItem::Force(k) => write!(f, "force {k}")?,
        }
        if !self.field.is_empty() {
            write!(f, " {}", self.field)?;
        }
        write!(f, ": {}", self.message)
    }
}

fn finite3(a: &[f64; 3]) -> bool {
    a.iter().all(|x| x.is_finite())
}

fn distance(a: [f64; 3], b: [f64; 3]) -> f64 {
    (DVec3::from_array(a) - DVec3::from_array(b)).length()
}

impl BodyLayout {
    /// Rest length of spring `k` (given, or the initial distance of its ends).
    pub fn rest_length(&self, k: usize) -> f64 {
        let s = &self.springs[k];
        s.rest_length
            .unwrap_or_else(|| distance(self.particles[s.a].position, self.particles[s.b].position))
    }

    /// The triangles contact uses (with colliders and with itself): the surface's, or the
    /// tets' boundary when the layout has no surface.
    pub fn contact_triangles(&self) -> Vec<[u32; 3]> {
        if self.surface.is_empty() && !self.tets.is_empty() {
            crate::core::fem::mesh::boundary_faces(
                &self
                    .tets
                    .iter()
                    .map(|t| t.vertices.map(|v| v as u32))
                    .collect::<Vec<_>>(),
            )
        } else {
            self.surface.clone()
        }
    }

    /// Every rule a body must satisfy to be simulated; all problems at once, in the order of
    /// the layout's parts.
    pub fn validate(&self) -> Vec<LayoutError> {
        let mut errs = Vec::new();
        let mut err = |item, field, message: &str| {
            errs.push(LayoutError {
                item,
                field,
                message: message.to_string(),
            })
        };
        let n = self.particles.len();
        if !finite3(&self.gravity) {
            err(LayoutItem::Body, "gravity", "must be finite");
        }
        if !(self.drag.is_finite() && self.drag >= 0.0) {
            err(LayoutItem::Body, "drag", "must be finite and non-negative");
        }
        if let Some(w) = &self.wind
            && !(finite3(&w.velocity)
                && w.gust.is_finite()
                && w.frequency.is_finite()
                && w.coefficient.is_finite()
                && w.coefficient >= 0.0)
        {
            err(
                LayoutItem::Body,
                "wind",
                "numbers must be finite and the coefficient non-negative",
            );
        }
        if let Some(Err(m)) = self.material.map(|m| m.validate()) {
            err(LayoutItem::Body, "material", m);
        }
        if let Some(sc) = &self.self_collision {
            let triangles = self.contact_triangles();
            if triangles.iter().flatten().any(|&i| i as usize >= n) {
                err(
                    LayoutItem::Body,
                    "surface",
                    "a triangle's index is out of range",
                );
            } else {
                let x: Vec<DVec3> = self
                    .particles
                    .iter()
                    .map(|p| DVec3::from_array(p.position))
                    .collect();
                let shortest = ContactSurface::new(&triangles).shortest_edge(&x);
                if let Err((field, m)) = sc.validate(shortest) {
                    let field = match field {
                        "friction" => "self_collision.friction",
                        _ => "self_collision.thickness",
                    };
                    err(LayoutItem::Body, field, &m);
                }
            }
        }
        for (i, p) in self.particles.iter().enumerate() {
            let item = LayoutItem::Particle(i);
            if !finite3(&p.position) {
                err(item, "position", "must be finite");
            }
            if !finite3(&p.velocity) {
                err(item, "velocity", "must be finite");
            }
            if let Anchor::Moving(m) = p.anchor
                && !m.is_finite()
            {
                err(item, "motion", "must be finite");
            }
            let anchored = p.anchor != Anchor::Free;
            if !p.mass.is_finite() || p.mass < 0.0 || (p.mass == 0.0 && !anchored) {
                err(
                    item,
                    "mass",
                    if anchored {
                        "must be finite and non-negative"
                    } else {
                        "must be positive and finite (or pin the particle)"
                    },
                );
            }
        }
        for (k, s) in self.springs.iter().enumerate() {
            let item = LayoutItem::Spring(k);
            if s.a >= n {
                err(item, "a", "index out of range");
            }
            if s.b >= n {
                err(item, "b", "index out of range");
            }
            if s.a == s.b {
                err(item, "b", "a spring cannot join a particle to itself");
            }
            if !(s.stiffness.is_finite() && s.stiffness >= 0.0) {
                err(item, "stiffness", "must be finite and non-negative");
            }
            if !(s.damping.is_finite() && s.damping >= 0.0) {
                err(item, "damping", "must be finite and non-negative");
            }
            let strain_needs = "a strain-law spring needs a positive rest length";
            match s.rest_length {
                Some(l) if !(l.is_finite() && l >= 0.0) => {
                    err(item, "rest_length", "must be finite and non-negative")
                }
                Some(l) if l == 0.0 && s.law == SpringLaw::Strain => {
                    err(item, "rest_length", strain_needs)
                }
                None if s.law == SpringLaw::Strain
                    && s.a < n
                    && s.b < n
                    && s.a != s.b
                    && distance(self.particles[s.a].position, self.particles[s.b].position)
                        == 0.0 =>
                {
                    err(item, "rest_length", strain_needs)
                }
                _ => {}
            }
        }
        for (k, t) in self.tets.iter().enumerate() {
            let item = LayoutItem::Tet(k);
            if t.vertices.iter().any(|&i| i >= n) {
                err(item, "vertices", "index out of range");
                continue;
            }
            match t.material.or(self.material) {
                None => err(
                    item,
                    "material",
                    "no material: give the tet or the body one",
                ),
                Some(m) => {
                    if let (Err(e), Some(_)) = (m.validate(), t.material) {
                        err(item, "material", e);
                    }
                }
            }
            let mut shape = Tets::new();
            if let Err(e) = shape.push(t.vertices, self.rest_shape(t), &NeoHookean::default()) {
                err(item, "", &e.to_string());
            }
        }
        for (k, &(p, f)) in self.forces.iter().enumerate() {
            let item = LayoutItem::Force(k);
            if p >= n {
                err(item, "particle", "index out of range");
            }
            if !finite3(&f) {
                err(item, "force", "must be finite");
            }
        }
        errs
    }

    fn rest_shape(&self, t: &LayoutTet) -> [DVec3; 4] {
        t.rest.unwrap_or_else(|| {
            t.vertices
                .map(|i| DVec3::from_array(self.particles[i].position))
        })
    }

    /// The initial state: the particles' positions and velocities, pinned ones at rest.
    pub fn initial_state(&self) -> ParticleState {
        let mut state = ParticleState::zeros(self.particles.len());
        for (i, p) in self.particles.iter().enumerate() {
            state.x[i] = p.position.to_scalar();
            state.v[i] = match p.anchor {
                Anchor::Pinned => [0.0; 3].to_scalar(),
                _ => p.velocity.to_scalar(),
            };
        }
        state
    }

    /// Validates, then builds the model and its initial state. Numbers enter the model through
    /// [`ToScalar`] (exact from `f32` inputs in either precision).
    pub fn build(&self) -> Result<(ParticleModel, ParticleState), Vec<LayoutError>> {
        let errs = self.validate();
        if !errs.is_empty() {
            return Err(errs);
        }
        let mut model =
            ParticleModel::new(self.particles.iter().map(|p| p.mass.to_scalar()).collect());
        let state = self.initial_state();
        for (i, p) in self.particles.iter().enumerate() {
            match p.anchor {
                Anchor::Free => {}
                Anchor::Pinned => model.pin(i, state.x[i]),
                Anchor::Moving(m) => model.prescribe(i, m),
            }
        }
        for (k, s) in self.springs.iter().enumerate() {
            model.springs.push(
                s.a,
                s.b,
                self.rest_length(k).to_scalar(),
                s.stiffness.to_scalar(),
                s.damping.to_scalar(),
                s.law,
            );
        }
        for t in &self.tets {
            let material = t.material.or(self.material).unwrap_or_default();
            if let Err(e) = model.tets.push(t.vertices, self.rest_shape(t), &material) {
                // Validated above; kept as an error rather than a panic all the same.
                return Err(vec![LayoutError {
                    item: LayoutItem::Body,
                    field: "",
                    message: e.to_string(),
                }]);
            }
        }
        model.gravity = self.gravity.to_scalar();
        model.drag = self.drag.to_scalar();
        model.set_wind(self.wind);
        let faces = self.contact_triangles();
        model.self_contact = self.self_collision.map(|p| {
            let surface = ContactSurface::torn(&faces, &self.torn_from);
            SelfContact::new(surface, p)
        });
        model.contact_faces = faces;
        for &(p, f) in &self.forces {
            model.set_external_force(p, f.to_scalar());
        }
        if let Err(e) = model.validate() {
            return Err(vec![LayoutError {
                item: LayoutItem::Body,
                field: "",
                message: e.to_string(),
            }]);
        }
        Ok((model, state))
    }
}
