//! Contact between the surfaces of bodies that are stepped apart (each with its own model,
//! state and step, as the plugin steps them, in parallel): after every body has advanced a
//! frame, the bodies whose swept boxes overlap are gathered into groups, and each group's
//! surfaces go through one [`SelfContact`] pass over the frame as a single surface — the
//! same proximity impulses, continuous detection and rigid impact zones (Bridson, Fedkiw
//! and Anderson 2002) as a body's contact with itself, so pairs across bodies and the pairs
//! within each body that the cross-body impulses disturb are resolved together, and the
//! frame's end is free of intersections between the group's surfaces as well as within them
//! (tried: pairs between bodies only — the cross-body pushes then left 20 intersecting pairs
//! within a body in the two-cloth test, and it was no cheaper, the broad phase being the
//! cost). A frame is long against the thickness, so the frame's straight paths are taken in
//! increments and a pass runs after an increment only when one is due, as a body's own passes
//! run between its steps ([`SelfContact::advance`]: when some particle has travelled, against
//! the surfaces' mean motion, half of what its nearest candidate pair may close), and at the
//! frame's end. Three 32² cloths as three bodies took 27 passes a group pass with a pass
//! after every increment, 16 so, at 200 against 277 ms a group pass (0.92 a frame;
//! docs/BENCHMARKS.md). Pairs that came close mid-frame were caught only by the continuous
//! detection; up to [`SETTLE_PASSES`] passes from where the last one ended (no motion but
//! their own pushes, checked again by the continuous detection) push pairs that ended nearer
//! than the thickness apart.
//!
//! The group's thickness is its members' smallest (every member's own bound on the thickness
//! against its shortest edge then holds for the whole group); its friction the members' mean
//! (avian's default way of combining two friction coefficients).

use crate::core::self_contact::{
    ContactSurface, PASS_TRAVEL, SelfContact, SelfContactParams, SelfContactReport,
};
use crate::math::{Scalar, Vector};

/// Passes from where the frame's pass ended (no motion but their own pushes) at most, each
/// pushing pairs that ended closer than the thickness apart; they stop at the first that
/// pushes nothing.
pub const SETTLE_PASSES: u32 = 3;

/// Increments a frame's straight paths are cut into at most (each an even share of what is
/// left of them, as many as keep the parts' approach per increment under [`PASS_TRAVEL`]
/// thicknesses); a pass runs after those at which one is due, and after the last.
pub const MAX_SUBPASSES: u32 = 32;

/// One body's part in a group pass.
#[derive(Debug)]
pub struct GroupMember<'a> {
    /// The body's contact surface (its particle indices).
    pub surface: &'a ContactSurface,
    /// The body's contact settings.
    pub params: SelfContactParams,
    /// Positions at the frame's start (free of intersections with the other members).
    pub x0: &'a [Vector],
    /// Positions at the frame's end (changed by the pass).
    pub x: &'a mut [Vector],
    /// Velocities at the frame's end (changed by the pass).
    pub v: &'a mut [Vector],
    /// Inverse masses (zero: pinned or moved on a path; the pass leaves those alone).
    pub inv_mass: &'a [Scalar],
    /// Particles resting on a collider (empty: none), counted heavier as in a body's own pass.
    pub support: &'a [bool],
}

/// The contact handler of one group of bodies, kept from frame to frame while its members
/// stay the same (its broad phase and buffers are reused; a frame allocates nothing once
/// they have grown).
#[derive(Clone, Debug, Default)]
pub struct ContactGroup {
    key: Vec<u64>,
    contact: SelfContact,
    x0: Vec<Vector>,
    x: Vec<Vector>,
    v: Vec<Vector>,
    w: Vec<Scalar>,
    target: Vec<Vector>,
    end: Vec<Vector>,
    /// The increments' velocities along the straight paths, and the members' particles
    /// resting on colliders.
    path: Vec<Vector>,
    support: Vec<bool>,
}

impl ContactGroup {
    /// The members' identities (as given to the last [`ContactGroup::resolve`]).
    pub fn key(&self) -> &[u64] {
        &self.key
    }

    /// Totals of every pass since the group was made.
    pub fn total(&self) -> &SelfContactReport {
        &self.contact.total
    }

    /// The group's settings: the smallest thickness and the mean friction of its members.
    pub fn combined(members: &[GroupMember]) -> SelfContactParams {
        let thickness = members
            .iter()
            .map(|m| m.params.thickness)
            .fold(f64::INFINITY, f64::min);
        let friction =
            members.iter().map(|m| m.params.friction).sum::<f64>() / members.len().max(1) as f64;
        SelfContactParams {
            thickness,
            friction,
        }
    }

    /// Makes the members' motions over a frame of length `h` (from `x0` to `x`) free of
    /// intersections between and within their surfaces. `key` names the members (e.g. their
    /// entities and rebuild counts): a different key rebuilds the joined surface.
    pub fn resolve(
        &mut self,
        key: &[u64],
        h: Scalar,
        members: &mut [GroupMember],
    ) -> SelfContactReport {
        let params = Self::combined(members);
        if self.key != key || self.contact.params != params {
            let mut offset = 0u32;
            let parts: Vec<(&ContactSurface, u32)> = members
                .iter()
                .map(|m| {
                    let p = (m.surface, offset);
                    offset += m.x.len() as u32;
                    p
                })
                .collect();
            self.contact = SelfContact::new(ContactSurface::concat(&parts), params);
            self.key = key.to_vec();
        }
        for buf in [&mut self.x0, &mut self.x, &mut self.v] {
            buf.clear();
        }
        self.w.clear();
        for m in members.iter() {
            self.x0.extend_from_slice(m.x0);
            self.x.extend_from_slice(m.x);
            self.v.extend_from_slice(m.v);
            self.w.extend_from_slice(m.inv_mass);
        }
        self.support.clear();
        self.support.resize(self.x.len(), false);
        let mut off = 0;
        for m in members.iter() {
            for (i, &s) in m.support.iter().enumerate() {
                self.support[off + i] = s;
            }
            off += m.x.len();
        }
        // The frame's straight paths in increments, so that a pass sees the surfaces' parts
        // come at most half a thickness closer (as a body's own passes do): a frame's motion
        // is long against the thickness, and one pass over it would have to pair everything
        // within that motion (measured: 850,000 candidate pairs and 11 s for one pass over
        // three 32² cloths sliding off a sphere).
        let verts = &self.contact.surface.vertices;
        let nv = verts.len().max(1) as Scalar;
        let mean = verts
            .iter()
            .map(|&i| self.x[i as usize] - self.x0[i as usize])
            .sum::<Vector>()
            / nv;
        let spread = verts
            .iter()
            .map(|&i| (self.x[i as usize] - self.x0[i as usize] - mean).length())
            .fold(0.0, Scalar::max) as f64;
        let subs = ((2.0 * spread / (PASS_TRAVEL * params.thickness)).ceil() as usize)
            .clamp(1, MAX_SUBPASSES as usize);
        self.target.clear();
        self.target.extend_from_slice(&self.x);
        self.x.copy_from_slice(&self.x0);
        self.contact.begin_frame(&self.x);
        let mut rep = SelfContactReport::default();
        let hs = h / subs as Scalar;
        for j in 0..subs {
            // An even share of what is left to the target (which takes every correction a
            // pass made), and the velocity that covers it in the increment.
            let left = (subs - j) as Scalar;
            self.path.clear();
            for (x, t) in self.x.iter_mut().zip(&self.target) {
                let d = (*t - *x) / left;
                *x += d;
                self.path.push(d / hs);
            }
            // A pass when the parts may have come half a thickness closer since the last
            // (each particle's travel against what its nearest candidate pair may close: see
            // [`SelfContact::advance`]), and at the frame's end.
            let due = self.contact.advance(hs, &self.x, &self.path);
            if !due && j + 1 < subs {
                continue;
            }
            self.end.clear();
            self.end.extend_from_slice(&self.x);
            self.lend_support();
            self.contact.pass(&mut self.x, &mut self.v, &self.w);
            let r = self.contact.last;
            rep.add(&r);
            if r.failed {
                break;
            }
            for ((t, x), e) in self.target.iter_mut().zip(&self.x).zip(&self.end) {
                *t += *x - *e;
            }
        }
        // Pairs that came close mid-pass were caught only by the continuous detection (a
        // tenth of the thickness apart): passes from where the last ended (no motion but
        // their own pushes, checked again by the continuous detection) restore the
        // thickness between them.
        for _ in 0..SETTLE_PASSES {
            if rep.failed {
                break;
            }
            self.lend_support();
            self.x0.copy_from_slice(&self.x);
            let again = self
                .contact
                .resolve(hs, &self.x0, &mut self.x, &mut self.v, &self.w);
            rep.add(&again);
            if again.separated == 0 {
                break;
            }
        }
        self.contact.support_mut(0);
        let mut off = 0;
        for m in members.iter_mut() {
            let n = m.x.len();
            m.x.copy_from_slice(&self.x[off..off + n]);
            m.v.copy_from_slice(&self.v[off..off + n]);
            off += n;
        }
        rep
    }

    /// Marks the members' particles resting on colliders for the next pass (a pass clears
    /// its marks).
    fn lend_support(&mut self) {
        self.contact
            .support_mut(self.support.len())
            .copy_from_slice(&self.support);
    }
}

/// Groups of bodies whose boxes overlap (directly or through others), from each body's box
/// over the frame: index lists of two or more, each ascending, in the order of their first
/// member. `boxes[k]` is `None` for a body that takes no part.
pub fn overlapping_groups(boxes: &[Option<(Vector, Vector)>]) -> Vec<Vec<usize>> {
    let n = boxes.len();
    let mut parent: Vec<usize> = (0..n).collect();
    fn find(p: &mut [usize], mut i: usize) -> usize {
        while p[i] != i {
            p[i] = p[p[i]];
            i = p[i];
        }
        i
    }
    for (a, box_a) in boxes.iter().enumerate() {
        let Some((lo_a, hi_a)) = *box_a else {
            continue;
        };
        for (b, box_b) in boxes.iter().enumerate().skip(a + 1) {
            let Some((lo_b, hi_b)) = *box_b else {
                continue;
            };
            if lo_a.cmple(hi_b).all() && lo_b.cmple(hi_a).all() {
                let (ra, rb) = (find(&mut parent, a), find(&mut parent, b));
                if ra != rb {
                    parent[ra.max(rb)] = ra.min(rb);
                }
            }
        }
    }
    let mut groups: Vec<Vec<usize>> = vec![];
    let mut slot: Vec<Option<usize>> = vec![None; n];
    for (i, b) in boxes.iter().enumerate() {
        if b.is_none() {
            continue;
        }
        let r = find(&mut parent, i);
        match slot[r] {
            Some(g) => groups[g].push(i),
            None => {
                slot[r] = Some(groups.len());
                groups.push(vec![i]);
            }
        }
    }
    groups.retain(|g| g.len() > 1);
    groups
}

/// A surface's box over a frame (its particles at the start and at the end), grown by
/// `margin` on every side; `None` for a surface without particles.
pub fn swept_box(
    surface: &ContactSurface,
    x0: &[Vector],
    x: &[Vector],
    margin: Scalar,
) -> Option<(Vector, Vector)> {
    let mut it = surface.vertices.iter().map(|&i| i as usize);
    let first = it.next()?;
    let (mut lo, mut hi) = (x0[first].min(x[first]), x0[first].max(x[first]));
    for i in it {
        lo = lo.min(x0[i]).min(x[i]);
        hi = hi.max(x0[i]).max(x[i]);
    }
    let m = Vector::splat(margin);
    Some((lo - m, hi + m))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn b(lo: f32, hi: f32) -> Option<(Vector, Vector)> {
        Some((Vector::splat(lo as Scalar), Vector::splat(hi as Scalar)))
    }

    #[test]
    fn groups_join_through_chains_of_overlaps() {
        // 0–1 overlap, 1–3 overlap, 2 is apart, 4 takes no part, 5–6 overlap.
        let boxes = [
            b(0.0, 1.0),
            b(0.9, 2.0),
            b(10.0, 11.0),
            b(1.5, 3.0),
            None,
            b(20.0, 21.0),
            b(21.0, 22.0),
        ];
        assert_eq!(overlapping_groups(&boxes), vec![vec![0, 1, 3], vec![5, 6]]);
        assert!(overlapping_groups(&[b(0.0, 1.0), b(2.0, 3.0)]).is_empty());
    }
}
