//! Spring and damper forces by rows: the forces of [`Springs::accumulate_reference`] to
//! round-off, two to three times faster, and parallel within one body.
//!
//! Each spring `(a, b)` is stored once in the row of its lower index `i = min(a, b)`, with
//! `j = max(a, b)`; rows are in particle order and a row's springs in order of `j`. A row's
//! force on `i` is summed in a register and stored once; only the `j` side is scattered. The
//! one-loop kernel instead adds into `f[i]` for every spring, and consecutive springs of a
//! mesh share `i`, so each iteration waited for the previous one's store.
//!
//! Rows are cut into chunks of about [`CHUNK_SPRINGS`] springs. A chunk owns the particles
//! from its first row up to the next chunk's first row and writes only those; a `j` beyond
//! them goes to a spill slot, added after all chunks in a fixed order. So every particle's
//! sum has the same order on any number of threads.
//!
//! [`Springs::accumulate_reference`]: crate::core::forces::Springs::accumulate_reference

use super::{SharedMut, for_each_chunk};
use crate::core::forces::PackedSpring;
use crate::math::{Scalar, Vector};
use std::sync::Mutex;

/// Springs per chunk, the unit of parallel work (about 10 µs of work: large enough that
/// handing it to a thread costs little, small enough that two threads stay balanced).
pub const CHUNK_SPRINGS: usize = 2048;

#[derive(Clone, Copy, Debug)]
struct Row {
    i: u32,
    start: u32,
    /// Springs `start..mid` write `f[j]`; `mid..end` write spill slots from `spill` on.
    mid: u32,
    end: u32,
    spill: u32,
}

#[derive(Clone, Copy, Debug)]
#[repr(C)]
struct Col {
    j: u32,
    rest: Scalar,
    k: Scalar,
    damping: Scalar,
}

/// Springs laid out by rows (see the module docs).
#[derive(Debug)]
pub struct SpringRows {
    rows: Vec<Row>,
    cols: Vec<Col>,
    /// Row ranges of the chunks.
    chunks: Vec<(u32, u32)>,
    /// The particle each spill slot is subtracted from, in slot order.
    spill_j: Vec<u32>,
    /// The lower particle of each spring (for the coefficient pass).
    col_i: Vec<u32>,
    scratch: Mutex<Scratch>,
}

/// Per-evaluation buffers, allocated with the layout.
#[derive(Clone, Debug)]
struct Scratch {
    /// Spill slots' forces.
    spill: Vec<Vector>,
    /// Each spring's force factor `c`, `f_i = c (x_i − x_j)`.
    coef: Vec<Scalar>,
}

impl SpringRows {
    /// Lays out `springs` (springs joining a particle to itself exert nothing and are left
    /// out).
    pub fn new(springs: &[PackedSpring]) -> Self {
        let bound = springs
            .iter()
            .map(|s| s.i.max(s.j) as usize + 1)
            .max()
            .unwrap_or(0);
        // Counting sort by the lower index, then by the upper within a row (stable).
        let mut count = vec![0u32; bound + 1];
        for s in springs.iter().filter(|s| s.i != s.j) {
            count[s.i.min(s.j) as usize + 1] += 1;
        }
        for a in 0..bound {
            count[a + 1] += count[a];
        }
        let total = count[bound] as usize;
        let mut cols = vec![
            Col {
                j: 0,
                rest: 0.0,
                k: 0.0,
                damping: 0.0,
            };
            total
        ];
        let mut next = count.clone();
        for s in springs.iter().filter(|s| s.i != s.j) {
            let a = s.i.min(s.j) as usize;
            cols[next[a] as usize] = Col {
                j: s.i.max(s.j),
                rest: s.rest,
                k: s.k,
                damping: s.damping,
            };
            next[a] += 1;
        }
        let mut rows = Vec::new();
        for a in 0..bound {
            let (start, end) = (count[a] as usize, count[a + 1] as usize);
            if end > start {
                cols[start..end].sort_by_key(|c| c.j);
                rows.push(Row {
                    i: a as u32,
                    start: start as u32,
                    mid: end as u32,
                    end: end as u32,
                    spill: 0,
                });
            }
        }
        // Chunks of about CHUNK_SPRINGS springs, cut between rows.
        let mut chunks = Vec::new();
        let (mut first, mut acc) = (0usize, 0usize);
        for (r, row) in rows.iter().enumerate() {
            acc += (row.end - row.start) as usize;
            if acc >= CHUNK_SPRINGS || r + 1 == rows.len() {
                chunks.push((first as u32, r as u32 + 1));
                first = r + 1;
                acc = 0;
            }
        }
        // What each chunk owns: particles from its first row's up to the next chunk's first
        // row's (the last chunk: all the rest). Springs reaching beyond spill.
        let mut spill_j = Vec::new();
        for (c, &(r0, r1)) in chunks.iter().enumerate() {
            let own_end = chunks
                .get(c + 1)
                .map_or(u32::MAX, |&(next, _)| rows[next as usize].i);
            for row in &mut rows[r0 as usize..r1 as usize] {
                let cs = &cols[row.start as usize..row.end as usize];
                row.mid = row.start + cs.partition_point(|c| c.j < own_end) as u32;
                row.spill = spill_j.len() as u32;
                spill_j.extend(cols[row.mid as usize..row.end as usize].iter().map(|c| c.j));
            }
        }
        let mut col_i = vec![0u32; cols.len()];
        for r in &rows {
            col_i[r.start as usize..r.end as usize].fill(r.i);
        }
        let scratch = Mutex::new(Scratch {
            spill: vec![Vector::ZERO; spill_j.len()],
            coef: vec![0.0; cols.len()],
        });
        Self {
            rows,
            cols,
            chunks,
            spill_j,
            col_i,
            scratch,
        }
    }

    /// Number of chunks (parallel work units).
    pub fn chunks(&self) -> usize {
        self.chunks.len()
    }

    /// Number of spill slots (springs whose upper particle another chunk owns).
    pub fn spills(&self) -> usize {
        self.spill_j.len()
    }

    /// Adds the spring forces into `f`, with the dampers' when `v` is given.
    ///
    /// # Safety
    /// `x`, `v` (when given) and `f` hold every particle any spring refers to.
    pub(crate) unsafe fn accumulate(&self, x: &[Vector], v: Option<&[Vector]>, f: &mut [Vector]) {
        let mut guard = self.scratch.lock().unwrap_or_else(|e| e.into_inner());
        let Scratch { spill, coef } = &mut *guard;
        let spill = SharedMut(spill.as_mut_ptr());
        let coef = SharedMut(coef.as_mut_ptr());
        let fp = SharedMut(f.as_mut_ptr());
        let job = |c: usize| {
            let (r0, r1) = self.chunks[c];
            let rows = &self.rows[r0 as usize..r1 as usize];
            let (s0, s1) = (rows[0].start as usize, rows[rows.len() - 1].end as usize);
            // SAFETY: indices are below the bound the caller guarantees; chunk `c` writes only
            // its own coefficients, `f` at the particles it owns and its own spill slots
            // (disjoint across chunks).
            unsafe {
                self.coefficients(s0, s1, x, v, coef);
                self.scatter(rows, x, coef, fp, spill);
            }
        };
        for_each_chunk(self.chunks.len(), job);
        for (s, &j) in guard.spill.iter().zip(&self.spill_j) {
            // SAFETY: as above; all chunks are done.
            unsafe { *f.get_unchecked_mut(j as usize) -= *s };
        }
    }

    /// For springs `s0..s1`, the factor `c` with `f_i = c (x_i − x_j)`: `k (L/l − 1)`, minus
    /// `b (n·(v_i − v_j))/l` with a damper.
    #[inline(always)]
    unsafe fn coefficients(
        &self,
        s0: usize,
        s1: usize,
        x: &[Vector],
        v: Option<&[Vector]>,
        coef: SharedMut<Scalar>,
    ) {
        // SAFETY: as this function's; SSE is part of x86_64.
        #[cfg(all(target_arch = "x86_64", not(feature = "f64")))]
        let mut s = unsafe { self.coefficients_sse(s0, s1, x, v, coef) };
        #[cfg(not(all(target_arch = "x86_64", not(feature = "f64"))))]
        let mut s = s0;
        let cp = coef.ptr();
        while s < s1 {
            // SAFETY: `s < s1 ≤ cols.len()`; particle indices below the bound.
            unsafe {
                let c = self.cols.get_unchecked(s);
                let i = *self.col_i.get_unchecked(s) as usize;
                let j = c.j as usize;
                let d = *x.get_unchecked(i) - *x.get_unchecked(j);
                let l = d.length();
                *cp.add(s) = match v {
                    Some(v) => {
                        let inv = if l > 0.0 { 1.0 / l } else { 0.0 };
                        let along = d.dot(*v.get_unchecked(i) - *v.get_unchecked(j)) * inv;
                        // f_i = n (−k (l − L) − b n·v_r) with n = d/l.
                        (-c.k * (l - c.rest) - c.damping * along) * inv
                    }
                    // −k (l − L) d/l = d·k (L/l − 1); zero-length springs exert nothing.
                    None if l > 0.0 => c.k * (c.rest / l - 1.0),
                    None => 0.0,
                };
            }
            s += 1;
        }
    }

    /// The coefficient pass four springs at a time in SSE (the same operations as the scalar
    /// loop, lane by lane, so the same bits); returns where the scalar loop takes over.
    #[cfg(all(target_arch = "x86_64", not(feature = "f64")))]
    #[inline(always)]
    unsafe fn coefficients_sse(
        &self,
        s0: usize,
        s1: usize,
        x: &[Vector],
        v: Option<&[Vector]>,
        coef: SharedMut<Scalar>,
    ) -> usize {
        use std::arch::x86_64::*;
        // Rows 0–3 of four lanes (x, y, z, w of four vectors) to three columns.
        #[inline(always)]
        unsafe fn transpose(a: __m128, b: __m128, c: __m128, d: __m128) -> [__m128; 3] {
            // SAFETY: SSE is part of x86_64.
            unsafe {
                let t0 = _mm_unpacklo_ps(a, b); // a.x b.x a.y b.y
                let t1 = _mm_unpacklo_ps(c, d); // c.x d.x c.y d.y
                let t2 = _mm_unpackhi_ps(a, b); // a.z b.z a.w b.w
                let t3 = _mm_unpackhi_ps(c, d); // c.z d.z c.w d.w
                [
                    _mm_movelh_ps(t0, t1),
                    _mm_movehl_ps(t1, t0),
                    _mm_movelh_ps(t2, t3),
                ]
            }
        }
        let cp = coef.ptr();
        let mut s = s0;
        // SAFETY: `s + 3 < s1 ≤ cols.len()`; particle indices below the bound the caller
        // guarantees; `Vec3A` is one `__m128`.
        unsafe {
            let zero = _mm_setzero_ps();
            let one = _mm_set1_ps(1.0);
            while s + 4 <= s1 {
                let cols = self.cols.as_ptr().add(s);
                let ii = self.col_i.as_ptr().add(s);
                let lane = |q: usize, a: &[Vector]| -> __m128 {
                    let (i, j) = (*ii.add(q) as usize, (*cols.add(q)).j as usize);
                    (*a.get_unchecked(i) - *a.get_unchecked(j)).into()
                };
                let [dx, dy, dz] = transpose(lane(0, x), lane(1, x), lane(2, x), lane(3, x));
                // rest, k, damping of four springs: the Col rows transposed (j is lane 0).
                let col = |q: usize| _mm_loadu_ps(cols.add(q) as *const f32);
                let [_, rest, k] = transpose(col(0), col(1), col(2), col(3));
                let dd = _mm_add_ps(
                    _mm_add_ps(_mm_mul_ps(dx, dx), _mm_mul_ps(dy, dy)),
                    _mm_mul_ps(dz, dz),
                );
                let l = _mm_sqrt_ps(dd);
                let pos = _mm_cmpgt_ps(l, zero);
                let out = match v {
                    Some(v) => {
                        let [wx, wy, wz] =
                            transpose(lane(0, v), lane(1, v), lane(2, v), lane(3, v));
                        let inv = _mm_and_ps(_mm_div_ps(one, l), pos);
                        let along = _mm_mul_ps(
                            _mm_add_ps(
                                _mm_add_ps(_mm_mul_ps(dx, wx), _mm_mul_ps(dy, wy)),
                                _mm_mul_ps(dz, wz),
                            ),
                            inv,
                        );
                        let damping = _mm_set_ps(
                            (*cols.add(3)).damping,
                            (*cols.add(2)).damping,
                            (*cols.add(1)).damping,
                            (*cols.add(0)).damping,
                        );
                        let neg_k = _mm_xor_ps(k, _mm_set1_ps(-0.0));
                        let mag = _mm_sub_ps(
                            _mm_mul_ps(neg_k, _mm_sub_ps(l, rest)),
                            _mm_mul_ps(damping, along),
                        );
                        _mm_mul_ps(mag, inv)
                    }
                    None => {
                        let r = _mm_div_ps(rest, l);
                        _mm_and_ps(_mm_mul_ps(k, _mm_sub_ps(r, one)), pos)
                    }
                };
                _mm_storeu_ps(cp.add(s), out);
                s += 4;
            }
        }
        s
    }

    /// Adds `c (x_i − x_j)` into `f_i` (summed over the row in a register) and subtracts it
    /// from `f_j` (or its spill slot).
    #[inline(always)]
    unsafe fn scatter(
        &self,
        rows: &[Row],
        x: &[Vector],
        coef: SharedMut<Scalar>,
        f: SharedMut<Vector>,
        spill: SharedMut<Vector>,
    ) {
        let (xp, cp, fp, sp) = (x.as_ptr(), coef.ptr(), f.ptr(), spill.ptr());
        for r in rows {
            // SAFETY: see `accumulate`.
            unsafe {
                let xi = *xp.add(r.i as usize);
                let mut acc = Vector::ZERO;
                for s in r.start as usize..r.mid as usize {
                    let j = self.cols.get_unchecked(s).j as usize;
                    let fi = (xi - *xp.add(j)) * *cp.add(s);
                    acc += fi;
                    *fp.add(j) -= fi;
                }
                let mut slot = r.spill as usize;
                for s in r.mid as usize..r.end as usize {
                    let j = self.cols.get_unchecked(s).j as usize;
                    let fi = (xi - *xp.add(j)) * *cp.add(s);
                    acc += fi;
                    *sp.add(slot) = fi;
                    slot += 1;
                }
                *fp.add(r.i as usize) += acc;
            }
        }
    }
}

impl Clone for SpringRows {
    fn clone(&self) -> Self {
        let scratch = self
            .scratch
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone();
        Self {
            rows: self.rows.clone(),
            cols: self.cols.clone(),
            chunks: self.chunks.clone(),
            spill_j: self.spill_j.clone(),
            col_i: self.col_i.clone(),
            scratch: Mutex::new(scratch),
        }
    }
}
