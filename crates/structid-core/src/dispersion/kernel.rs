//! Positive-definite kernels k(z₁, z₂) on ℝᵖ and the map estimate they induce.

use std::fmt;
use std::ops::Range;
use std::sync::Arc;

use faer::MatMut;
use faer::reborrow::{Reborrow, ReborrowMut};
use structid_lti::Signal;

use crate::error::{Result, positive_finite};
use crate::model::interpolant::Interpolant;

/// A symmetric positive-definite kernel k: ℝᵖ × ℝᵖ → ℝ.
///
/// Implement [`Kernel::eval`] and wrap the kernel in [`crate::KernelDispersion`] to use it as a
/// dispersion (the RKHS norm D(z, w) = wᵀK⁻¹w, never formed with K⁻¹). A Laplacian kernel takes
/// a few lines:
///
/// ```
/// use structid_core::Kernel;
///
/// #[derive(Debug)]
/// struct Laplacian { scale: f64 }
///
/// impl Kernel for Laplacian {
///     fn eval(&self, a: &[f64], b: &[f64]) -> f64 {
///         let d: f64 = a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f64>().sqrt();
///         (-d / self.scale).exp()
///     }
///     fn describe(&self) -> String { format!("laplacian(scale={})", self.scale) }
/// }
///
/// let k = Laplacian { scale: 0.5 };
/// assert_eq!(k.eval(&[1.0], &[1.0]), 1.0);
/// ```
pub trait Kernel: Send + Sync + fmt::Debug {
    /// k(a, b) for two points of equal dimension p.
    fn eval(&self, a: &[f64], b: &[f64]) -> f64;

    /// A short human-readable description, e.g. `gaussian(sigma=0.4)`.
    fn describe(&self) -> String;

    /// Named numeric parameters, for reports.
    fn parameters(&self) -> Vec<(String, f64)> {
        Vec::new()
    }

    /// The kernel's width (length scale), if it has one: what `--sigma auto` tunes.
    fn width(&self) -> Option<f64> {
        None
    }

    /// The kernel as plain data ([`crate::stored::StoredKernel`]), so that a kernel
    /// expansion on it can be stored in an [`crate::estimate::Estimate`]; `None` (the
    /// default) for a kernel without a stored form.
    fn stored_kernel(&self) -> Option<crate::stored::StoredKernel> {
        None
    }

    /// The same kernel with another width; `None` (the default) when it has none.
    fn with_width(&self, width: f64) -> Option<Result<Self>>
    where
        Self: Sized,
    {
        let _ = width;
        None
    }

    /// Writes the whole Gram matrix (`z.len()` × `z.len()`) into `out`. Override it to exploit
    /// symmetry; the default fills every column.
    fn fill_gram(&self, z: &Signal, out: MatMut<'_, f64>) {
        self.fill_gram_columns(z, 0..z.len(), out);
    }

    /// Writes the columns `cols` of the Gram matrix K_ij = k(z_i, z_j) into `out`
    /// (`z.len()` × `cols.len()`, any layout). Override it when a faster route exists; the
    /// default evaluates [`Kernel::eval`] entry by entry, in parallel over rows.
    fn fill_gram_columns(&self, z: &Signal, cols: Range<usize>, out: MatMut<'_, f64>) {
        let start = cols.start;
        par_rows(out, &|i, mut row| {
            let zi = z.sample(i);
            for jj in 0..row.ncols() {
                row[jj] = self.eval(zi, z.sample(start + jj));
            }
        });
    }

    /// Writes the cross-Gram matrix k(a_i, b_j) of the points of `rows` and `cols` into `out`
    /// (`rows.len()` × `cols.len()`, any layout): what posterior bands at new points need.
    /// The default evaluates [`Kernel::eval`] entry by entry, in parallel over rows; a kernel
    /// with one batched evaluation (a kernel written in another language) overrides it.
    fn fill_cross(&self, rows: &Signal, cols: &Signal, out: MatMut<'_, f64>) {
        par_rows(out, &|i, mut row| {
            let a = rows.sample(i);
            for j in 0..row.ncols() {
                row[j] = self.eval(a, cols.sample(j));
            }
        });
    }

    /// N̂(z) = Σ_k α_k k(z, z_k) at one point `z` for the centres z_k and coefficients α: how
    /// a [`KernelExpansion`] evaluates, in simulation once per sample. The default sums
    /// [`Kernel::eval`] over the centres with α_k ≠ 0, in order; a kernel with one batched
    /// evaluation overrides it.
    fn eval_expansion(&self, z: &[f64], centres: &Signal, alpha: &[f64]) -> f64 {
        alpha
            .iter()
            .enumerate()
            .filter(|(_, a)| **a != 0.0)
            .map(|(k, a)| a * self.eval(z, centres.sample(k)))
            .sum()
    }
}

/// Copies the upper triangle of the square matrix `m` into its lower triangle, one block of
/// columns at a time (the split keeps the reads and writes in disjoint borrows).
pub(crate) fn mirror_upper_to_lower(mut m: MatMut<'_, f64>) {
    const TILE: usize = 64;
    let n = m.nrows();
    for j0 in (0..n).step_by(TILE) {
        let j1 = (j0 + TILE).min(n);
        for j in j0..j1 {
            for i in j + 1..j1 {
                m[(i, j)] = m[(j, i)];
            }
        }
        if j1 < n {
            let (left, right) = m.rb_mut().split_at_col_mut(j1);
            let src = right.rb().submatrix(j0, 0, j1 - j0, n - j1);
            let mut dst = left.submatrix_mut(j1, j0, n - j1, j1 - j0);
            // TILE×TILE tiles: the source tile's TILE columns stay in L1 while the destination
            // columns are written contiguously.
            for c0 in (0..n - j1).step_by(TILE) {
                let c1 = (c0 + TILE).min(n - j1);
                for jj in 0..j1 - j0 {
                    let mut col = dst.rb_mut().col_mut(jj);
                    for c in c0..c1 {
                        col[c] = src[(jj, c)];
                    }
                }
            }
        }
    }
}

/// Runs `f(j, column j)` over the columns of `out`, splitting them between rayon threads.
pub(crate) fn par_cols(out: MatMut<'_, f64>, f: &(dyn Fn(usize, faer::ColMut<'_, f64>) + Sync)) {
    fn go(
        first: usize,
        mut out: MatMut<'_, f64>,
        f: &(dyn Fn(usize, faer::ColMut<'_, f64>) + Sync),
    ) {
        let n = out.ncols();
        if n <= 16 {
            for j in 0..n {
                f(first + j, out.rb_mut().col_mut(j));
            }
        } else {
            let cut = balanced_cut(first, n);
            let (l, r) = out.split_at_col_mut(cut);
            rayon::join(|| go(first, l, f), || go(first + cut, r, f));
        }
    }
    go(0, out, f);
}

/// Where to split the columns `first..first + n` of an upper-triangular fill, whose column j
/// costs about j + 1, so that both halves get similar work: the c with
/// Σ_{first ≤ j < c} j = Σ_{c ≤ j < first + n} j, i.e. c = √((first² + (first + n)²)/2),
/// returned relative to `first`. Each half holds at most about 71 % of the columns, so the
/// recursion depth is logarithmic in the number of columns wherever the range starts (a cut
/// at a fixed share of `first + n` peels one column at a time off a range far from 0, and
/// overflowed the stack from about 11 000 samples).
fn balanced_cut(first: usize, n: usize) -> usize {
    let (a, b) = (first as f64, (first + n) as f64);
    let c = (0.5 * (a * a + b * b)).sqrt() as usize;
    c.clamp(first + n.div_ceil(4), first + n - n.div_ceil(4)) - first
}

/// Runs `f(i, row i)` over the rows of `out`, splitting the rows between rayon threads.
pub(crate) fn par_rows(out: MatMut<'_, f64>, f: &(dyn Fn(usize, faer::RowMut<'_, f64>) + Sync)) {
    fn go(
        first: usize,
        mut out: MatMut<'_, f64>,
        f: &(dyn Fn(usize, faer::RowMut<'_, f64>) + Sync),
    ) {
        let n = out.nrows();
        if n <= 64 {
            for i in 0..n {
                f(first + i, out.rb_mut().row_mut(i));
            }
        } else {
            let (top, bottom) = out.split_at_row_mut(n / 2);
            rayon::join(|| go(first, top, f), || go(first + n / 2, bottom, f));
        }
    }
    go(0, out, f);
}

/// The paper's Gaussian kernel, K(z₁,z₂) = (2πσ²)^(−p/2)·exp(−‖z₁−z₂‖²/(2σ²)).
///
/// The normalisation is the paper's, so a given β means the same as in Hsu et al. (2006).
///
/// ```
/// use structid_core::{GaussianKernel, Kernel};
/// let k = GaussianKernel::new(0.5).unwrap();
/// let peak = 1.0 / (2.0 * std::f64::consts::PI * 0.25).sqrt();
/// assert!((k.eval(&[0.3], &[0.3]) - peak).abs() < 1e-15);
/// assert!(GaussianKernel::new(0.0).is_err());
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GaussianKernel {
    sigma: f64,
}

impl GaussianKernel {
    /// A Gaussian kernel of width `sigma` (> 0, finite).
    pub fn new(sigma: f64) -> Result<Self> {
        Ok(Self {
            sigma: positive_finite("sigma", sigma)?,
        })
    }

    /// The width σ.
    pub fn sigma(&self) -> f64 {
        self.sigma
    }

    /// The normalising constant (2πσ²)^(−p/2) for inputs of dimension `p`.
    pub fn normalisation(&self, p: usize) -> f64 {
        (2.0 * std::f64::consts::PI * self.sigma * self.sigma).powf(-(p as f64) / 2.0)
    }
}

impl Kernel for GaussianKernel {
    fn eval(&self, a: &[f64], b: &[f64]) -> f64 {
        let d2: f64 = a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum();
        self.normalisation(a.len()) * (-d2 / (2.0 * self.sigma * self.sigma)).exp()
    }

    fn stored_kernel(&self) -> Option<crate::stored::StoredKernel> {
        Some(crate::stored::StoredKernel::Gaussian { sigma: self.sigma })
    }

    fn describe(&self) -> String {
        format!("gaussian(sigma={})", self.sigma)
    }

    fn parameters(&self) -> Vec<(String, f64)> {
        vec![("sigma".into(), self.sigma)]
    }

    fn width(&self) -> Option<f64> {
        Some(self.sigma)
    }

    fn with_width(&self, width: f64) -> Option<Result<Self>> {
        Some(GaussianKernel::new(width))
    }

    fn fill_gram(&self, z: &Signal, mut out: MatMut<'_, f64>) {
        // Half the exponentials: the upper triangle column by column (contiguous when `out` is
        // column-major), then a mirror copy.
        let len = z.len();
        let p = z.channels();
        let c = self.normalisation(p);
        let s = 1.0 / (2.0 * self.sigma * self.sigma);
        let data = z.as_slice();
        par_cols(out.rb_mut(), &|j, mut col| {
            let zj = &data[j * p..(j + 1) * p];
            let fill = |v: &mut [f64]| {
                for (i, x) in v.iter_mut().enumerate() {
                    let zi = &data[i * p..(i + 1) * p];
                    let d2: f64 = zi.iter().zip(zj).map(|(a, b)| (a - b) * (a - b)).sum();
                    *x = -d2 * s;
                }
                exp_in_place(v, c);
            };
            match col.rb_mut().subrows_mut(0, j + 1).try_as_col_major_mut() {
                Some(cm) => fill(cm.as_slice_mut()),
                None => {
                    let mut v = vec![0.0; j + 1];
                    fill(&mut v);
                    for (i, x) in v.into_iter().enumerate() {
                        col[i] = x;
                    }
                }
            }
        });
        debug_assert_eq!(out.nrows(), len);
        mirror_upper_to_lower(out);
    }

    fn fill_gram_columns(&self, z: &Signal, cols: Range<usize>, out: MatMut<'_, f64>) {
        // Hoisting the constants, specialising p = 1 and the vectorised exp matter: this fills
        // L² entries. Rows are contiguous in the row-major panels the exact solver asks for.
        let p = z.channels();
        let c = self.normalisation(p);
        let s = 1.0 / (2.0 * self.sigma * self.sigma);
        let data = z.as_slice();
        let zc = &data[cols.start * p..cols.end * p];
        let w = cols.len();
        par_rows(out, &|i, mut row| {
            let zi = &data[i * p..(i + 1) * p];
            let fill = |v: &mut [f64]| {
                if p == 1 {
                    for (x, &zj) in v.iter_mut().zip(zc) {
                        let d = zi[0] - zj;
                        *x = -(d * d) * s;
                    }
                } else {
                    for (x, zj) in v.iter_mut().zip(zc.chunks_exact(p)) {
                        let d2: f64 = zi.iter().zip(zj).map(|(a, b)| (a - b) * (a - b)).sum();
                        *x = -d2 * s;
                    }
                }
                exp_in_place(v, c);
            };
            match row.rb_mut().try_as_row_major_mut() {
                Some(r) => fill(r.as_slice_mut()),
                None => {
                    let mut v = vec![0.0; w];
                    fill(&mut v);
                    for (jj, x) in v.into_iter().enumerate() {
                        row[jj] = x;
                    }
                }
            }
        });
    }
}

/// x ← scale·exp(x) for x ≤ 0, element-wise, accurate to a few ulp.
///
/// libm's `exp` is a call per element; this branch-free Cody–Waite reduction with a degree-12
/// Taylor polynomial auto-vectorises, which matters because a Gram matrix has L² entries.
/// Arguments below −708 flush to scale·exp(−708) ≈ 0 (relative to the diagonal entry `scale`
/// that is far below rounding).
pub(crate) fn exp_in_place(xs: &mut [f64], scale: f64) {
    const LOG2E: f64 = std::f64::consts::LOG2_E;
    // ln 2 split so that n·LN2_HI is exact for |n| < 2^11 (fdlibm's constants).
    const LN2_HI: f64 = f64::from_bits(0x3FE6_2E42_FEE0_0000);
    const LN2_LO: f64 = f64::from_bits(0x3DEA_39EF_3579_3C76);
    // Adding 1.5·2^52 rounds to an integer in the low mantissa bits.
    const MAGIC: f64 = 6_755_399_441_055_744.0;
    const INV_FACT: [f64; 13] = [
        1.0,
        1.0,
        1.0 / 2.0,
        1.0 / 6.0,
        1.0 / 24.0,
        1.0 / 120.0,
        1.0 / 720.0,
        1.0 / 5040.0,
        1.0 / 40320.0,
        1.0 / 362_880.0,
        1.0 / 3_628_800.0,
        1.0 / 39_916_800.0,
        1.0 / 479_001_600.0,
    ];
    for x in xs.iter_mut() {
        let v = x.clamp(-708.0, 0.0);
        let t = v * LOG2E + MAGIC;
        let n = t - MAGIC;
        let r = (v - n * LN2_HI) - n * LN2_LO;
        let mut poly = INV_FACT[12];
        for k in (0..12).rev() {
            poly = poly * r + INV_FACT[k];
        }
        let bits = (t.to_bits() as i64 - MAGIC.to_bits() as i64 + 1023) << 52;
        *x = scale * poly * f64::from_bits(bits as u64);
    }
}

/// The representer-form estimate N̂(z) = Σ_k α_k k(z, z_k) of a kernel dispersion.
#[derive(Debug, Clone)]
pub struct KernelExpansion<K: Kernel> {
    kernel: Arc<K>,
    centres: Signal,
    alpha: Vec<f64>,
}

impl<K: Kernel> KernelExpansion<K> {
    /// An expansion with the given centres z_k and coefficients α_k.
    ///
    /// # Panics
    /// Never for consistent inputs; a length mismatch between `centres` and `alpha` is a
    /// programming error and is checked by `debug_assert`.
    pub fn new(kernel: Arc<K>, centres: Signal, alpha: Vec<f64>) -> Self {
        debug_assert_eq!(centres.len(), alpha.len());
        Self {
            kernel,
            centres,
            alpha,
        }
    }

    /// The coefficients α.
    pub fn alpha(&self) -> &[f64] {
        &self.alpha
    }

    /// The centres z_k.
    pub fn centres(&self) -> &Signal {
        &self.centres
    }

    /// The kernel.
    pub fn kernel(&self) -> &K {
        &self.kernel
    }
}

impl<K: Kernel> Interpolant for KernelExpansion<K> {
    fn eval(&self, z: &[f64]) -> f64 {
        self.kernel.eval_expansion(z, &self.centres, &self.alpha)
    }

    /// A block of points at a time through [`Kernel::fill_cross`] (one call of a batched
    /// kernel per block), summed as [`Kernel::eval_expansion`] sums: the same values as
    /// `eval` at each point.
    fn eval_many(&self, z: &Signal) -> Vec<f64> {
        let n = self.centres.len();
        if n == 0 || z.channels() != self.centres.channels() {
            return (0..z.len()).map(|k| self.eval(z.sample(k))).collect();
        }
        // Blocks of at most 2²² kernel values (32 MiB).
        let block = ((1usize << 22) / n).max(1);
        let p = z.channels();
        let mut out = Vec::with_capacity(z.len());
        let mut k = vec![0.0; block.min(z.len()) * n];
        for t0 in (0..z.len()).step_by(block) {
            let rows = block.min(z.len() - t0);
            let points = Signal::new(p, z.as_slice()[t0 * p..(t0 + rows) * p].to_vec())
                .expect("a block of a signal is a signal");
            let buf = &mut k[..rows * n];
            self.kernel.fill_cross(
                &points,
                &self.centres,
                MatMut::from_row_major_slice_mut(buf, rows, n),
            );
            out.extend(buf.chunks_exact(n).map(|row| {
                self.alpha
                    .iter()
                    .zip(row)
                    .filter(|(a, _)| **a != 0.0)
                    .map(|(a, v)| a * v)
                    .sum::<f64>()
            }));
        }
        out
    }

    fn stored(&self) -> Option<crate::stored::StoredMap> {
        Some(crate::stored::StoredMap::KernelExpansion {
            kernel: self.kernel.stored_kernel()?,
            centres: crate::stored::StoredPoints::from_signal(&self.centres),
            alpha: self.alpha.clone(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The depth of `par_cols`' recursion, replayed without the matrix.
    fn split_depth(first: usize, n: usize) -> usize {
        if n <= 16 {
            return 0;
        }
        let cut = balanced_cut(first, n);
        assert!(cut >= 1 && cut < n, "cut {cut} of {n} at {first}");
        1 + split_depth(first, cut).max(split_depth(first + cut, n - cut))
    }

    #[test]
    fn column_split_depth_is_logarithmic_and_work_is_balanced() {
        // 12 000 columns used to split ~24 000 frames deep; a balanced split needs ~log_{4/3}.
        for n in [17, 100, 12_000, 1_000_000] {
            let depth = split_depth(0, n);
            let bound = ((n as f64 / 16.0).ln() / (4.0f64 / 3.0).ln()).ceil() as usize + 1;
            assert!(depth <= bound, "n = {n}: depth {depth} > {bound}");
        }
        // A range far from 0 (the right half of a large fill) is cut near its middle.
        let (first, n) = (10_000, 1_000);
        let cut = balanced_cut(first, n);
        let work = |a: usize, b: usize| (a..b).map(|j| (j + 1) as f64).sum::<f64>();
        let (l, r) = (work(first, first + cut), work(first + cut, first + n));
        assert!((l / r - 1.0).abs() < 0.01, "left {l} right {r}");
    }

    #[test]
    fn gaussian_fast_gram_equals_entrywise_eval() {
        let k = GaussianKernel::new(0.3).unwrap();
        for p in 1..=3 {
            let z = Signal::from_fn(17, p, |i, c| ((i * 7 + c * 3) % 11) as f64 / 5.0 - 1.0);
            for row_major in [true, false] {
                let mut buf = vec![0.0; 17 * 5];
                let out = if row_major {
                    MatMut::from_row_major_slice_mut(&mut buf, 17, 5)
                } else {
                    MatMut::from_column_major_slice_mut(&mut buf, 17, 5)
                };
                k.fill_gram_columns(&z, 4..9, out);
                let fast = if row_major {
                    faer::MatRef::from_row_major_slice(&buf, 17, 5)
                } else {
                    faer::MatRef::from_column_major_slice(&buf, 17, 5)
                };
                for (jj, j) in (4..9).enumerate() {
                    for i in 0..17 {
                        let direct = k.eval(z.sample(i), z.sample(j));
                        assert!((fast[(i, jj)] - direct).abs() <= 1e-14 * direct.abs().max(1e-300));
                    }
                }
            }
        }
    }

    #[test]
    fn default_gram_fill_matches_the_fast_gaussian_fill() {
        #[derive(Debug)]
        struct Plain(GaussianKernel);
        impl Kernel for Plain {
            fn eval(&self, a: &[f64], b: &[f64]) -> f64 {
                self.0.eval(a, b)
            }
            fn describe(&self) -> String {
                "plain".into()
            }
        }
        let g = GaussianKernel::new(0.4).unwrap();
        let z = Signal::from_fn(300, 2, |i, c| ((i * 13 + c * 7) % 29) as f64 / 9.0);
        // The symmetric whole-matrix fill equals the column fill.
        for p in [1, 2] {
            let zp = Signal::from_fn(203, p, |i, c| ((i * 13 + c * 7) % 29) as f64 / 9.0);
            let mut full = faer::Mat::<f64>::zeros(203, 203);
            g.fill_gram(&zp, full.as_mut());
            let mut cols = faer::Mat::<f64>::zeros(203, 203);
            g.fill_gram_columns(&zp, 0..203, cols.as_mut());
            for j in 0..203 {
                for i in 0..203 {
                    assert!(
                        (full[(i, j)] - cols[(i, j)]).abs()
                            <= 1e-14 * cols[(i, j)].abs().max(1e-300),
                        "({i},{j})"
                    );
                }
            }
        }
        let (mut a, mut b) = (vec![0.0; 300 * 40], vec![0.0; 300 * 40]);
        Plain(g).fill_gram_columns(
            &z,
            100..140,
            MatMut::from_column_major_slice_mut(&mut a, 300, 40),
        );
        g.fill_gram_columns(
            &z,
            100..140,
            MatMut::from_column_major_slice_mut(&mut b, 300, 40),
        );
        for (x, y) in a.iter().zip(&b) {
            assert!((x - y).abs() <= 1e-14 * y.abs().max(1e-300));
        }
    }

    #[test]
    fn vectorised_exp_matches_libm_to_a_few_ulp() {
        let mut xs: Vec<f64> = (0..200_001)
            .map(|i| -(i as f64) * 708.0 / 200_000.0)
            .collect();
        xs.extend([0.0, -1e-300, -0.5, -0.346_573_590_279_972_6, -700.123]);
        let mut ys = xs.clone();
        exp_in_place(&mut ys, 1.0);
        for (x, y) in xs.iter().zip(&ys) {
            let e = x.exp();
            assert!(
                (y - e).abs() <= 4.0 * f64::EPSILON * e,
                "exp({x}) = {e}, got {y}"
            );
        }
        let mut far = vec![-1e4, -750.0];
        exp_in_place(&mut far, 1.0);
        assert!(far.iter().all(|v| *v >= 0.0 && *v < 1e-300));
    }

    #[test]
    fn gaussian_normalisation_integrates_to_one_in_1d() {
        let k = GaussianKernel::new(0.7).unwrap();
        let h = 1e-3;
        let total: f64 = (-10_000..=10_000)
            .map(|i| k.eval(&[i as f64 * h], &[0.0]) * h)
            .sum();
        assert!((total - 1.0).abs() < 1e-9, "{total}");
    }

    #[test]
    fn gaussian_rejects_bad_sigma() {
        for s in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert!(GaussianKernel::new(s).is_err());
        }
    }
}
