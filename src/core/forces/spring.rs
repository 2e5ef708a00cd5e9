//! Springs and spring dampers, packed for a tight force kernel.
//!
//! Two laws are offered per spring:
//! - Hooke, `f_i = −k (|d| − L) d/|d|` with `d = x_i − x_j` and `k` in N/m (the cloth
//!   assignment's law);
//! - strain, `f_i = −k (l/L − 1) n` with `k` in N (Young's modulus times area, the PhysBAM
//!   slides' law).
//!
//! The strain law is Hooke's law with stiffness `k/L`, so both are stored as an effective
//! Hooke stiffness and share one kernel (and one Jacobian). A damper along the spring adds
//! `f_i = −b (n·(v_i − v_j)) n`.

use crate::core::kernels::springs::SpringRows;
use crate::math::{Scalar, Vector};
use serde::{Deserialize, Serialize};
use std::sync::OnceLock;

/// How a spring's stiffness is given.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SpringLaw {
    /// `f = −k (l − L) n`, `k` in N/m.
    #[default]
    Hooke,
    /// `f = −k (l/L − 1) n`, `k` in N (the PhysBAM slides' "Young's modulus").
    Strain,
}

impl SpringLaw {
    /// The Hooke stiffness (N/m) equivalent to stiffness `k` under this law at rest length `rest`.
    pub fn effective_stiffness(self, k: Scalar, rest: Scalar) -> Scalar {
        match self {
            SpringLaw::Hooke => k,
            SpringLaw::Strain => k / rest,
        }
    }
}

/// One spring as the kernel reads it: 20 bytes in f32, so a cache line holds three.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C)]
pub struct PackedSpring {
    /// First particle.
    pub i: u32,
    /// Second particle.
    pub j: u32,
    /// Rest length `L`.
    pub rest: Scalar,
    /// Effective Hooke stiffness (N/m).
    pub k: Scalar,
    /// Damping along the spring (N·s/m).
    pub damping: Scalar,
}

/// All springs of a model.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Springs {
    springs: Vec<PackedSpring>,
    damped: usize,
    /// One more than the largest particle index referenced (0 when empty).
    bound: usize,
    /// The fast kernel's layout, built on the first evaluation after a change.
    rows: LazyRows,
    /// Names the springs as they are now: see [`Springs::stamp`].
    stamp: Stamp,
}

/// A number from a process-wide counter, new at every edit of the springs (0 for springs
/// never edited), so that caches built from them (an implicit method's matrix) can tell in
/// one comparison that nothing changed. Compared as always equal: equal springs are equal
/// whatever their history.
#[derive(Clone, Copy, Debug, Default)]
struct Stamp(u64);

impl Stamp {
    fn new() -> Self {
        static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);
        Self(NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed))
    }
}

impl PartialEq for Stamp {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

/// A [`SpringRows`] built when first needed; cloning or editing the springs drops it (it is
/// rebuilt from the springs, never compared).
#[derive(Debug, Default)]
struct LazyRows(OnceLock<SpringRows>);

impl Clone for LazyRows {
    fn clone(&self) -> Self {
        Self::default()
    }
}

impl PartialEq for LazyRows {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

impl Springs {
    /// No springs.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds a spring. Indices must be valid for the model that uses it (the model checks).
    pub fn push(
        &mut self,
        i: usize,
        j: usize,
        rest: Scalar,
        k: Scalar,
        damping: Scalar,
        law: SpringLaw,
    ) {
        self.springs.push(PackedSpring {
            i: i as u32,
            j: j as u32,
            rest,
            k: law.effective_stiffness(k, rest),
            damping,
        });
        if damping != 0.0 {
            self.damped += 1;
        }
        self.bound = self.bound.max(i.max(j) + 1);
        self.rows = LazyRows::default();
        self.stamp = Stamp::new();
    }

    /// Number of springs.
    pub fn len(&self) -> usize {
        self.springs.len()
    }

    /// True when there are none.
    pub fn is_empty(&self) -> bool {
        self.springs.is_empty()
    }

    /// The packed springs.
    pub fn as_slice(&self) -> &[PackedSpring] {
        &self.springs
    }

    /// Mutable access (stiffness changes at run time). Call [`Springs::refresh`] after
    /// changing damping.
    pub fn as_mut_slice(&mut self) -> &mut [PackedSpring] {
        // Indices may change through this slice: the bound is recomputed on the next
        // `accumulate` (or exactly by `refresh`).
        self.bound = usize::MAX;
        self.rows = LazyRows::default();
        self.stamp = Stamp::new();
        &mut self.springs
    }

    /// Recounts damped springs and the index bound after edits.
    pub fn refresh(&mut self) {
        self.damped = self.springs.iter().filter(|s| s.damping != 0.0).count();
        self.bound = self.max_index();
        self.rows = LazyRows::default();
        self.stamp = Stamp::new();
    }

    /// Removes the spring at `index` (order of the others is kept).
    pub fn remove(&mut self, index: usize) -> PackedSpring {
        let s = self.springs.remove(index);
        self.refresh();
        s
    }

    /// A number that changes whenever the springs may have (every `&mut` access gives a new
    /// one, from a process-wide counter; 0 before any edit): springs with the stamp a cache
    /// saw are the springs it was built from.
    pub fn stamp(&self) -> u64 {
        self.stamp.0
    }

    /// True when any spring has a damper.
    pub fn has_damping(&self) -> bool {
        self.damped > 0
    }

    /// Panics unless every spring index is below `n` (done once per call, so the kernels can
    /// index without checks).
    fn check_bound(&self, n: usize) {
        let bound = if self.bound == usize::MAX {
            self.max_index()
        } else {
            self.bound
        };
        assert!(
            bound <= n,
            "a spring refers to particle {} of {n}",
            bound.saturating_sub(1)
        );
    }

    /// The fast kernel's layout (built now if the springs changed since the last call).
    pub fn rows(&self) -> &SpringRows {
        self.rows.0.get_or_init(|| SpringRows::new(&self.springs))
    }

    /// Adds spring (and damper) forces into `f`. `x`, `v` and `f` have one entry per particle.
    /// Uses the row kernel ([`crate::core::kernels::springs`]), in parallel for large bodies;
    /// the result is the same bits on any number of threads, and equals
    /// [`Springs::accumulate_reference`] to round-off.
    ///
    /// # Panics
    /// If the slices differ in length or a spring refers past their end (a model that passed
    /// `validate` never does).
    pub fn accumulate(&self, x: &[Vector], v: &[Vector], f: &mut [Vector]) {
        let n = x.len();
        assert!(
            v.len() == n && f.len() == n,
            "state and force arrays differ in length"
        );
        self.check_bound(n);
        let v = (self.damped > 0).then_some(v);
        // SAFETY: lengths and index bound checked just above.
        unsafe { self.rows().accumulate(x, v, f) }
    }

    /// Sets `f` to the spring (and damper) forces — the bits of zeroing it and
    /// [`Springs::accumulate`] — then runs `finish` on each chunk of particles, on the thread
    /// that summed its forces (see [`crate::core::kernels::Chunk`]).
    ///
    /// # Panics
    /// As [`Springs::accumulate`].
    pub(crate) fn set_then(
        &self,
        x: &mut [Vector],
        v: &mut [Vector],
        f: &mut [Vector],
        finish: crate::core::kernels::Finish<'_>,
    ) {
        let n = x.len();
        assert!(
            v.len() == n && f.len() == n,
            "state and force arrays differ in length"
        );
        self.check_bound(n);
        // SAFETY: lengths and index bound checked just above.
        unsafe { self.rows().set_then(x, v, self.damped > 0, f, finish) }
    }

    /// Adds only the elastic part of the spring forces (dampers left out), for methods that
    /// treat damping implicitly.
    pub fn accumulate_elastic(&self, x: &[Vector], f: &mut [Vector]) {
        assert!(
            f.len() == x.len(),
            "state and force arrays differ in length"
        );
        self.check_bound(x.len());
        // SAFETY: lengths and index bound checked just above.
        unsafe { self.rows().accumulate(x, None, f) }
    }

    /// The reference kernel: one loop over the springs in their order, adding into both ends
    /// (what [`Springs::accumulate`] computes, to round-off). Kept for tests and benchmarks.
    ///
    /// # Panics
    /// As [`Springs::accumulate`].
    pub fn accumulate_reference(&self, x: &[Vector], v: &[Vector], f: &mut [Vector]) {
        let n = x.len();
        assert!(
            v.len() == n && f.len() == n,
            "state and force arrays differ in length"
        );
        self.check_bound(n);
        if self.damped == 0 {
            // SAFETY: lengths and index bound checked just above.
            unsafe { self.elastic_unchecked(x, f) };
            return;
        }
        let (xp, vp, fp) = (x.as_ptr(), v.as_ptr(), f.as_mut_ptr());
        // SAFETY: every index is below the bound, which is ≤ n, the length of all three slices
        // (checked above), and `f` is exclusively borrowed for the whole loop.
        unsafe {
            for s in &self.springs {
                let (i, j) = (s.i as usize, s.j as usize);
                let d = *xp.add(i) - *xp.add(j);
                let l = d.length();
                // Zero-length springs have no direction and exert nothing.
                let nrm = d * if l > 0.0 { 1.0 / l } else { 0.0 };
                let mag = -s.k * (l - s.rest) - s.damping * nrm.dot(*vp.add(i) - *vp.add(j));
                let fi = nrm * mag;
                *fp.add(i) += fi;
                *fp.add(j) -= fi;
            }
        }
    }

    /// The undamped kernel: `f_i += d·k (L/l − 1)`, `f_j −= …`.
    ///
    /// # Safety
    /// `f.len() == x.len()` and [`Springs::check_bound`] passed for that length.
    unsafe fn elastic_unchecked(&self, x: &[Vector], f: &mut [Vector]) {
        let (xp, fp) = (x.as_ptr(), f.as_mut_ptr());
        for s in &self.springs {
            let (i, j) = (s.i as usize, s.j as usize);
            // SAFETY: the caller guarantees i, j < x.len() == f.len().
            unsafe {
                let d = *xp.add(i) - *xp.add(j);
                let l = d.length();
                // −k (l − L) d/l = d·k (L/l − 1); zero-length springs exert nothing.
                let c = if l > 0.0 {
                    s.k * (s.rest / l - 1.0)
                } else {
                    0.0
                };
                let fi = d * c;
                *fp.add(i) += fi;
                *fp.add(j) -= fi;
            }
        }
    }

    /// The elastic energy from the fast kernel's layout, summed in f64 by chunk on the team
    /// (the same bits on any number of threads): [`Springs::energy`] to round-off. The
    /// divergence guard's check; energy reports use [`Springs::energy`].
    ///
    /// # Panics
    /// If a spring refers past the end of `x`.
    pub fn energy_fast(&self, x: &[Vector]) -> f64 {
        if self.springs.is_empty() {
            return 0.0;
        }
        self.check_bound(x.len());
        // SAFETY: index bound checked just above.
        unsafe { self.rows().energy(x) }
    }

    /// Elastic energy `Σ ½ k (l − L)²`.
    pub fn energy(&self, x: &[Vector]) -> Scalar {
        self.springs
            .iter()
            .map(|s| {
                let e = (x[s.i as usize] - x[s.j as usize]).length() - s.rest;
                0.5 * s.k * e * e
            })
            .sum()
    }

    /// Largest index referenced plus one (0 when empty).
    pub fn max_index(&self) -> usize {
        self.springs
            .iter()
            .map(|s| s.i.max(s.j) as usize + 1)
            .max()
            .unwrap_or(0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A matrix takes the springs it matched by their stamp alone, and every edit that can
    /// change their structure is seen: a pair's particles changed through the mutable slice,
    /// a spring pushed or removed; a clone of the springs is the same structure, and a clone
    /// edited apart is not.
    #[test]
    fn a_matrix_sees_every_edit_of_its_springs() {
        use crate::core::solve::SpringMatrix;
        let mut s = Springs::new();
        for i in 0..4 {
            s.push(i, i + 1, 1.0, 10.0, 0.0, SpringLaw::Hooke);
        }
        let a = SpringMatrix::new(5, &s);
        assert!(a.matches(5, &s) && a.matches(5, &s));
        assert!(!a.matches(6, &s), "another particle count");
        let c = s.clone();
        assert_eq!(c.stamp(), s.stamp());
        assert!(a.matches(5, &c));
        // A stiffness change through the slice: a new stamp, the same structure.
        s.as_mut_slice()[0].k = 20.0;
        assert_ne!(s.stamp(), c.stamp());
        assert!(a.matches(5, &s));
        s.as_mut_slice()[2].j = 0;
        assert!(!a.matches(5, &s), "a pair's particle changed");
        s.as_mut_slice()[2].j = 3;
        assert!(a.matches(5, &s));
        s.push(0, 4, 1.0, 10.0, 0.0, SpringLaw::Hooke);
        assert!(!a.matches(5, &s), "a spring pushed");
        s.remove(4);
        assert!(a.matches(5, &s));
        s.remove(1);
        assert!(!a.matches(5, &s), "a spring removed");
        assert!(a.matches(5, &c), "the clone kept its structure");
    }

    #[test]
    fn zero_length_and_self_springs_exert_nothing() {
        let mut s = Springs::new();
        s.push(0, 1, 1.0, 10.0, 1.0, SpringLaw::Hooke);
        s.push(1, 1, 1.0, 10.0, 1.0, SpringLaw::Hooke);
        let x = vec![Vector::ONE; 2];
        let v = vec![Vector::X, -Vector::X];
        let mut f = vec![Vector::ZERO; 2];
        s.accumulate(&x, &v, &mut f);
        assert!(f.iter().all(|f| *f == Vector::ZERO));
    }

    #[test]
    #[should_panic(expected = "refers to particle")]
    fn out_of_range_spring_is_caught_before_any_access() {
        let mut s = Springs::new();
        s.push(0, 5, 1.0, 10.0, 0.0, SpringLaw::Hooke);
        let x = vec![Vector::ZERO; 3];
        s.accumulate(&x, &x.clone(), &mut x.clone());
    }
}
