//! Spring and damper forces by rows: the forces of [`Springs::accumulate_reference`] to
//! round-off, two to three times faster, and parallel within one body.
//!
//! Each spring `(a, b)` is stored once in the row of its lower index `i = min(a, b)`, with
//! `j = max(a, b)`; rows are in particle order and a row's springs in order of `j`. One pass
//! over the springs computes each force `f = c (x_i − x_j)` — the factor
//! `c = k (L/l − 1) − b (n·v_r)/l` eight springs at a time with AVX where the processor has it
//! (four in the f64 build), so square roots and divisions run in parallel lanes — subtracts it from `f_j`, and sums the row's
//! forces on `i` in a register: the running sum is stored to a per-particle buffer after every
//! spring (no branch at row ends; the last store of a row holds its total), and each row total
//! is added to `f_i` once at the end. The one-loop reference kernel instead adds into `f[i]`
//! for every spring, and consecutive springs of a mesh share `i`, so each iteration waited
//! for the previous one's store.
//!
//! Springs are cut into chunks of about [`CHUNK_SPRINGS`] springs, between rows. A chunk owns
//! the particles from its first row up to the next chunk's first row and writes only those; a
//! `j` beyond them goes to a spill slot, added after all chunks in a fixed order. So every
//! particle's sum has the same order on any number of threads.
//!
//! [`Springs::accumulate_reference`]: crate::core::forces::Springs::accumulate_reference

use super::{SharedMut, for_each_chunk};
use crate::core::forces::PackedSpring;
use crate::math::{Scalar, Vector};
use std::sync::Mutex;

/// Springs per chunk, the unit of parallel work (about 5 µs of work: large enough that
/// handing it to a thread costs little, small enough that two threads stay balanced).
pub const CHUNK_SPRINGS: usize = 4096;

/// Flag bit: the spring continues its row (clear on a row's first spring).
const KEEP: u32 = 1;
/// Flag bit: the spring's `j` side goes to the chunk's next spill slot.
const SPILL: u32 = 2;

#[derive(Clone, Copy, Debug)]
#[repr(C)]
struct Col {
    j: u32,
    rest: Scalar,
    k: Scalar,
    damping: Scalar,
}

#[derive(Clone, Copy, Debug)]
struct Chunk {
    /// Springs `s0..s1`.
    s0: u32,
    s1: u32,
    /// Rows `r0..r1` of `row_i`.
    r0: u32,
    r1: u32,
    /// First spill slot.
    spill: u32,
}

/// Springs laid out by rows (see the module docs).
#[derive(Debug)]
pub struct SpringRows {
    cols: Vec<Col>,
    /// The lower particle of each spring.
    col_i: Vec<u32>,
    /// [`KEEP`] and [`SPILL`] bits of each spring.
    flags: Vec<u32>,
    /// The particle of each row.
    row_i: Vec<u32>,
    chunks: Vec<Chunk>,
    /// The particle each spill slot is subtracted from, in slot order.
    spill_j: Vec<u32>,
    scratch: Mutex<Scratch>,
}

/// Per-evaluation buffers, allocated with the layout.
#[derive(Clone, Debug)]
struct Scratch {
    /// Spill slots' forces.
    spill: Vec<Vector>,
    /// Running row sums, by particle.
    rowsum: Vec<Vector>,
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
        let zero = Col {
            j: 0,
            rest: 0.0,
            k: 0.0,
            damping: 0.0,
        };
        let mut cols = vec![zero; total];
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
        let mut col_i = vec![0u32; total];
        let mut flags = vec![KEEP; total];
        let mut rows = Vec::new(); // (i, start, end)
        for a in 0..bound {
            let (start, end) = (count[a] as usize, count[a + 1] as usize);
            if end > start {
                cols[start..end].sort_by_key(|c| c.j);
                col_i[start..end].fill(a as u32);
                flags[start] = 0;
                rows.push((a as u32, start as u32, end as u32));
            }
        }
        // Chunks of about CHUNK_SPRINGS springs, cut between rows.
        let mut cuts = Vec::new();
        let (mut first, mut acc) = (0usize, 0usize);
        for (r, row) in rows.iter().enumerate() {
            acc += (row.2 - row.1) as usize;
            if acc >= CHUNK_SPRINGS || r + 1 == rows.len() {
                cuts.push((first, r + 1));
                first = r + 1;
                acc = 0;
            }
        }
        // What each chunk owns: particles from its first row's up to the next chunk's first
        // row's (the last chunk: all the rest). Springs reaching beyond spill.
        let mut spill_j = Vec::new();
        let mut chunks = Vec::new();
        for (c, &(r0, r1)) in cuts.iter().enumerate() {
            let own_end = cuts.get(c + 1).map_or(u32::MAX, |&(next, _)| rows[next].0);
            let spill = spill_j.len() as u32;
            let (s0, s1) = (rows[r0].1, rows[r1 - 1].2);
            for s in s0 as usize..s1 as usize {
                if cols[s].j >= own_end {
                    flags[s] |= SPILL;
                    spill_j.push(cols[s].j);
                }
            }
            chunks.push(Chunk {
                s0,
                s1,
                r0: r0 as u32,
                r1: r1 as u32,
                spill,
            });
        }
        let scratch = Mutex::new(Scratch {
            spill: vec![Vector::ZERO; spill_j.len()],
            rowsum: vec![Vector::ZERO; bound],
        });
        Self {
            cols,
            col_i,
            flags,
            row_i: rows.iter().map(|r| r.0).collect(),
            chunks,
            spill_j,
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
        let Scratch { spill, rowsum } = &mut *guard;
        let out = Out {
            f: SharedMut(f.as_mut_ptr()),
            spill: SharedMut(spill.as_mut_ptr()),
            rowsum: SharedMut(rowsum.as_mut_ptr()),
        };
        #[cfg(target_arch = "x86_64")]
        let avx = std::arch::is_x86_feature_detected!("avx");
        let job = |c: usize| {
            let ch = self.chunks[c];
            // SAFETY: indices are below the bound the caller guarantees; chunk `c` writes only
            // `f` and the row sums at the particles it owns and its own spill slots (disjoint
            // across chunks).
            unsafe {
                let mut st = Walk {
                    s: ch.s0 as usize,
                    acc: Vector::ZERO,
                    slot: ch.spill as usize,
                };
                #[cfg(target_arch = "x86_64")]
                if avx {
                    self.walk_avx(&mut st, ch.s1 as usize, x, v, out);
                }
                self.walk(&mut st, ch.s1 as usize, x, v, out);
                for &i in self.row_i.get_unchecked(ch.r0 as usize..ch.r1 as usize) {
                    *out.f.ptr().add(i as usize) += *out.rowsum.ptr().add(i as usize);
                }
            }
        };
        for_each_chunk(self.chunks.len(), job);
        for (s, &j) in guard.spill.iter().zip(&self.spill_j) {
            // SAFETY: as above; all chunks are done.
            unsafe { *f.get_unchecked_mut(j as usize) -= *s };
        }
    }

    /// Applies the force `fi` of spring `s` (see the module docs).
    #[inline(always)]
    unsafe fn apply(&self, st: &mut Walk, s: usize, fi: Vector, out: Out) {
        // SAFETY: `s` is in the chunk being walked; see `accumulate`.
        unsafe {
            let fl = *self.flags.get_unchecked(s);
            st.acc = row_sum(st.acc, fl) + fi;
            *out.rowsum.ptr().add(*self.col_i.get_unchecked(s) as usize) = st.acc;
            if fl & SPILL == 0 {
                *out.f.ptr().add(self.cols.get_unchecked(s).j as usize) -= fi;
            } else {
                *out.spill.ptr().add(st.slot) = fi;
                st.slot += 1;
            }
        }
    }

    /// Springs `st.s..s1` one at a time: `c` as in the module docs, then [`Self::apply`].
    #[inline(always)]
    unsafe fn walk(&self, st: &mut Walk, s1: usize, x: &[Vector], v: Option<&[Vector]>, out: Out) {
        while st.s < s1 {
            let s = st.s;
            // SAFETY: `s < s1 ≤ cols.len()`; particle indices below the bound.
            unsafe {
                let c = self.cols.get_unchecked(s);
                let i = *self.col_i.get_unchecked(s) as usize;
                let j = c.j as usize;
                let d = *x.get_unchecked(i) - *x.get_unchecked(j);
                let l = d.length();
                let coef = match v {
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
                self.apply(st, s, d * coef, out);
            }
            st.s += 1;
        }
    }

    /// Eight springs at a time in AVX: the factors as [`Self::walk`] computes them, lane by
    /// lane with the same operations (no fused multiply-add, so the same bits), then
    /// [`Self::apply`] in order. Stops where fewer than eight springs are left.
    #[cfg(all(target_arch = "x86_64", not(feature = "f64")))]
    #[target_feature(enable = "avx")]
    unsafe fn walk_avx(
        &self,
        st: &mut Walk,
        s1: usize,
        x: &[Vector],
        v: Option<&[Vector]>,
        out: Out,
    ) {
        use super::avx::columns;
        use std::arch::x86_64::*;
        // SAFETY: `st.s + 7 < s1 ≤ cols.len()`; particle indices below the bound the caller
        // guarantees; `Vec3A` is one `__m128`.
        unsafe {
            let zero = _mm256_setzero_ps();
            let one = _mm256_set1_ps(1.0);
            let mut c = [0.0f32; 8];
            while st.s + 8 <= s1 {
                let s = st.s;
                let cols = self.cols.as_ptr().add(s);
                let ii = self.col_i.as_ptr().add(s);
                let diff = |a: &[Vector], q: usize| -> Vector {
                    *a.get_unchecked(*ii.add(q) as usize)
                        - *a.get_unchecked((*cols.add(q)).j as usize)
                };
                let d: [Vector; 8] = std::array::from_fn(|q| diff(x, q));
                let [dx, dy, dz, _] = columns(&d.map(Into::into));
                // (j, rest, k, damping) of eight springs, transposed.
                let [_, rest, k, damping] = columns(&std::array::from_fn(|q| {
                    _mm_loadu_ps(cols.add(q) as *const f32)
                }));
                let dd = _mm256_add_ps(
                    _mm256_add_ps(_mm256_mul_ps(dx, dx), _mm256_mul_ps(dy, dy)),
                    _mm256_mul_ps(dz, dz),
                );
                let l = _mm256_sqrt_ps(dd);
                let pos = _mm256_cmp_ps::<_CMP_GT_OQ>(l, zero);
                let coef = match v {
                    Some(v) => {
                        let w: [__m128; 8] = std::array::from_fn(|q| diff(v, q).into());
                        let [wx, wy, wz, _] = columns(&w);
                        let inv = _mm256_and_ps(_mm256_div_ps(one, l), pos);
                        let along = _mm256_mul_ps(
                            _mm256_add_ps(
                                _mm256_add_ps(_mm256_mul_ps(dx, wx), _mm256_mul_ps(dy, wy)),
                                _mm256_mul_ps(dz, wz),
                            ),
                            inv,
                        );
                        let neg_k = _mm256_xor_ps(k, _mm256_set1_ps(-0.0));
                        let mag = _mm256_sub_ps(
                            _mm256_mul_ps(neg_k, _mm256_sub_ps(l, rest)),
                            _mm256_mul_ps(damping, along),
                        );
                        _mm256_mul_ps(mag, inv)
                    }
                    None => {
                        let r = _mm256_div_ps(rest, l);
                        _mm256_and_ps(_mm256_mul_ps(k, _mm256_sub_ps(r, one)), pos)
                    }
                };
                _mm256_storeu_ps(c.as_mut_ptr(), coef);
                for q in 0..8 {
                    self.apply(st, s + q, d[q] * c[q], out);
                }
                st.s += 8;
            }
        }
    }
}

impl SpringRows {
    /// Four springs at a time in AVX, in f64: the factors as [`Self::walk`] computes them,
    /// lane by lane with the same operations (no fused multiply-add, so the same bits), then
    /// [`Self::apply`] in order. Stops where fewer than four springs are left.
    #[cfg(all(target_arch = "x86_64", feature = "f64"))]
    #[target_feature(enable = "avx")]
    unsafe fn walk_avx(
        &self,
        st: &mut Walk,
        s1: usize,
        x: &[Vector],
        v: Option<&[Vector]>,
        out: Out,
    ) {
        use std::arch::x86_64::*;
        // SAFETY: `st.s + 3 < s1 ≤ cols.len()`; particle indices below the bound the caller
        // guarantees.
        unsafe {
            let zero = _mm256_setzero_pd();
            let one = _mm256_set1_pd(1.0);
            let mut c = [0.0f64; 4];
            while st.s + 4 <= s1 {
                let s = st.s;
                let cols = self.cols.as_ptr().add(s);
                let ii = self.col_i.as_ptr().add(s);
                let diff = |a: &[Vector], q: usize| -> Vector {
                    *a.get_unchecked(*ii.add(q) as usize)
                        - *a.get_unchecked((*cols.add(q)).j as usize)
                };
                let lanes = |a: [f64; 4]| _mm256_set_pd(a[3], a[2], a[1], a[0]);
                let col = |f: fn(&Col) -> f64| lanes(std::array::from_fn(|q| f(&*cols.add(q))));
                let d: [Vector; 4] = std::array::from_fn(|q| diff(x, q));
                let (dx, dy, dz) = (
                    lanes(d.map(|d| d.x)),
                    lanes(d.map(|d| d.y)),
                    lanes(d.map(|d| d.z)),
                );
                let (rest, k) = (col(|c| c.rest), col(|c| c.k));
                let dd = _mm256_add_pd(
                    _mm256_add_pd(_mm256_mul_pd(dx, dx), _mm256_mul_pd(dy, dy)),
                    _mm256_mul_pd(dz, dz),
                );
                let l = _mm256_sqrt_pd(dd);
                let pos = _mm256_cmp_pd::<_CMP_GT_OQ>(l, zero);
                let coef = match v {
                    Some(v) => {
                        let w: [Vector; 4] = std::array::from_fn(|q| diff(v, q));
                        let (wx, wy, wz) = (
                            lanes(w.map(|w| w.x)),
                            lanes(w.map(|w| w.y)),
                            lanes(w.map(|w| w.z)),
                        );
                        let damping = col(|c| c.damping);
                        let inv = _mm256_and_pd(_mm256_div_pd(one, l), pos);
                        let along = _mm256_mul_pd(
                            _mm256_add_pd(
                                _mm256_add_pd(_mm256_mul_pd(dx, wx), _mm256_mul_pd(dy, wy)),
                                _mm256_mul_pd(dz, wz),
                            ),
                            inv,
                        );
                        let neg_k = _mm256_xor_pd(k, _mm256_set1_pd(-0.0));
                        let mag = _mm256_sub_pd(
                            _mm256_mul_pd(neg_k, _mm256_sub_pd(l, rest)),
                            _mm256_mul_pd(damping, along),
                        );
                        _mm256_mul_pd(mag, inv)
                    }
                    None => {
                        let r = _mm256_div_pd(rest, l);
                        _mm256_and_pd(_mm256_mul_pd(k, _mm256_sub_pd(r, one)), pos)
                    }
                };
                _mm256_storeu_pd(c.as_mut_ptr(), coef);
                for q in 0..4 {
                    self.apply(st, s + q, d[q] * c[q], out);
                }
                st.s += 4;
            }
        }
    }
}

/// The running row sum kept (`fl` has [`KEEP`]) or restarted, without a branch (rows end
/// every few springs, too irregularly for a predictor).
#[inline(always)]
fn row_sum(acc: Vector, fl: u32) -> Vector {
    #[cfg(all(target_arch = "x86_64", not(feature = "f64")))]
    {
        use std::arch::x86_64::*;
        let keep = 0u32.wrapping_sub(fl & KEEP) as i32;
        // SAFETY: SSE2 is part of x86_64.
        unsafe {
            Vector::from(_mm_and_ps(
                acc.into(),
                _mm_castsi128_ps(_mm_set1_epi32(keep)),
            ))
        }
    }
    #[cfg(not(all(target_arch = "x86_64", not(feature = "f64"))))]
    {
        if fl & KEEP != 0 { acc } else { Vector::ZERO }
    }
}

/// Where a chunk walk is.
struct Walk {
    /// Next spring.
    s: usize,
    /// The current row's running sum.
    acc: Vector,
    /// Next spill slot.
    slot: usize,
}

/// The buffers a chunk writes.
#[derive(Clone, Copy)]
struct Out {
    f: SharedMut<Vector>,
    spill: SharedMut<Vector>,
    rowsum: SharedMut<Vector>,
}

impl Clone for SpringRows {
    fn clone(&self) -> Self {
        let scratch = self
            .scratch
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone();
        Self {
            cols: self.cols.clone(),
            col_i: self.col_i.clone(),
            flags: self.flags.clone(),
            row_i: self.row_i.clone(),
            chunks: self.chunks.clone(),
            spill_j: self.spill_j.clone(),
            scratch: Mutex::new(scratch),
        }
    }
}
