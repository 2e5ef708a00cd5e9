//! Constraints on combinations of particles for the filtered solves: a triangle spanning a
//! collider, touching it at a point inside it, is held there, not at its corners.
//!
//! Baraff and Witkin's filter (*Large steps in cloth simulation*, 1998, §5.3) constrains one
//! particle at a time: a projector `Sᵢ` per particle. A triangle touching a thin rod at a
//! point `p = Σ wⱼ xⱼ` (barycentric weights `wⱼ`) with normal `n` is one constraint on three
//! particles, `Σ wⱼ n · vⱼ = c`. Held instead at each corner along `n`, the triangle cannot
//! tip about the contact: a strip hung over a rod off its middle stays, where it should slide
//! off towards its long side. These rows are such constraints, on top of the particles'
//! projectors: `C` the rows (`cₖⱼ = wₖⱼ n`), `C' = C S` the same rows seen in the directions
//! the particles' filters leave free, and the solve kept in the subspace of `S` where
//! `C' x` is prescribed, by the orthogonal projector `P = S − C'ᵀ (C' C'ᵀ)⁻¹ C'` (the null
//! space method of equality-constrained quadratic programs: Nocedal and Wright, *Numerical
//! Optimization*, §16.2; in conjugate gradients, Gould, Hribar and Nocedal, *On the solution
//! of equality constrained quadratic programming problems arising in optimization*, 2001).
//!
//! `G = C' C'ᵀ` couples two rows only through shared particles: the rows are sorted by their
//! first particle and `G` factored in its envelope (a contact line across a cloth gives a
//! narrow band). A row within a quarter (|sin| ≤ 0.25, 14.5°) of the span of those before it
//! is dropped: the triangles round one vertex touching at that vertex are one constraint.

use crate::math::{Matrix3, Scalar, Vector};

/// A row's three particles and coefficients (a coefficient of zero where a corner is not free).
pub type Row = [(u32, Vector); 3];

/// The rows a filtered solve keeps (see the module's docs), factored for the projection.
/// Kept by the integrator: a step allocates nothing once the lists have grown.
#[derive(Clone, Debug, Default)]
pub struct PointRows {
    /// Each row as pushed (`wⱼ n`, before the filters) and its prescribed value of `C x`;
    /// sorted by [`PointRows::factor`].
    whole: Vec<(Row, Scalar)>,
    /// Each row seen through the particles' filters (`C'`), in the same order.
    rows: Vec<Row>,
    /// Each row's first column in the envelope of `G`'s factor.
    first: Vec<u32>,
    /// Where each row's entries start in `l`.
    start: Vec<u32>,
    /// `G = L Lᵀ` by rows of the envelope, in `f64` (a dropped row is all zero but a one on
    /// the diagonal).
    l: Vec<f64>,
    /// Whether each row is kept.
    kept: Vec<bool>,
    /// Scratch: `(particle, row)` pairs, and the projection's coefficients.
    by_particle: Vec<(u32, u32)>,
    y: Vec<f64>,
    /// The preconditioner's metric at each row's corners: the filtered inverse diagonal
    /// blocks `Sⱼ Dⱼ⁻¹ Sⱼ` ([`PointRows::set_metric`]).
    dinv: Vec<[Matrix3; 3]>,
    /// `H = C' D⁻¹ C'ᵀ = L_H L_Hᵀ` in the envelope of `G`'s factor, and the rows it keeps.
    hl: Vec<f64>,
    hkept: Vec<bool>,
    /// The entries of `r` that [`PointRows::precondition_in`] changed, as they were.
    saved: Vec<(u32, Vector)>,
}

impl PointRows {
    /// Quarter: a row whose part outside the span of the rows before it is shorter than this
    /// times its length is dropped.
    const DISTINCT: f64 = 0.25;

    /// Room for `k` rows (and an envelope eight entries a row wide), so that the solves that
    /// follow allocate nothing as contacts come and go; grows only (nothing for `k = 0`).
    pub fn reserve_for(&mut self, k: usize) {
        use crate::core::room;
        room(&mut self.whole, k);
        room(&mut self.rows, k);
        room(&mut self.first, k);
        room(&mut self.start, k);
        room(&mut self.kept, k);
        room(&mut self.hkept, k);
        room(&mut self.y, k);
        room(&mut self.dinv, k);
        room(&mut self.by_particle, 3 * k);
        room(&mut self.saved, 3 * k);
        room(&mut self.l, 8 * k);
        room(&mut self.hl, 8 * k);
    }

    /// Forgets the rows.
    pub fn clear(&mut self) {
        self.rows.clear();
        self.whole.clear();
        self.first.clear();
        self.start.clear();
        self.l.clear();
        self.kept.clear();
    }

    /// How many rows the lists have room for ([`PointRows::reserve_for`]): scratch kept by
    /// row elsewhere takes as much, so that it too grows only when the rows do.
    pub(crate) fn room(&self) -> usize {
        self.rows.capacity()
    }

    /// No rows kept.
    pub fn is_empty(&self) -> bool {
        !self.kept.iter().any(|&k| k)
    }

    /// How many rows are kept.
    pub fn kept(&self) -> usize {
        self.kept.iter().filter(|&&k| k).count()
    }

    /// Adds a row: particles `ids` with coefficients `coef` (`wⱼ n`; zero for a corner that is
    /// not free), `C x = target`. Take [`PointRows::factor`] after the last.
    pub fn push(&mut self, ids: [u32; 3], coef: [Vector; 3], target: Scalar) {
        self.whole
            .push(([0, 1, 2].map(|k| (ids[k], coef[k])), target));
    }

    /// Sorts the rows (by particles, then coefficients, bitwise: the same rows in any order
    /// give the same factor), sees them through the particles' `filters` (sorted by
    /// particle), factors `G = C' C'ᵀ` dropping the dependent rows, and moves `x` onto the
    /// constraints: `x ← x + C'ᵀ G⁻¹ (c − C x)` (`C'ᵀ` lies in the filters' free directions,
    /// so the particles' prescribed parts stay).
    pub fn factor(&mut self, filters: &[(u32, Matrix3)], x: &mut [Vector]) {
        let k = self.whole.len();
        self.rows.clear();
        if k == 0 {
            self.kept.clear();
            return;
        }
        // By a key of the row: its least particle first, then the whole row bitwise.
        let key = |(r, c): &(Row, Scalar)| {
            let least = r[0].0.min(r[1].0).min(r[2].0);
            (
                least,
                r.map(|(i, c)| (i, c.to_array().map(|v| v.to_bits() as u64))),
                c.to_bits() as u64,
            )
        };
        self.whole.sort_unstable_by_key(key);
        // The rows seen through the filters.
        self.rows.extend(
            self.whole
                .iter()
                .map(|(row, _)| row.map(|(i, c)| (i, filter_of(filters, i).map_or(c, |s| s * c)))),
        );
        // Which rows share particles: (particle, row) sorted.
        self.by_particle.clear();
        for (r, row) in self.rows.iter().enumerate() {
            for &(i, c) in row {
                if c != Vector::ZERO {
                    self.by_particle.push((i, r as u32));
                }
            }
        }
        self.by_particle.sort_unstable();
        // Each row's first column: the least row it shares a particle with.
        self.first.clear();
        self.first.extend(0..k as u32);
        let mut a = 0;
        while a < self.by_particle.len() {
            let mut b = a;
            while b < self.by_particle.len() && self.by_particle[b].0 == self.by_particle[a].0 {
                b += 1;
            }
            let least = self.by_particle[a].1; // sorted: the group's least row
            for &(_, r) in &self.by_particle[a..b] {
                let f = &mut self.first[r as usize];
                *f = (*f).min(least);
            }
            a = b;
        }
        self.start.clear();
        let mut len = 0u32;
        for r in 0..k {
            self.start.push(len);
            len += r as u32 - self.first[r] + 1;
        }
        self.l.clear();
        self.l.resize(len as usize, 0.0);
        // G's envelope entries, then the factor in place, row by row. Kept: rows that are
        // not all but taken by the filters, and independent of the kept rows before them,
        // each against its length before the filters.
        let rows = &self.rows;
        fill_envelope(&self.first, &self.start, &mut self.l, |r, c| {
            row_product(&rows[r], &rows[c], |_| Matrix3::IDENTITY)
        });
        self.kept.clear();
        self.kept.resize(k, true);
        factor_envelope_relative(&self.first, &self.start, &mut self.l, &mut self.kept, |r| {
            self.whole[r]
                .0
                .iter()
                .map(|(_, c)| c.length_squared() as f64)
                .sum()
        });
        // x onto the constraints.
        self.y.clear();
        self.y.resize(k, 0.0);
        for r in 0..k {
            if self.kept[r] {
                let (row, target) = &self.whole[r];
                let cx: f64 = row.iter().map(|&(i, c)| c.dot(x[i as usize]) as f64).sum();
                self.y[r] = *target as f64 - cx;
            }
        }
        self.solve_g();
        self.add_rows(x);
    }

    /// Makes the rows homogeneous, `C x = 0`, keeping their factor: the solves that follow
    /// give corrections to a point already on the constraints (Newton's directions, from
    /// velocities [`PointRows::factor`] put there), which must keep `C d = 0`.
    pub fn zero_targets(&mut self) {
        for (_, target) in &mut self.whole {
            *target = 0.0;
        }
    }

    /// `y ← G⁻¹ y` by the factor (dropped rows' entries zero).
    fn solve_g(&mut self) {
        solve_envelope(&self.first, &self.start, &self.l, &self.kept, &mut self.y);
    }

    /// Sets the metric of the constraint preconditioner ([`PointRows::precondition_in`]):
    /// the inverse diagonal blocks `diag` of the system at the rows' corners, filtered
    /// (`S D⁻¹ S`) where `filters` hold a corner, and factors `H = C' D⁻¹ C'ᵀ`.
    pub fn set_metric(&mut self, diag: &[Matrix3], filters: &[(u32, Matrix3)]) {
        self.dinv.clear();
        for row in &self.rows {
            self.dinv.push(row.map(|(i, _)| {
                let inv = super::invert_block(&diag[i as usize]);
                filter_of(filters, i).map_or(inv, |s| s * inv * s)
            }));
        }
        self.hl.clear();
        self.hl.resize(self.l.len(), 0.0);
        self.hkept.clear();
        self.hkept.extend_from_slice(&self.kept);
        let (rows, dinv) = (&self.rows, &self.dinv);
        fill_envelope(&self.first, &self.start, &mut self.hl, |r, c| {
            row_product(&rows[r], &rows[c], |a| dinv[r][a])
        });
        factor_envelope(&self.first, &self.start, &mut self.hl, &mut self.hkept);
    }

    /// The first half of the constraint preconditioner `Π B Πᵀ` (Keller, Gould and Wathen,
    /// *Constraint preconditioning for indefinite linear systems*, 2000, with `B` the
    /// solver's preconditioner and `Π = I − D⁻¹ C'ᵀ H⁻¹ C'` the projector onto the rows'
    /// null space that is orthogonal in `D`'s metric): `r ← Πᵀ r = r − C'ᵀ H⁻¹ C' D⁻¹ r`, the
    /// entries it changes kept for [`PointRows::restore`]. With `B = D⁻¹` (block-Jacobi)
    /// `Π D⁻¹ Πᵀ` is the inverse of `D` on the null space exactly; the orthogonal projection
    /// `P D⁻¹ P` took two to five times the iterations on a cloth resting on a rod.
    pub fn precondition_in(&mut self, r: &mut [Vector]) {
        self.saved.clear();
        if self.rows.is_empty() {
            return;
        }
        for (k, row) in self.rows.iter().enumerate() {
            self.y[k] = (0..3)
                .map(|a| row[a].1.dot(self.dinv[k][a] * r[row[a].0 as usize]) as f64)
                .sum();
        }
        solve_envelope(&self.first, &self.start, &self.hl, &self.hkept, &mut self.y);
        for (row, &mu) in self.rows.iter().zip(&self.y) {
            if mu != 0.0 {
                for &(i, c) in row {
                    if c != Vector::ZERO {
                        self.saved.push((i, r[i as usize]));
                        r[i as usize] -= c * (mu as Scalar);
                    }
                }
            }
        }
    }

    /// Puts back the entries of `r` that [`PointRows::precondition_in`] changed.
    pub fn restore(&mut self, r: &mut [Vector]) {
        for &(i, v) in self.saved.iter().rev() {
            r[i as usize] = v;
        }
        self.saved.clear();
    }

    /// The second half of the constraint preconditioner: `z ← Π z = z − D⁻¹ C'ᵀ H⁻¹ C' z`
    /// (`z` then in the rows' null space).
    pub fn precondition_out(&mut self, z: &mut [Vector]) {
        if self.rows.is_empty() {
            return;
        }
        for (k, row) in self.rows.iter().enumerate() {
            self.y[k] = row.iter().map(|&(i, c)| c.dot(z[i as usize]) as f64).sum();
        }
        solve_envelope(&self.first, &self.start, &self.hl, &self.hkept, &mut self.y);
        for (k, (row, &mu)) in self.rows.iter().zip(&self.y).enumerate() {
            if mu != 0.0 {
                for (a, &(i, c)) in row.iter().enumerate() {
                    z[i as usize] -= self.dinv[k][a] * (c * (mu as Scalar));
                }
            }
        }
    }

    /// `v ← v + C'ᵀ y`.
    fn add_rows(&self, v: &mut [Vector]) {
        for (row, &y) in self.rows.iter().zip(&self.y) {
            if y != 0.0 {
                for &(i, c) in row {
                    v[i as usize] += c * (y as Scalar);
                }
            }
        }
    }

    /// `y ← H⁻¹ y` ([`PointRows::set_metric`]'s `H = C' D⁻¹ C'ᵀ`; dropped rows' entries zero).
    pub(crate) fn solve_h(&self, y: &mut [f64]) {
        solve_envelope(&self.first, &self.start, &self.hl, &self.hkept, y);
    }

    /// How many rows, kept or dropped.
    pub(crate) fn len(&self) -> usize {
        self.rows.len()
    }

    /// Row `r` seen through the filters (`C'`), and whether it is kept.
    pub(crate) fn row(&self, r: usize) -> (&Row, bool) {
        (&self.rows[r], self.kept[r])
    }

    /// What row `r` asks of `x` more: its prescribed value less `C x` (zero for a dropped
    /// row).
    pub(crate) fn shortfall(&self, r: usize, x: &[Vector]) -> f64 {
        if !self.kept[r] {
            return 0.0;
        }
        let (row, target) = &self.whole[r];
        *target as f64
            - row
                .iter()
                .map(|&(i, c)| c.dot(x[i as usize]) as f64)
                .sum::<f64>()
    }

    /// `v ← v − C'ᵀ G⁻¹ C' v`: `v`, already in the particles' filters' free directions, onto
    /// the rows' null space as well.
    pub fn project(&mut self, v: &mut [Vector]) {
        if self.rows.is_empty() {
            return;
        }
        for (r, row) in self.rows.iter().enumerate() {
            self.y[r] = -row
                .iter()
                .map(|&(i, c)| c.dot(v[i as usize]) as f64)
                .sum::<f64>();
        }
        self.solve_g();
        self.add_rows(v);
    }
}

/// Particle `i`'s projector among `filters` (sorted by particle), if it has one.
fn filter_of(filters: &[(u32, Matrix3)], i: u32) -> Option<Matrix3> {
    filters
        .binary_search_by_key(&i, |f| f.0)
        .ok()
        .map(|f| filters[f].1)
}

/// `pᵀ M q` of two rows over the particles they share, `M` block-diagonal: `m(a)` the block
/// at `p`'s corner `a` (`G`'s entries with the identity, `H`'s with `D⁻¹`).
fn row_product(p: &Row, q: &Row, m: impl Fn(usize) -> Matrix3) -> f64 {
    let mut sum = 0.0f64;
    for (a, &(i, c)) in p.iter().enumerate() {
        for &(j, d) in q {
            if i == j {
                sum += c.dot(m(a) * d) as f64;
            }
        }
    }
    sum
}

/// The entries `entry(r, c)` of a symmetric matrix's envelope (`first`, `start` as in
/// [`factor_envelope`]) into `l`, row by row.
fn fill_envelope(first: &[u32], start: &[u32], l: &mut [f64], entry: impl Fn(usize, usize) -> f64) {
    for r in 0..first.len() {
        let (f, s) = (first[r] as usize, start[r] as usize);
        for c in f..=r {
            l[s + c - f] = entry(r, c);
        }
    }
}

/// Cholesky factorization in place of a symmetric matrix stored by rows of its envelope
/// (`first[r]`: row `r`'s first column, `start[r]`: where its entries start in `l`), over the
/// rows marked in `kept`: a row whose pivot is not positive (to round-off of its diagonal)
/// is dropped (all zero but a one on the diagonal, `kept` cleared).
fn factor_envelope(first: &[u32], start: &[u32], l: &mut [f64], kept: &mut [bool]) {
    factor_envelope_relative(first, start, l, kept, |_| 0.0)
}

/// [`factor_envelope`], a row also dropped when its pivot² is at most `DISTINCT²` of
/// `size(r)`: what is left of it outside the span of the kept rows before it is short
/// against its size.
fn factor_envelope_relative(
    first: &[u32],
    start: &[u32],
    l: &mut [f64],
    kept: &mut [bool],
    size: impl Fn(usize) -> f64,
) {
    const ROUND_OFF: f64 = 1e-12;
    for r in 0..kept.len() {
        let (f, s) = (first[r] as usize, start[r] as usize);
        let diag = l[s + r - f];
        for c in f..r {
            let v = if kept[c] {
                let (fc, sc) = (first[c] as usize, start[c] as usize);
                let mut sum = l[s + c - f];
                for m in f.max(fc)..c {
                    sum -= l[s + m - f] * l[sc + m - fc];
                }
                sum / l[sc + c - fc]
            } else {
                0.0
            };
            l[s + c - f] = v;
        }
        let mut d = diag;
        for m in f..r {
            d -= l[s + m - f] * l[s + m - f];
        }
        let bound = (PointRows::DISTINCT * PointRows::DISTINCT * size(r)).max(ROUND_OFF * diag);
        if kept[r] && diag > 0.0 && d > bound {
            l[s + r - f] = d.sqrt();
        } else {
            kept[r] = false;
            for m in f..r {
                l[s + m - f] = 0.0;
            }
            l[s + r - f] = 1.0;
        }
    }
}

/// `y ← M⁻¹ y` by an envelope factor of [`factor_envelope`] (dropped rows' entries zero).
fn solve_envelope(first: &[u32], start: &[u32], l: &[f64], kept: &[bool], y: &mut [f64]) {
    let k = kept.len();
    for r in 0..k {
        if !kept[r] {
            y[r] = 0.0;
            continue;
        }
        let (f, s) = (first[r] as usize, start[r] as usize);
        let mut sum = y[r];
        for m in f..r {
            sum -= l[s + m - f] * y[m];
        }
        y[r] = sum / l[s + r - f];
    }
    for r in (0..k).rev() {
        if !kept[r] {
            continue;
        }
        let (f, s) = (first[r] as usize, start[r] as usize);
        let u = y[r] / l[s + r - f];
        y[r] = u;
        for m in f..r {
            y[m] -= l[s + m - f] * u;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lcg(r: &mut u64) -> f64 {
        *r = r
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (*r >> 11) as f64 / (1u64 << 53) as f64
    }

    fn unit(r: &mut u64) -> Vector {
        let v = Vector::new(
            (lcg(r) - 0.5) as Scalar,
            (lcg(r) - 0.5) as Scalar,
            (lcg(r) - 0.5) as Scalar,
        );
        v / v.length()
    }

    /// The orthogonal projector onto the complement of the span of `dirs` (vectors of `3n`),
    /// by modified Gram–Schmidt in `f64`, dropping directions within `tol` of the span before.
    fn dense_complement(dirs: &[Vec<f64>], n: usize, tol: f64) -> Vec<Vec<f64>> {
        let mut basis: Vec<Vec<f64>> = vec![];
        for d in dirs {
            let mut u = d.clone();
            for b in &basis {
                let c: f64 = u.iter().zip(b).map(|(x, y)| x * y).sum();
                u.iter_mut().zip(b).for_each(|(x, y)| *x -= c * y);
            }
            let l = u.iter().map(|x| x * x).sum::<f64>().sqrt();
            let whole = d.iter().map(|x| x * x).sum::<f64>().sqrt();
            if l > tol * whole {
                basis.push(u.iter().map(|x| x / l).collect());
            }
        }
        (0..3 * n)
            .map(|r| {
                (0..3 * n)
                    .map(|c| {
                        let id = if r == c { 1.0 } else { 0.0 };
                        id - basis.iter().map(|b| b[r] * b[c]).sum::<f64>()
                    })
                    .collect()
            })
            .collect()
    }

    /// Random rows on twelve particles, some of whose corners are held along a direction by
    /// their own filters, with a copy of one row and a row that is another's with a scaled
    /// normal (both dropped): the projection equals the orthogonal projector onto the
    /// complement of the filters' held directions and the independent rows, computed apart by
    /// Gram–Schmidt in `f64`; `factor` puts `x` on the rows' prescribed values and leaves the
    /// filters' held parts where they were.
    #[test]
    fn the_projection_is_the_orthogonal_projector_onto_the_constraints_null_space() {
        let n = 12;
        let mut r = 7u64;
        // Particles 1 and 9 held along one direction each, 6 along two.
        let mut held: Vec<(u32, Vec<Vector>)> = vec![
            (1, vec![unit(&mut r)]),
            (6, vec![unit(&mut r), unit(&mut r)]),
            (9, vec![unit(&mut r)]),
        ];
        // Orthonormal within each particle.
        for (_, d) in &mut held {
            if d.len() == 2 {
                d[1] = (d[1] - d[0] * d[0].dot(d[1])).normalize();
            }
        }
        let filters: Vec<(u32, Matrix3)> = held
            .iter()
            .map(|(i, d)| {
                let outer = |e: Vector| Matrix3::from_cols(e * e.x, e * e.y, e * e.z);
                (*i, d.iter().fold(Matrix3::IDENTITY, |m, &e| m - outer(e)))
            })
            .collect();
        let mut rows = PointRows::default();
        let mut pushed = vec![];
        // A chain of rows sharing corners, two through held particles.
        let chain = [
            [0, 2, 3],
            [3, 4, 5],
            [5, 7, 8],
            [8, 9, 10],
            [1, 10, 11],
            [6, 11, 2],
        ];
        for (k, ids) in chain.into_iter().enumerate() {
            let w = [lcg(&mut r), lcg(&mut r), lcg(&mut r)];
            let sum: f64 = w.iter().sum();
            let nrm = unit(&mut r);
            let coef = w.map(|w| nrm * (w / sum) as Scalar);
            let target = (k as Scalar - 3.0) * 0.25;
            rows.push(ids, coef, target);
            pushed.push((ids, coef, target));
        }
        // Dependent: the first row again, and the second with its normal doubled.
        let (ids, coef, target) = pushed[0];
        rows.push(ids, coef, target);
        let (ids, coef, target) = pushed[1];
        rows.push(ids, coef.map(|c| c * 2.0), target * 2.0);
        let mut x: Vec<Vector> = (0..n).map(|_| unit(&mut r) * 0.3).collect();
        let before = x.clone();
        rows.factor(&filters, &mut x);
        assert_eq!(rows.kept(), pushed.len(), "the two dependent rows dropped");

        // The rows hold.
        for (ids, coef, target) in &pushed {
            let cx: Scalar = (0..3).map(|k| coef[k].dot(x[ids[k] as usize])).sum();
            assert!((cx - target).abs() <= 1e-5, "{cx} against {target}");
        }
        // The held parts stay.
        for (i, d) in &held {
            for e in d {
                let (a, b) = (e.dot(x[*i as usize]), e.dot(before[*i as usize]));
                assert!((a - b).abs() <= 1e-5, "particle {i}: {a} against {b}");
            }
        }
        // The projector, against the one computed apart.
        let flat = |c: &[(u32, Vector)]| {
            let mut v = vec![0.0; 3 * n];
            for &(i, d) in c {
                for k in 0..3 {
                    v[3 * i as usize + k] += d[k] as f64;
                }
            }
            v
        };
        let mut dirs: Vec<Vec<f64>> = held
            .iter()
            .flat_map(|(i, d)| d.iter().map(|&e| flat(&[(*i, e)])))
            .collect();
        dirs.extend(pushed.iter().map(|(ids, coef, _)| {
            flat(&[(ids[0], coef[0]), (ids[1], coef[1]), (ids[2], coef[2])])
        }));
        let p = dense_complement(&dirs, n, 1e-6);
        for _ in 0..5 {
            let v: Vec<Vector> = (0..n).map(|_| unit(&mut r)).collect();
            let mut pv = v.clone();
            crate::core::solve::filter_rows(&filters, &mut pv);
            rows.project(&mut pv);
            let vf: Vec<f64> = v.iter().flat_map(|v| (0..3).map(|k| v[k] as f64)).collect();
            for q in 0..3 * n {
                let want: f64 = (0..3 * n).map(|c| p[q][c] * vf[c]).sum();
                let got = pv[q / 3][q % 3] as f64;
                // f32 coefficients: a few roundings of entries of order one.
                let tol = if cfg!(feature = "f64") { 1e-12 } else { 1e-5 };
                assert!((got - want).abs() <= tol, "entry {q}: {got} against {want}");
            }
        }
    }
}
