//! Springs in bands: the springs of a structured mesh, evaluated on contiguous columns.
//!
//! A cloth built as a grid numbers its particles row by row, so its springs fall into a few
//! *bands*: every spring of one kind joins a particle `i` to `i + o` for one offset `o` (a
//! 64² grid: 1 and 64 structural, 63 and 65 shear, 2 and 128 bending). A band keeps its
//! springs by their lower particle, one slot per `i` over its range (a missing spring is a
//! slot of zero stiffness and damping: it exerts exactly nothing), so that
//!
//! 1. **Forces.** The positions (and velocities) of a chunk of particles and of the `omax`
//!    after it are copied into columns (`x`, `y`, `z` apart); then, band after band, the
//!    springs of the chunk's particles read `i` and `i + o` from the columns at consecutive
//!    places, and every spring's force on `i` goes to the band's columns of forces, in the
//!    order of `i`: straight loops the compiler turns into AVX lanes, with no index, no
//!    shuffle and no transpose per spring. (The row kernel spends about 34 shuffles on every
//!    eight springs turning `Vec3A` differences into columns and forces back into rows; those
//!    bound it.)
//!    (The copy into columns is a 4×4 transpose per half register, eight `Vec3A`s at a time,
//!    in the f32 build with AVX.)
//! 2. **Gather.** Particle `p` adds, band after band, the force of the band's spring at `p`
//!    and subtracts that of its spring at `p − o`: two contiguous reads per band, a register
//!    of particles at a time with their sums in registers (with AVX: eight in f32, four in
//!    f64), turned back into rows once per register.
//!
//! The force columns and each chunk's scratch are laid out in whole cache lines (64 bytes):
//! a band's entry of a particle that starts a line-sized group starts a line, so chunks of
//! whole lines, run on different threads, write no line in common (when they did, each
//! thread's stores there waited for the other's copy to be invalidated, at every step).
//!
//! Every lane does the scalar operations of [`SpringRows`](super::springs::SpringRows)'s
//! loop (`c = k (L/l − 1) − b (n·v_r)/l`, no fused multiply-add), element by element, so the
//! loops give the same bits whether the compiler made lanes of them or not, on any machine;
//! each particle's sum has one order (its bands in order of offset), fixed by the layout, so
//! the same bits on any number of threads. Springs that are not in a band (an offset with
//! few springs, or a second spring between the same two particles) stay in the row kernel,
//! which adds its sums before the bands'.

use crate::core::forces::PackedSpring;
use crate::math::{Scalar, Vector};
use std::collections::BTreeMap;

/// Particles the register gather takes at a time: one AVX register of the build's scalars.
#[cfg(target_arch = "x86_64")]
const LANES: usize = 32 / std::mem::size_of::<Scalar>();

/// Scalars in a cache line (64 bytes): the force columns and the chunks' scratch are laid
/// out in whole lines (see [`Bands::split`] and [`BandBuf`](super::springs)).
pub(crate) const LINE: usize = 64 / std::mem::size_of::<Scalar>();

/// Fewest springs with one offset that make a band.
pub const MIN_BAND: usize = 64;

/// Largest offset a band may have (particles a chunk copies past its end).
pub const MAX_OFFSET: u32 = 1024;

/// One band: its offset, its range of lower particles `a..e`, where its parameters start
/// in [`Bands`]'s arrays, and where its force column starts: `e − a + 2 o` entries, the
/// force of its spring at `i` at `g + o + i − a`, zeros around, so that particle `p` (of
/// `a..e + o`, the particles the band reaches) reads its two at `g + o + p − a` (as the lower
/// particle) and `g + p − a` (as the upper).
#[derive(Clone, Copy, Debug)]
struct Band {
    o: usize,
    a: usize,
    e: usize,
    at: usize,
    g: usize,
}

/// The bands of a set of springs (see the module docs).
#[derive(Clone, Debug)]
pub(crate) struct Bands {
    band: Vec<Band>,
    rest: Vec<Scalar>,
    k: Vec<Scalar>,
    damping: Vec<Scalar>,
    /// Springs the bands hold (their slots less the empty ones).
    springs: usize,
    /// The largest offset.
    omax: usize,
    /// One more than the largest particle index.
    bound: usize,
    /// Length of one coordinate's force columns (all bands; see [`Band`]).
    columns: usize,
    /// Particles per chunk (the row kernel's).
    chunk: usize,
    /// The particles every band reaches (each band reaches `a..e + o`): where the gather
    /// may read every band's two columns without a check (the f32 build's AVX gather).
    #[cfg_attr(any(feature = "f64", not(target_arch = "x86_64")), allow(dead_code))]
    common: std::ops::Range<usize>,
}

impl Bands {
    /// One past the last particle the force pass of the chunk ending before `p1` reads: its
    /// particles and the largest offset after them.
    pub(crate) fn reads_end(&self, p1: usize) -> usize {
        (p1 + self.omax).min(self.bound)
    }

    /// Splits `springs` into bands and the rest (springs joining a particle to itself go to
    /// the rest, which leaves them out). `None` when no offset has [`MIN_BAND`] springs over
    /// a range they fill at least half of.
    pub(crate) fn split(
        springs: &[PackedSpring],
        bound: usize,
        chunk: usize,
    ) -> (Option<Self>, Vec<PackedSpring>) {
        // Count, lowest and highest lower particle of each offset.
        let mut stats: BTreeMap<u32, (usize, u32, u32)> = BTreeMap::new();
        for s in springs.iter().filter(|s| s.i != s.j) {
            let (lo, o) = (s.i.min(s.j), s.i.abs_diff(s.j));
            if o > MAX_OFFSET {
                continue;
            }
            let e = stats.entry(o).or_insert((0, lo, lo));
            e.0 += 1;
            e.1 = e.1.min(lo);
            e.2 = e.2.max(lo);
        }
        let mut band = Vec::new();
        let (mut at, mut g) = (0, 0);
        for (&o, &(count, a, last)) in &stats {
            let (o, a, e) = (o as usize, a as usize, last as usize + 1);
            if count < MIN_BAND || 2 * count < e - a {
                continue;
            }
            // Particle `p`'s entry, `g + o + p − a`, at the start of a cache line when `p` is
            // a multiple of `LINE` (a chunk's first particle, for chunks of whole lines):
            // the lines two threads write meet nowhere.
            g += (a % LINE + LINE - (g + o) % LINE) % LINE;
            band.push(Band { o, a, e, at, g });
            at += e - a;
            g += e - a + 2 * o;
        }
        let g = g.next_multiple_of(LINE);
        if band.is_empty() {
            return (None, springs.to_vec());
        }
        let n = at;
        let (mut rest, mut k, mut damping) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
        let mut taken = vec![false; n];
        let which: BTreeMap<usize, usize> =
            band.iter().enumerate().map(|(b, d)| (d.o, b)).collect();
        let mut others = Vec::new();
        for s in springs {
            let (lo, o) = (s.i.min(s.j) as usize, s.i.abs_diff(s.j) as usize);
            let slot = (s.i != s.j)
                .then(|| which.get(&o))
                .flatten()
                .map(|&b| band[b].at + lo - band[b].a)
                .filter(|&q| !taken[q]);
            match slot {
                Some(q) => {
                    taken[q] = true;
                    (rest[q], k[q], damping[q]) = (s.rest, s.k, s.damping);
                }
                None => others.push(*s),
            }
        }
        let omax = band.iter().map(|b| b.o).max().unwrap_or(0);
        let common = band.iter().map(|b| b.a).max().unwrap_or(0)
            ..band.iter().map(|b| b.e + b.o).min().unwrap_or(0);
        let bands = Self {
            band,
            rest,
            k,
            damping,
            springs: springs.len() - others.len(),
            omax,
            bound,
            columns: g,
            chunk,
            common,
        };
        (Some(bands), others)
    }

    /// Springs in bands.
    pub(crate) fn len(&self) -> usize {
        self.springs
    }

    /// Length of the force columns (all three coordinates) the passes share.
    pub(crate) fn buffer_len(&self) -> usize {
        3 * self.columns
    }

    /// Length of each chunk's scratch: the columns of positions and velocities of its
    /// particles and the `omax` after them, and its sums.
    pub(crate) fn scratch_len(&self) -> usize {
        (6 * (self.chunk + self.omax) + 3 * self.chunk).next_multiple_of(LINE)
    }

    /// The force pass of the chunk of particles `p0..p1`: every band spring whose lower
    /// particle is in the chunk, its force on that particle into the force columns `g`
    /// (`buffer_len` long), with the dampers' when `v` is given.
    ///
    /// # Safety
    /// `x` and `v` hold the bound's particles; `g` is the shared force columns, of which this
    /// writes only the chunk's springs' entries; `scratch` is the chunk's own
    /// (`scratch_len` long).
    pub(crate) unsafe fn forces(
        &self,
        p0: usize,
        p1: usize,
        (x, v, from): (&[Vector], Option<&[Vector]>, usize),
        g: *mut Scalar,
        scratch: *mut Scalar,
    ) {
        let end = self.reads_end(p1);
        let m = end - p0;
        let stride = self.chunk + self.omax;
        // SAFETY: the scratch is the chunk's own and holds six columns of `stride ≥ m`.
        let cols = |q: usize| unsafe { std::slice::from_raw_parts_mut(scratch.add(q * stride), m) };
        let (xs, ys, zs) = (cols(0), cols(1), cols(2));
        to_columns(&x[p0 - from..end - from], xs, ys, zs);
        let (vx, vy, vz) = (cols(3), cols(4), cols(5));
        if let Some(v) = v {
            to_columns(&v[p0 - from..end - from], vx, vy, vz);
        }
        for b in &self.band {
            let (lo0, lo1) = (b.a.max(p0), b.e.min(p1));
            if lo0 >= lo1 {
                continue;
            }
            let (len, o) = (lo1 - lo0, b.o);
            let (i, j) = (lo0 - p0, lo0 - p0 + o);
            let q = b.at + lo0 - b.a;
            let at = b.g + o + lo0 - b.a;
            // SAFETY: the three force columns of this band's springs `lo0..lo1`, written by
            // this chunk alone.
            let out = |c: usize| unsafe {
                std::slice::from_raw_parts_mut(g.add(c * self.columns + at), len)
            };
            let p = Params {
                rest: &self.rest[q..q + len],
                k: &self.k[q..q + len],
                damping: &self.damping[q..q + len],
            };
            let d = Ends::at([&*xs, &*ys, &*zs], i, j, len);
            let (fx, fy, fz) = (out(0), out(1), out(2));
            if v.is_some() {
                let w = Ends::at([&*vx, &*vy, &*vz], i, j, len);
                band_forces::<true>(&d, &w, &p, fx, fy, fz);
            } else {
                band_forces::<false>(&d, &d, &p, fx, fy, fz);
            }
        }
    }

    /// Adds the bands' forces on the chunk's particles `p0..p1` into `out[p − p0]`, after
    /// the row kernel's sums (or sets them to the sums, with `set`).
    ///
    /// # Safety
    /// `g` points to the force pass's columns, the entries of the springs reaching
    /// `p0..p1` written and not being written (other entries may be: they are read through
    /// the pointer, never as a slice of the whole); `scratch` is the chunk's own; `out`
    /// points to at least `p1 − p0` vectors; `p1 ≤` the bound.
    pub(crate) unsafe fn gather(
        &self,
        p0: usize,
        p1: usize,
        g: *const Scalar,
        scratch: *mut Scalar,
        (out, set): (*mut Vector, bool),
    ) {
        // Where every band reaches every particle, a register's width of particles at a time
        // in registers (with AVX: eight in f32, four in f64); elsewhere (and otherwise)
        // through the sum columns. Both add the same terms in the same order.
        #[allow(unused_mut)]
        let (mut f0, mut f1) = (p0, p0);
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx") {
            f0 = self.common.start.clamp(p0, p1);
            f1 = f0 + (self.common.end.clamp(f0, p1) - f0) / LANES * LANES;
            // SAFETY: AVX is present; `p0 ≤ f0 ≤ f1 ≤ p1`, every band reaching `f0..f1`.
            unsafe { self.gather_avx(f0, f1, g, (out.add(f0 - p0), set)) };
        }
        // SAFETY: as the caller guarantees, on the two parts left.
        unsafe {
            self.gather_columns(p0, f0, g, scratch, (out, set));
            self.gather_columns(f1, p1, g, scratch, (out.add(f1 - p0), set));
        }
    }

    /// [`Self::gather`] of particles `p0..p1`, every band reaching all of them, [`LANES`] at
    /// a time: each band's two columns read and their difference added, band after band, in
    /// registers; the sums turned to rows and added to `out`.
    ///
    /// # Safety
    /// `p1 − p0` is a multiple of [`LANES`]; `out` holds `p1 − p0` vectors; every band
    /// reaches `p0..p1` (`a ≤ p0`, `p1 ≤ e + o`).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    unsafe fn gather_avx(
        &self,
        p0: usize,
        p1: usize,
        g: *const Scalar,
        (out, set): (*mut Vector, bool),
    ) {
        #[cfg(feature = "f64")]
        use std::arch::x86_64::{
            _mm256_add_pd as add, _mm256_loadu_pd as load, _mm256_setzero_pd as zero,
            _mm256_sub_pd as sub,
        };
        #[cfg(not(feature = "f64"))]
        use std::arch::x86_64::{
            _mm256_add_ps as add, _mm256_loadu_ps as load, _mm256_setzero_ps as zero,
            _mm256_sub_ps as sub,
        };
        let c = self.columns;
        for t in (p0..p1).step_by(LANES) {
            let mut s = [zero(); 3];
            for b in &self.band {
                // SAFETY: `a ≤ t` and `t + LANES ≤ e + o`: both reads within the band's column.
                unsafe {
                    let minus = g.add(b.g + t - b.a);
                    let plus = minus.add(b.o);
                    for (k, s) in s.iter_mut().enumerate() {
                        *s = add(*s, sub(load(plus.add(k * c)), load(minus.add(k * c))));
                    }
                }
            }
            // SAFETY: particles `t − p0..t − p0 + LANES` are in `out`.
            unsafe { add_rows(s, out.add(t - p0), set) };
        }
    }

    /// [`Self::gather`] of particles `p0..p1` through the chunk's sum columns.
    ///
    /// # Safety
    /// As for [`Self::gather`], `out` pointing at particle `p0`'s force.
    unsafe fn gather_columns(
        &self,
        p0: usize,
        p1: usize,
        g: *const Scalar,
        scratch: *mut Scalar,
        (out, set): (*mut Vector, bool),
    ) {
        if p0 >= p1 {
            return;
        }
        let m = p1 - p0;
        let base = 6 * (self.chunk + self.omax);
        // SAFETY: the chunk's three sum columns, `chunk ≥ m` long each.
        let sums = |q: usize| unsafe {
            std::slice::from_raw_parts_mut(scratch.add(base + q * self.chunk), m)
        };
        let (sx, sy, sz) = (sums(0), sums(1), sums(2));
        sx.fill(0.0);
        sy.fill(0.0);
        sz.fill(0.0);
        for b in &self.band {
            // The particles the band reaches: `a..e + o`.
            let (q0, q1) = (b.a.max(p0), (b.e + b.o).min(p1));
            if q0 >= q1 {
                continue;
            }
            let (from, len) = (b.g + q0 - b.a, q1 - q0);
            for (c, s) in [&mut *sx, &mut *sy, &mut *sz].into_iter().enumerate() {
                // SAFETY: the band's entries of particles `q0 − o..q1`, within its column.
                let col = unsafe {
                    std::slice::from_raw_parts(g.add(c * self.columns + from), len + b.o)
                };
                add_band(&mut s[q0 - p0..q1 - p0], &col[b.o..], &col[..len]);
            }
        }
        for (q, ((x, y), z)) in sx.iter().zip(&*sy).zip(&*sz).enumerate() {
            // SAFETY: `q < m ≤` what `out` holds.
            unsafe {
                let o = out.add(q);
                *o = if set { Vector::ZERO } else { *o } + Vector::new(*x, *y, *z);
            }
        }
    }

    /// The bands' elastic energy over the springs whose lower particle is in `p0..p1`, each
    /// spring's in the build's precision, summed in `f64`.
    pub(crate) fn energy(&self, p0: usize, p1: usize, x: &[Vector]) -> f64 {
        let mut sum = 0.0f64;
        for b in &self.band {
            for i in b.a.max(p0)..b.e.min(p1) {
                let q = b.at + i - b.a;
                if self.k[q] == 0.0 {
                    continue;
                }
                let e = (x[i] - x[i + b.o]).length() - self.rest[q];
                sum += (0.5 * self.k[q] * e * e) as f64;
            }
        }
        sum
    }
}

/// Adds three columns of sums (x, y, z of [`LANES`] particles) to those particles' forces
/// at `out`, as rows: eight `Vec3A`s in the f32 build.
///
/// # Safety
/// AVX is present; `out` holds [`LANES`] vectors.
#[cfg(all(target_arch = "x86_64", not(feature = "f64")))]
#[target_feature(enable = "avx")]
unsafe fn add_rows(s: [std::arch::x86_64::__m256; 3], out: *mut Vector, set: bool) {
    use std::arch::x86_64::*;
    for (q, row) in super::avx::rows(s[0], s[1], s[2]).into_iter().enumerate() {
        // SAFETY: `q < LANES`, within `out`; a `Vec3A` is an aligned `__m128`.
        unsafe {
            let o = out.add(q) as *mut __m128;
            *o = _mm_add_ps(if set { _mm_setzero_ps() } else { *o }, row);
        }
    }
}

/// [`add_rows`] in the f64 build: four packed `DVec3`s, three registers' worth.
///
/// # Safety
/// As the f32 build's.
#[cfg(all(target_arch = "x86_64", feature = "f64"))]
#[target_feature(enable = "avx")]
unsafe fn add_rows(s: [std::arch::x86_64::__m256d; 3], out: *mut Vector, set: bool) {
    use std::arch::x86_64::*;
    let o = out as *mut f64;
    for (k, row) in super::avx::rows3(s[0], s[1], s[2]).into_iter().enumerate() {
        // SAFETY: `DVec3` is three packed `f64`s; the twelve of four particles are in `out`.
        unsafe {
            let o = o.add(4 * k);
            let was = if set {
                _mm256_setzero_pd()
            } else {
                _mm256_loadu_pd(o)
            };
            _mm256_storeu_pd(o, _mm256_add_pd(was, row));
        }
    }
}

/// Copies vectors into three columns (exact: the same bits however it is done); with AVX,
/// eight `Vec3A`s at a time in the f32 build (a 4×4 transpose per half of a register), four
/// `DVec3`s (three registers' worth) in the f64 build.
pub(crate) fn to_columns(a: &[Vector], xs: &mut [Scalar], ys: &mut [Scalar], zs: &mut [Scalar]) {
    #[allow(unused_mut)]
    let mut done = 0;
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx") {
        // SAFETY: AVX is present.
        done = unsafe { to_columns_avx(a, xs, ys, zs) };
    }
    for (q, p) in a.iter().enumerate().skip(done) {
        (xs[q], ys[q], zs[q]) = (p.x, p.y, p.z);
    }
}

/// [`to_columns`]'s whole groups of eight; returns how many it copied.
#[cfg(all(target_arch = "x86_64", not(feature = "f64")))]
#[target_feature(enable = "avx")]
fn to_columns_avx(a: &[Vector], xs: &mut [Scalar], ys: &mut [Scalar], zs: &mut [Scalar]) -> usize {
    use std::arch::x86_64::*;
    let n = a.len() / 8 * 8;
    let (xs, ys, zs) = (&mut xs[..n], &mut ys[..n], &mut zs[..n]);
    for q in (0..n).step_by(8) {
        let rows: [__m128; 8] = std::array::from_fn(|k| a[q + k].into());
        let [x, y, z, _] = super::avx::columns(&rows);
        // SAFETY: `q + 8 ≤ n`, the columns' length.
        unsafe {
            _mm256_storeu_ps(xs.as_mut_ptr().add(q), x);
            _mm256_storeu_ps(ys.as_mut_ptr().add(q), y);
            _mm256_storeu_ps(zs.as_mut_ptr().add(q), z);
        }
    }
    n
}

/// [`to_columns`]'s whole groups of four `DVec3`s (twelve packed `f64`s: `x₀y₀z₀x₁`,
/// `y₁z₁x₂y₂`, `z₂x₃y₃z₃`); returns how many it copied.
#[cfg(all(target_arch = "x86_64", feature = "f64"))]
#[target_feature(enable = "avx")]
fn to_columns_avx(a: &[Vector], xs: &mut [Scalar], ys: &mut [Scalar], zs: &mut [Scalar]) -> usize {
    use std::arch::x86_64::*;
    let n = a.len() / 4 * 4;
    let (xs, ys, zs) = (&mut xs[..n], &mut ys[..n], &mut zs[..n]);
    let flat = a.as_ptr() as *const f64;
    for q in (0..n).step_by(4) {
        // SAFETY: `DVec3` is three packed `f64`s; particles `q..q + 4` are in `a`, and their
        // columns' entries in `xs`, `ys`, `zs`.
        unsafe {
            let r0 = _mm256_loadu_pd(flat.add(3 * q));
            let r1 = _mm256_loadu_pd(flat.add(3 * q + 4));
            let r2 = _mm256_loadu_pd(flat.add(3 * q + 8));
            let [x, y, z] = super::avx::columns3(r0, r1, r2);
            _mm256_storeu_pd(xs.as_mut_ptr().add(q), x);
            _mm256_storeu_pd(ys.as_mut_ptr().add(q), y);
            _mm256_storeu_pd(zs.as_mut_ptr().add(q), z);
        }
    }
    n
}

/// A band's springs' two ends, in columns.
struct Ends<'a> {
    xi: &'a [Scalar],
    xj: &'a [Scalar],
    yi: &'a [Scalar],
    yj: &'a [Scalar],
    zi: &'a [Scalar],
    zj: &'a [Scalar],
}

impl<'a> Ends<'a> {
    /// The `len` springs whose ends are at `i..` and `j..` of the columns `[x, y, z]`.
    fn at(c: [&'a [Scalar]; 3], i: usize, j: usize, len: usize) -> Self {
        Self {
            xi: &c[0][i..i + len],
            xj: &c[0][j..j + len],
            yi: &c[1][i..i + len],
            yj: &c[1][j..j + len],
            zi: &c[2][i..i + len],
            zj: &c[2][j..j + len],
        }
    }
}

/// A band's springs' parameters.
struct Params<'a> {
    rest: &'a [Scalar],
    k: &'a [Scalar],
    damping: &'a [Scalar],
}

/// The forces of a run of a band's springs: [`forces_in_lanes`] compiled for AVX where the
/// processor has it (the same operations, element by element: the same bits).
fn band_forces<const DAMPED: bool>(
    d: &Ends,
    w: &Ends,
    p: &Params,
    fx: &mut [Scalar],
    fy: &mut [Scalar],
    fz: &mut [Scalar],
) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx") {
        // SAFETY: AVX is present.
        unsafe { forces_avx::<DAMPED>(d, w, p, fx, fy, fz) };
        return;
    }
    forces_in_lanes::<DAMPED>(d, w, p, fx, fy, fz);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
fn forces_avx<const DAMPED: bool>(
    d: &Ends,
    w: &Ends,
    p: &Params,
    fx: &mut [Scalar],
    fy: &mut [Scalar],
    fz: &mut [Scalar],
) {
    forces_in_lanes::<DAMPED>(d, w, p, fx, fy, fz);
}

/// Each spring `t`: `d = x_i − x_j`, `l = |d|`, the factor `c` of the row kernel's scalar loop
/// (the same operations in the same order), and the force `d c` into `(fx, fy, fz)[t]`.
#[inline(always)]
fn forces_in_lanes<const DAMPED: bool>(
    d: &Ends,
    w: &Ends,
    p: &Params,
    fx: &mut [Scalar],
    fy: &mut [Scalar],
    fz: &mut [Scalar],
) {
    let n = fx.len();
    let (fy, fz) = (&mut fy[..n], &mut fz[..n]);
    let (xi, xj, yi, yj, zi, zj) = (
        &d.xi[..n],
        &d.xj[..n],
        &d.yi[..n],
        &d.yj[..n],
        &d.zi[..n],
        &d.zj[..n],
    );
    let (rest, k, damping) = (&p.rest[..n], &p.k[..n], &p.damping[..n]);
    let (wxi, wxj, wyi, wyj, wzi, wzj) = if DAMPED {
        (
            &w.xi[..n],
            &w.xj[..n],
            &w.yi[..n],
            &w.yj[..n],
            &w.zi[..n],
            &w.zj[..n],
        )
    } else {
        (xi, xj, yi, yj, zi, zj)
    };
    for t in 0..n {
        let (dx, dy, dz) = (xi[t] - xj[t], yi[t] - yj[t], zi[t] - zj[t]);
        let l = (dx * dx + dy * dy + dz * dz).sqrt();
        let c = if DAMPED {
            let inv = if l > 0.0 { 1.0 / l } else { 0.0 };
            let (ux, uy, uz) = (wxi[t] - wxj[t], wyi[t] - wyj[t], wzi[t] - wzj[t]);
            let along = (dx * ux + dy * uy + dz * uz) * inv;
            (-k[t] * (l - rest[t]) - damping[t] * along) * inv
        } else if l > 0.0 {
            k[t] * (rest[t] / l - 1.0)
        } else {
            0.0
        };
        fx[t] = dx * c;
        fy[t] = dy * c;
        fz[t] = dz * c;
    }
}

/// `s[t] += plus[t] − minus[t]`, compiled for AVX where the processor has it.
fn add_band(s: &mut [Scalar], plus: &[Scalar], minus: &[Scalar]) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx") {
        // SAFETY: AVX is present.
        unsafe { add_avx(s, plus, minus) };
        return;
    }
    add_in_lanes(s, plus, minus);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
fn add_avx(s: &mut [Scalar], plus: &[Scalar], minus: &[Scalar]) {
    add_in_lanes(s, plus, minus);
}

#[inline(always)]
fn add_in_lanes(s: &mut [Scalar], plus: &[Scalar], minus: &[Scalar]) {
    let n = s.len();
    let (plus, minus) = (&plus[..n], &minus[..n]);
    for t in 0..n {
        s[t] += plus[t] - minus[t];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each band's entry of a particle that starts a line-sized group starts a cache line of
    /// the columns (so chunks of whole lines write no line in common), and each coordinate's
    /// columns and each chunk's scratch are whole lines: bands of every offset a 37-wide
    /// grid has, starting at odd particles.
    #[test]
    fn columns_are_laid_out_in_whole_lines() {
        let w = 37u32;
        let mut springs = Vec::new();
        for p in 3..w * w {
            for o in [1, 2, 3, w - 1, w, w + 1, 2 * w] {
                if p + o < w * w {
                    springs.push(PackedSpring {
                        i: p,
                        j: p + o,
                        rest: 0.1,
                        k: 10.0,
                        damping: 0.0,
                    });
                }
            }
        }
        let n = (w * w) as usize;
        let bands = Bands::split(&springs, n, 4 * LINE)
            .0
            .expect("a grid has bands");
        assert_eq!(bands.band.len(), 7);
        for b in &bands.band {
            assert_eq!((b.g + b.o + LINE * b.a - b.a) % LINE, 0, "offset {}", b.o);
        }
        assert_eq!(bands.columns % LINE, 0);
        assert_eq!(bands.scratch_len() % LINE, 0);
    }

    /// The loops compiled for AVX give the bits of the same loops compiled without it: runs
    /// of 1 to 37 springs (whole lanes and remainders), lengths from zero to large, damped and
    /// not, and the band sums.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn lanes_give_the_bits_of_the_plain_loop() {
        if !std::arch::is_x86_feature_detected!("avx") {
            return;
        }
        let mut seed = 7u64;
        let mut next = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0) as Scalar
        };
        for n in 1..=37 {
            let mut col =
                |scale: Scalar| -> Vec<Scalar> { (0..n).map(|_| scale * next()).collect() };
            let (xi, xj, yi, yj, zi, mut zj) =
                (col(1.0), col(1.0), col(1e-3), col(1e-3), col(1e3), col(1e3));
            // A zero-length spring.
            zj[0] = zi[0];
            let (xs, ys) = (xj.clone(), yj.clone());
            let d = Ends {
                xi: &xi,
                xj: if n > 1 { &xj } else { &xi },
                yi: &yi,
                yj: if n > 1 { &yj } else { &yi },
                zi: &zi,
                zj: &zj,
            };
            let (ui, uj, vi, vj, wi, wj) =
                (col(1.0), col(1.0), col(1.0), col(1.0), col(1.0), col(1.0));
            let w = Ends {
                xi: &ui,
                xj: &uj,
                yi: &vi,
                yj: &vj,
                zi: &wi,
                zj: &wj,
            };
            let (rest, k, damping) = (col(1.0), col(1e3), col(1.0));
            let p = Params {
                rest: &rest,
                k: &k,
                damping: &damping,
            };
            let bits = |a: &[Scalar]| a.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            let run = |avx: bool, damped: bool| {
                let (mut fx, mut fy, mut fz) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
                match (avx, damped) {
                    // SAFETY: AVX is present (checked above).
                    (true, true) => unsafe {
                        forces_avx::<true>(&d, &w, &p, &mut fx, &mut fy, &mut fz)
                    },
                    (true, false) => unsafe {
                        forces_avx::<false>(&d, &d, &p, &mut fx, &mut fy, &mut fz)
                    },
                    (false, true) => forces_in_lanes::<true>(&d, &w, &p, &mut fx, &mut fy, &mut fz),
                    (false, false) => {
                        forces_in_lanes::<false>(&d, &d, &p, &mut fx, &mut fy, &mut fz)
                    }
                }
                [bits(&fx), bits(&fy), bits(&fz)]
            };
            for damped in [false, true] {
                assert_eq!(
                    run(true, damped),
                    run(false, damped),
                    "{n} springs, damped {damped}"
                );
            }
            let (mut a, mut b) = (xs.clone(), xs.clone());
            // SAFETY: AVX is present.
            unsafe { add_avx(&mut a, &ys, &zj) };
            add_in_lanes(&mut b, &ys, &zj);
            assert_eq!(bits(&a), bits(&b), "{n} sums");
        }
    }

    /// The copy into columns, whole groups in AVX and the rest one by one, holds every
    /// coordinate of every vector, for every length up to 37.
    #[test]
    fn columns_hold_the_vectors() {
        for n in 0..=37usize {
            let a: Vec<Vector> = (0..n)
                .map(|p| {
                    let p = p as Scalar;
                    Vector::new(p + 0.5, -p - 0.25, p * 1e3 + 0.125)
                })
                .collect();
            let (mut xs, mut ys, mut zs) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
            to_columns(&a, &mut xs, &mut ys, &mut zs);
            for (q, p) in a.iter().enumerate() {
                assert_eq!([xs[q], ys[q], zs[q]], [p.x, p.y, p.z], "{q} of {n}");
            }
        }
    }

    /// The gather in registers gives the bits of the gather through the sum columns: a 20×20
    /// grid's six bands with arbitrary force columns, summed both ways.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn gather_in_registers_gives_the_bits_of_the_columns() {
        if !std::arch::is_x86_feature_detected!("avx") {
            return;
        }
        let w = 20u32;
        let mut springs = Vec::new();
        for p in 0..w * w {
            for o in [1, 2, w - 1, w, w + 1, 2 * w] {
                if p + o < w * w {
                    springs.push(PackedSpring {
                        i: p + o,
                        j: p,
                        rest: 0.1,
                        k: 10.0,
                        damping: 0.0,
                    });
                }
            }
        }
        let n = (w * w) as usize;
        let (bands, rest) = Bands::split(&springs, n, n);
        let bands = bands.expect("a grid has bands");
        assert!(rest.is_empty() && bands.band.len() == 6);
        let mut seed = 3u64;
        let g: Vec<Scalar> = (0..bands.buffer_len())
            .map(|_| {
                seed = seed
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                ((seed >> 40) as Scalar / (1u64 << 24) as Scalar - 0.5) * 100.0
            })
            .collect();
        let mut scratch = vec![0.0; bands.scratch_len()];
        let start: Vec<Vector> = (0..n)
            .map(|p| {
                let p = p as Scalar;
                Vector::new(p * 0.25, -p * 0.5, p + 0.125)
            })
            .collect();
        let bits = |a: &[Vector]| {
            a.iter()
                .map(|v| v.to_array().map(Scalar::to_bits))
                .collect::<Vec<_>>()
        };
        // Added to the forces there, and setting them (the bits of adding to zeroed forces).
        let zeroed = vec![Vector::ZERO; n];
        for (set, want) in [(false, &start), (true, &zeroed)] {
            let (mut fast, mut plain, mut set_plain) = (start.clone(), start.clone(), want.clone());
            let s = scratch.as_mut_ptr();
            // SAFETY: the scratch and outputs are the chunk's (all `n` particles).
            unsafe {
                bands.gather(0, n, g.as_ptr(), s, (fast.as_mut_ptr(), set));
                bands.gather_columns(0, n, g.as_ptr(), s, (plain.as_mut_ptr(), set));
                bands.gather_columns(0, n, g.as_ptr(), s, (set_plain.as_mut_ptr(), false));
            }
            assert_eq!(bits(&fast), bits(&plain), "set {set}");
            assert_eq!(bits(&fast), bits(&set_plain), "set {set}");
        }
    }
}
