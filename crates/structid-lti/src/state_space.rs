//! Discrete-time state-space systems (with recursive and blocked Toeplitz operators) and
//! continuous-time state-space systems with zero-order-hold discretisation.

use crate::error::{LtiError, check_matrix_finite};
use crate::operator::{BlockedRecursion, LinearSystem, horizon, static_columns};
use crate::signal::Signal;
use faer::{Accum, Mat, MatMut, MatRef};
use nalgebra::DMatrix;

/// Time-block length `b` of the blocked many-column operators. The cost per sample and
/// column is about `2 (b p + n)(b m + n) / b` flops, minimal near `b = n / sqrt(p m)`;
/// blocks of at least 16 rows keep the matrix products efficient.
fn time_block(n: usize, m: usize, p: usize) -> usize {
    let by_width = 16usize.div_ceil(m.max(p).max(1));
    let by_order = (n as f64 / ((m.max(1) * p.max(1)) as f64).sqrt()).ceil() as usize;
    by_width.max(by_order).clamp(1, 64)
}

/// Checks the shapes `a: n x n`, `b: n x m`, `c: p x n`, `d: p x m` and finiteness.
fn validate(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    c: &DMatrix<f64>,
    d: &DMatrix<f64>,
) -> Result<(), LtiError> {
    let n = a.nrows();
    if a.ncols() != n {
        return Err(LtiError::dims(
            "state matrix A",
            "a square matrix",
            format!("{} x {}", a.nrows(), a.ncols()),
        ));
    }
    if b.nrows() != n {
        return Err(LtiError::dims(
            "input matrix B rows",
            format!("{n} (the order of A)"),
            b.nrows(),
        ));
    }
    if c.ncols() != n {
        return Err(LtiError::dims(
            "output matrix C columns",
            format!("{n} (the order of A)"),
            c.ncols(),
        ));
    }
    if d.nrows() != c.nrows() || d.ncols() != b.ncols() {
        return Err(LtiError::dims(
            "feedthrough matrix D",
            format!("{} x {} (outputs x inputs)", c.nrows(), b.ncols()),
            format!("{} x {}", d.nrows(), d.ncols()),
        ));
    }
    check_matrix_finite("A", a)?;
    check_matrix_finite("B", b)?;
    check_matrix_finite("C", c)?;
    check_matrix_finite("D", d)?;
    Ok(())
}

fn check_sample_time(ts: f64) -> Result<(), LtiError> {
    if ts.is_finite() && ts > 0.0 {
        Ok(())
    } else {
        Err(LtiError::param(
            "sample_time",
            format!("must be positive and finite, got {ts}"),
        ))
    }
}

fn row_major(m: &DMatrix<f64>) -> Vec<f64> {
    let mut v = Vec::with_capacity(m.len());
    for i in 0..m.nrows() {
        for j in 0..m.ncols() {
            v.push(m[(i, j)]);
        }
    }
    v
}

fn to_faer(m: &DMatrix<f64>) -> Mat<f64> {
    Mat::from_fn(m.nrows(), m.ncols(), |i, j| m[(i, j)])
}

/// Row-major copies of A, B, C, D for the scalar per-sample recursions.
#[derive(Clone, Debug, PartialEq, Default)]
struct RowMajor {
    a: Vec<f64>,
    b: Vec<f64>,
    c: Vec<f64>,
    d: Vec<f64>,
}

/// The matrix accessors and dimensions shared by [`StateSpace`] and
/// [`ContinuousStateSpace`] (both hold private fields `a`, `b`, `c`, `d`).
macro_rules! abcd_accessors {
    () => {
        /// State matrix `A` (`n x n`).
        pub fn a(&self) -> &DMatrix<f64> {
            &self.a
        }

        /// Input matrix `B` (`n x m`).
        pub fn b(&self) -> &DMatrix<f64> {
            &self.b
        }

        /// Output matrix `C` (`p x n`).
        pub fn c(&self) -> &DMatrix<f64> {
            &self.c
        }

        /// Feedthrough matrix `D` (`p x m`).
        pub fn d(&self) -> &DMatrix<f64> {
            &self.d
        }

        /// Number of states `n`.
        pub fn order(&self) -> usize {
            self.a.nrows()
        }

        /// Number of inputs `m`.
        pub fn inputs(&self) -> usize {
            self.b.ncols()
        }

        /// Number of outputs `p`.
        pub fn outputs(&self) -> usize {
            self.c.nrows()
        }
    };
}

/// A discrete-time state-space system
/// `x_{k+1} = A x_k + B u_k`, `y_k = C x_k + D u_k`.
///
/// Order `n = 0` (a static gain `y_k = D u_k`) is allowed, as are zero inputs or outputs.
/// Implements [`LinearSystem`]: `T` is the block lower-triangular Toeplitz matrix of the
/// Markov parameters, applied by recursion (never formed densely).
#[derive(Clone, PartialEq)]
pub struct StateSpace {
    a: DMatrix<f64>,
    b: DMatrix<f64>,
    c: DMatrix<f64>,
    d: DMatrix<f64>,
    sample_time: Option<f64>,
    rm: RowMajor,
}

impl std::fmt::Debug for StateSpace {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // the row-major cache is derived data: leave it out
        f.debug_struct("StateSpace")
            .field("a", &self.a)
            .field("b", &self.b)
            .field("c", &self.c)
            .field("d", &self.d)
            .field("sample_time", &self.sample_time)
            .finish()
    }
}

impl StateSpace {
    /// Creates a validated system: `a` is `n x n`, `b` is `n x m`, `c` is `p x n`,
    /// `d` is `p x m`, all entries finite. `n = 0` is allowed (`0 x 0` A, `0 x m` B,
    /// `p x 0` C).
    ///
    /// ```
    /// use nalgebra::DMatrix;
    /// use structid_lti::{LinearSystem, Signal, StateSpace};
    /// // y_k = x_k, x_{k+1} = 0.5 x_k + u_k  (impulse response 0, 1, 0.5, 0.25, ...)
    /// let sys = StateSpace::new(
    ///     DMatrix::from_element(1, 1, 0.5),
    ///     DMatrix::from_element(1, 1, 1.0),
    ///     DMatrix::from_element(1, 1, 1.0),
    ///     DMatrix::zeros(1, 1),
    /// )
    /// .unwrap();
    /// let u = Signal::new(1, vec![1.0, 0.0, 0.0, 0.0]).unwrap();
    /// let y = sys.simulate(&u).unwrap();
    /// assert_eq!(y.as_slice(), &[0.0, 1.0, 0.5, 0.25]);
    /// ```
    pub fn new(
        a: DMatrix<f64>,
        b: DMatrix<f64>,
        c: DMatrix<f64>,
        d: DMatrix<f64>,
    ) -> Result<Self, LtiError> {
        validate(&a, &b, &c, &d)?;
        let rm = RowMajor {
            a: row_major(&a),
            b: row_major(&b),
            c: row_major(&c),
            d: row_major(&d),
        };
        Ok(StateSpace {
            a,
            b,
            c,
            d,
            sample_time: None,
            rm,
        })
    }

    /// A static gain `y_k = D u_k` (order 0). Fails if `d` has non-finite entries.
    ///
    /// ```
    /// use nalgebra::DMatrix;
    /// use structid_lti::{LinearSystem, Signal, StateSpace};
    /// let g = StateSpace::static_gain(DMatrix::from_row_slice(1, 2, &[2.0, -1.0])).unwrap();
    /// assert_eq!(g.order(), 0);
    /// let y = g.simulate(&Signal::new(2, vec![1.0, 1.0, 3.0, 0.0]).unwrap()).unwrap();
    /// assert_eq!(y.as_slice(), &[1.0, 6.0]);
    /// ```
    pub fn static_gain(d: DMatrix<f64>) -> Result<Self, LtiError> {
        let (p, m) = d.shape();
        Self::new(
            DMatrix::zeros(0, 0),
            DMatrix::zeros(0, m),
            DMatrix::zeros(p, 0),
            d,
        )
    }

    /// Attaches a sample time (seconds, positive and finite). It is metadata only: the
    /// operators work in samples.
    pub fn with_sample_time(mut self, ts: f64) -> Result<Self, LtiError> {
        check_sample_time(ts)?;
        self.sample_time = Some(ts);
        Ok(self)
    }

    /// The sample time, if one was attached.
    pub fn sample_time(&self) -> Option<f64> {
        self.sample_time
    }

    abcd_accessors!();

    /// The first `count` Markov parameters: `h_0 = D`, `h_j = C A^{j-1} B`.
    pub fn markov_parameters(&self, count: usize) -> Vec<DMatrix<f64>> {
        let mut out = Vec::with_capacity(count);
        if count == 0 {
            return out;
        }
        out.push(self.d.clone());
        let mut ajb = self.b.clone();
        for _ in 1..count {
            out.push(&self.c * &ajb);
            ajb = &self.a * &ajb;
        }
        out
    }

    /// The spectral radius of A restricted to the states its inputs reach: the subspace
    /// spanned by B, AB, A²B, … (an orthonormal Krylov basis Q, rank by SVD at 10⁻¹⁰ of the
    /// largest singular value; then the radius of QᵀAQ). Modes that no input excites (e.g. a
    /// plant's integrator in a noise path that only drives a sensor) never grow from a zero
    /// state, so a recursion driven by the inputs is stable when this radius is below 1 even
    /// if [`spectral_radius`](Self::spectral_radius) is not. 0 for a system without reachable
    /// states; NaN when the Krylov basis overflows (finite but huge entries).
    ///
    /// ```
    /// use nalgebra::dmatrix;
    /// use structid_lti::StateSpace;
    /// // An integrator that the input does not reach, and a reachable pole at 0.5.
    /// let s = StateSpace::new(dmatrix![1.0, 0.0; 0.0, 0.5], dmatrix![0.0; 1.0], dmatrix![1.0, 1.0], dmatrix![0.0]).unwrap();
    /// assert_eq!(s.spectral_radius(), 1.0);
    /// assert!((s.reachable_spectral_radius() - 0.5).abs() < 1e-12);
    /// ```
    pub fn reachable_spectral_radius(&self) -> f64 {
        let n = self.order();
        if n == 0 || self.b.ncols() == 0 {
            return 0.0;
        }
        let mut krylov = DMatrix::zeros(n, n * self.b.ncols());
        let mut block = self.b.clone();
        for i in 0..n {
            krylov
                .view_mut((0, i * self.b.ncols()), (n, self.b.ncols()))
                .copy_from(&block);
            block = &self.a * block;
        }
        // Huge (finite) entries can overflow A^k·B; the SVD panics on a non-finite matrix.
        if krylov.iter().any(|v| !v.is_finite()) {
            return f64::NAN;
        }
        let svd = krylov.svd(true, false);
        let smax = svd.singular_values.max();
        if smax == 0.0 || !smax.is_finite() {
            return if smax == 0.0 { 0.0 } else { f64::NAN };
        }
        let u = svd.u.as_ref().expect("SVD computed with U");
        let rank = svd
            .singular_values
            .iter()
            .filter(|s| **s > 1e-10 * smax)
            .count();
        let q = u.columns(0, rank).into_owned();
        let reduced = q.transpose() * &self.a * &q;
        // The eigenvalue iteration does not terminate on a non-finite matrix.
        if reduced.iter().any(|v| !v.is_finite()) {
            return f64::NAN;
        }
        reduced
            .complex_eigenvalues()
            .iter()
            .map(|z| z.norm())
            .fold(0.0, f64::max)
    }

    /// Spectral radius of `A` (largest eigenvalue modulus); 0 for `n = 0`.
    pub fn spectral_radius(&self) -> f64 {
        if self.order() == 0 {
            return 0.0;
        }
        self.a
            .complex_eigenvalues()
            .iter()
            .map(|z| z.norm())
            .fold(0.0, f64::max)
    }

    /// `true` when the spectral radius of `A` is strictly below 1 (asymptotic stability).
    pub fn is_stable(&self) -> bool {
        self.spectral_radius() < 1.0
    }

    fn check_x0_u(&self, x0: &[f64], u: &Signal) -> Result<(), LtiError> {
        if x0.len() != self.order() {
            return Err(LtiError::dims(
                "initial state length",
                self.order(),
                x0.len(),
            ));
        }
        if let Some(i) = x0.iter().position(|v| !v.is_finite()) {
            return Err(LtiError::NonFiniteMatrix {
                what: "initial state".into(),
                row: i,
                col: 0,
                value: x0[i],
            });
        }
        if u.channels() != self.inputs() {
            return Err(LtiError::dims(
                "input signal channels",
                self.inputs(),
                u.channels(),
            ));
        }
        u.check_finite("input signal")
    }

    /// Scalar recursion from `x0`; writes `y` (and the states `x_0 .. x_{L-1}` when asked),
    /// returns the final state `x_L`.
    pub(crate) fn run(
        &self,
        x0: &[f64],
        u: &[f64],
        y: &mut [f64],
        len: usize,
        mut states: Option<&mut [f64]>,
    ) -> Vec<f64> {
        let (n, m, p) = (self.order(), self.inputs(), self.outputs());
        let RowMajor { a, b, c, d } = &self.rm;
        let mut x = x0.to_vec();
        let mut xn = vec![0.0; n];
        for k in 0..len {
            let uk = &u[k * m..(k + 1) * m];
            if let Some(st) = states.as_deref_mut() {
                st[k * n..(k + 1) * n].copy_from_slice(&x);
            }
            let yk = &mut y[k * p..(k + 1) * p];
            set_sum_of_products(c, &x[..n], d, uk, yk);
            if n > 0 {
                set_sum_of_products(a, &x[..n], b, uk, &mut xn);
                std::mem::swap(&mut x, &mut xn);
            }
        }
        x
    }

    /// Simulates from the initial state `x0` (length `n`). Returns `(y, x_L)`: the output
    /// signal and the final state after the last sample. Checks dimensions and finiteness.
    ///
    /// ```
    /// use nalgebra::DMatrix;
    /// use structid_lti::{Signal, StateSpace};
    /// let sys = StateSpace::new(
    ///     DMatrix::from_element(1, 1, 0.5),
    ///     DMatrix::from_element(1, 1, 1.0),
    ///     DMatrix::from_element(1, 1, 1.0),
    ///     DMatrix::zeros(1, 1),
    /// )
    /// .unwrap();
    /// let (y, x_end) = sys.simulate_from(&[4.0], &Signal::zeros(3, 1)).unwrap();
    /// assert_eq!(y.as_slice(), &[4.0, 2.0, 1.0]);
    /// assert_eq!(x_end, vec![0.5]);
    /// ```
    pub fn simulate_from(&self, x0: &[f64], u: &Signal) -> Result<(Signal, Vec<f64>), LtiError> {
        self.check_x0_u(x0, u)?;
        let mut y = Signal::zeros(u.len(), self.outputs());
        let xl = self.run(x0, u.as_slice(), y.as_mut_slice(), u.len(), None);
        Ok((y, xl))
    }

    /// Like [`simulate_from`](StateSpace::simulate_from) but returns the state trajectory:
    /// `(y, x)` where `x` has `n` channels and holds `x_0 .. x_{L-1}`.
    pub fn simulate_states(&self, x0: &[f64], u: &Signal) -> Result<(Signal, Signal), LtiError> {
        self.check_x0_u(x0, u)?;
        let mut y = Signal::zeros(u.len(), self.outputs());
        let mut x = Signal::zeros(u.len(), self.order());
        self.run(
            x0,
            u.as_slice(),
            y.as_mut_slice(),
            u.len(),
            Some(x.as_mut_slice()),
        );
        Ok((y, x))
    }

    /// The subsystem driven by the inputs `idx` (columns of `B` and `D`, in that order);
    /// `A`, `C` and the sample time are kept.
    pub fn select_inputs(&self, idx: &[usize]) -> Result<StateSpace, LtiError> {
        check_channels(idx, self.inputs(), "input")?;
        let mut s = StateSpace::new(
            self.a.clone(),
            self.b.select_columns(idx.iter()),
            self.c.clone(),
            self.d.select_columns(idx.iter()),
        )?;
        s.sample_time = self.sample_time;
        Ok(s)
    }

    /// The subsystem seen from the outputs `idx` (rows of `C` and `D`, in that order);
    /// `A`, `B` and the sample time are kept.
    pub fn select_outputs(&self, idx: &[usize]) -> Result<StateSpace, LtiError> {
        check_channels(idx, self.outputs(), "output")?;
        let mut s = StateSpace::new(
            self.a.clone(),
            self.b.clone(),
            self.c.select_rows(idx.iter()),
            self.d.select_rows(idx.iter()),
        )?;
        s.sample_time = self.sample_time;
        Ok(s)
    }

    /// The dense `(len * outputs) x (len * inputs)` block lower-triangular Toeplitz matrix
    /// `T` (block `(i, j)` is `h_{i-j}` for `i >= j`).
    ///
    /// **For tests and small reference code only**: it costs `O(len^2)` memory and the
    /// operators of [`LinearSystem`] never form it.
    pub fn toeplitz_dense(&self, len: usize) -> DMatrix<f64> {
        let (m, p) = (self.inputs(), self.outputs());
        let h = self.markov_parameters(len);
        let mut t = DMatrix::zeros(len * p, len * m);
        for i in 0..len {
            for j in 0..=i {
                t.view_mut((i * p, j * m), (p, m)).copy_from(&h[i - j]);
            }
        }
        t
    }

    /// Series connection `y = self(other(u))`: `other`'s outputs feed `self`'s inputs.
    /// The state is `[x_other; x_self]`. Sample times must agree when both are set.
    pub fn series(&self, other: &StateSpace) -> Result<StateSpace, LtiError> {
        if other.outputs() != self.inputs() {
            return Err(LtiError::dims(
                "series connection (outputs of the first system vs inputs of the second)",
                self.inputs(),
                other.outputs(),
            ));
        }
        let sample_time = match (self.sample_time, other.sample_time) {
            (Some(a), Some(b)) if a != b => {
                return Err(LtiError::param(
                    "sample_time",
                    format!("series connection of systems with different sample times {b} and {a}"),
                ));
            }
            (a, b) => a.or(b),
        };
        let (n1, n2) = (self.order(), other.order());
        let n = n1 + n2;
        let m = other.inputs();
        let p = self.outputs();
        let mut a = DMatrix::zeros(n, n);
        a.view_mut((0, 0), (n2, n2)).copy_from(&other.a);
        a.view_mut((n2, 0), (n1, n2))
            .copy_from(&(&self.b * &other.c));
        a.view_mut((n2, n2), (n1, n1)).copy_from(&self.a);
        let mut b = DMatrix::zeros(n, m);
        b.view_mut((0, 0), (n2, m)).copy_from(&other.b);
        b.view_mut((n2, 0), (n1, m))
            .copy_from(&(&self.b * &other.d));
        let mut c = DMatrix::zeros(p, n);
        c.view_mut((0, 0), (p, n2)).copy_from(&(&self.d * &other.c));
        c.view_mut((0, n2), (p, n1)).copy_from(&self.c);
        let d = &self.d * &other.d;
        let mut s = StateSpace::new(a, b, c, d)?;
        s.sample_time = sample_time;
        Ok(s)
    }

    /// The blocked recursion (forward or adjoint) for a horizon of `len` samples.
    pub(crate) fn blocked(&self, len: usize, adjoint: bool) -> BlockedRecursion {
        let (n, m, p) = (self.order(), self.inputs(), self.outputs());
        self.blocked_with(time_block(n, m, p).min(len.max(1)), adjoint)
    }

    /// `x ← T x` (or `x ← Tᵀ x` with `adjoint`) in place, for a square system
    /// (inputs = outputs): each **column** of `x` is one stacked signal of `len · inputs`
    /// rows, as in [`LinearSystem::apply_columns`], and `x` may be any strided view (a
    /// transposed, row-major one streams fastest). The result equals `apply_columns` (or
    /// `apply_adjoint_columns`) into a separate matrix, without that matrix.
    ///
    /// # Panics
    /// When the system is not square or the rows of `x` are not a multiple of the inputs.
    ///
    /// ```
    /// use faer::{Accum, Mat};
    /// use structid_lti::{LinearSystem, testing::random_stable_system};
    /// let sys = random_stable_system(3, 4, 1, 1, 0.9);
    /// let x = Mat::<f64>::from_fn(50, 7, |i, j| ((i * 5 + j * 3) % 13) as f64);
    /// let mut out = Mat::<f64>::zeros(50, 7);
    /// sys.apply_columns(x.as_ref(), out.as_mut(), Accum::Replace, 1.0);
    /// let mut y = x.clone();
    /// sys.apply_columns_in_place(y.as_mut(), false);
    /// assert!((&out - &y).norm_max() < 1e-12);
    /// ```
    pub fn apply_columns_in_place(&self, x: MatMut<'_, f64>, adjoint: bool) {
        let m = self.inputs();
        assert_eq!(m, self.outputs(), "an in-place operator must be square");
        if m == 0 || x.nrows() == 0 || x.ncols() == 0 {
            return;
        }
        assert!(
            x.nrows().is_multiple_of(m),
            "{} rows are not a multiple of the {m} channels",
            x.nrows()
        );
        let len = x.nrows() / m;
        self.blocked(len, adjoint).run_in_place(len, x);
    }

    /// The blocked recursion with an explicit block length (streams over narrow operands use
    /// long blocks: fewer, larger matrix products).
    pub(crate) fn blocked_with(&self, bsz: usize, adjoint: bool) -> BlockedRecursion {
        let (n, m, p) = (self.order(), self.inputs(), self.outputs());
        let bsz = bsz.max(1);
        // A^i B and C A^i for i < b, and A^b
        let mut aib = Vec::with_capacity(bsz);
        let mut cai = Vec::with_capacity(bsz);
        let mut ab = DMatrix::<f64>::identity(n, n);
        let mut cur = self.b.clone();
        for _ in 0..bsz {
            cai.push(&self.c * &ab);
            ab = &self.a * &ab;
            aib.push(cur.clone());
            cur = &self.a * &cur;
        }
        let markov = |k: usize| -> DMatrix<f64> {
            if k == 0 {
                self.d.clone()
            } else {
                &self.c * &aib[k - 1]
            }
        };
        let h: Vec<DMatrix<f64>> = (0..bsz).map(markov).collect();
        // forward: m1 = [T_b, Gamma] ((b p) x (b m + n)), m2 = [R, A^b] (n x (b m + n))
        let kf = bsz * m + n;
        let mut m1 = Mat::<f64>::zeros(bsz * p, kf);
        let mut m2 = Mat::<f64>::zeros(n, kf);
        for i in 0..bsz {
            for j in 0..=i {
                for r in 0..p {
                    for s in 0..m {
                        m1[(i * p + r, j * m + s)] = h[i - j][(r, s)];
                    }
                }
            }
            for r in 0..p {
                for s in 0..n {
                    m1[(i * p + r, bsz * m + s)] = cai[i][(r, s)];
                }
            }
        }
        for j in 0..bsz {
            let blk = &aib[bsz - 1 - j];
            for r in 0..n {
                for s in 0..m {
                    m2[(r, j * m + s)] = blk[(r, s)];
                }
            }
        }
        for r in 0..n {
            for s in 0..n {
                m2[(r, bsz * m + s)] = ab[(r, s)];
            }
        }
        if !adjoint {
            return BlockedRecursion {
                b: bsz,
                cin: m,
                cout: p,
                n,
                m1,
                m2,
                reverse: false,
            };
        }
        // adjoint: m1' = [T_b^T, R^T] ((b m) x (b p + n)), m2' = [Gamma^T, (A^b)^T]
        let ka = bsz * p + n;
        let t1 = m1.as_ref().transpose(); // (b m + n) x (b p)
        let t2 = m2.as_ref().transpose(); // (b m + n) x n
        let m1a = Mat::from_fn(bsz * m, ka, |i, j| {
            if j < bsz * p {
                t1[(i, j)]
            } else {
                t2[(i, j - bsz * p)]
            }
        });
        let m2a = Mat::from_fn(n, ka, |i, j| {
            if j < bsz * p {
                t1[(bsz * m + i, j)]
            } else {
                t2[(bsz * m + i, j - bsz * p)]
            }
        });
        BlockedRecursion {
            b: bsz,
            cin: p,
            cout: m,
            n,
            m1: m1a,
            m2: m2a,
            reverse: true,
        }
    }
}

/// Handles the degenerate shapes shared by both blocked operators; returns `true` when
/// nothing is left to do.
fn trivial_columns(
    in_ch: usize,
    out_ch: usize,
    len: usize,
    out: &mut MatMut<'_, f64>,
    accum: Accum,
) -> bool {
    if out.ncols() == 0 || out_ch == 0 || len == 0 {
        return true;
    }
    if in_ch == 0 {
        if let Accum::Replace = accum {
            out.fill(0.0);
        }
        return true;
    }
    false
}

impl LinearSystem for StateSpace {
    fn as_state_space(&self) -> Option<&StateSpace> {
        Some(self)
    }

    fn inputs(&self) -> usize {
        self.b.ncols()
    }

    fn outputs(&self) -> usize {
        self.c.nrows()
    }

    fn order(&self) -> usize {
        self.a.nrows()
    }

    fn apply(&self, u: &[f64], y: &mut [f64]) {
        let len = horizon(self.inputs(), self.outputs(), u.len(), y.len());
        let x0 = vec![0.0; self.order()];
        self.run(&x0, u, y, len, None);
    }

    fn apply_adjoint(&self, y: &[f64], u: &mut [f64]) {
        let (n, m, p) = (self.order(), self.inputs(), self.outputs());
        let len = horizon(m, p, u.len(), y.len());
        let RowMajor { a, b, c, d } = &self.rm;
        let mut s = vec![0.0; n];
        let mut sn = vec![0.0; n];
        for k in (0..len).rev() {
            let yk = &y[k * p..(k + 1) * p];
            let uk = &mut u[k * m..(k + 1) * m];
            // u_k = D^T y_k + B^T s_{k+1}
            uk.fill(0.0);
            add_transposed_product(d, yk, uk);
            if n == 0 {
                continue;
            }
            add_transposed_product(b, &s, uk);
            // s_k = A^T s_{k+1} + C^T y_k
            sn.fill(0.0);
            add_transposed_product(a, &s, &mut sn);
            add_transposed_product(c, yk, &mut sn);
            std::mem::swap(&mut s, &mut sn);
        }
    }

    /// Blocked recursion: time is split into blocks of `b` samples and, for block `k`
    /// with rows `X_k`, `Y_k = T_b X_k + Gamma S`, `S <- A^b S + R X_k`, each as one
    /// (SIMD) matrix product on the packed `[X_k; S]`; columns are split across faer's
    /// global thread pool (`faer::get_global_parallelism()`).
    fn apply_columns(&self, x: MatRef<'_, f64>, out: MatMut<'_, f64>, accum: Accum, alpha: f64) {
        self.columns(false, x, out, accum, alpha);
    }

    /// Blocked backward recursion with the transposed block matrices (costate `n x ncols`).
    fn apply_adjoint_columns(
        &self,
        x: MatRef<'_, f64>,
        out: MatMut<'_, f64>,
        accum: Accum,
        alpha: f64,
    ) {
        self.columns(true, x, out, accum, alpha);
    }
}

impl StateSpace {
    /// The forward (`adjoint = false`) or adjoint column application: the adjoint swaps the
    /// input and output channels and runs the transposed block matrices backwards in time.
    fn columns(
        &self,
        adjoint: bool,
        x: MatRef<'_, f64>,
        mut out: MatMut<'_, f64>,
        accum: Accum,
        alpha: f64,
    ) {
        let (n, m, p) = (self.order(), self.inputs(), self.outputs());
        assert_eq!(
            x.ncols(),
            out.ncols(),
            "x and out must have the same number of columns"
        );
        let (from, to) = if adjoint { (p, m) } else { (m, p) };
        let len = horizon(from, to, x.nrows(), out.nrows());
        if trivial_columns(from, to, len, &mut out, accum) {
            return;
        }
        if n == 0 {
            let d = to_faer(&self.d);
            let d = if adjoint {
                d.as_ref().transpose()
            } else {
                d.as_ref()
            };
            static_columns(d, len, x, out, accum, alpha);
        } else {
            self.blocked(len, adjoint).run(len, x, out, accum, alpha);
        }
    }
}

/// Refuses an index of `idx` at or beyond the `count` channels (`what`: input or output).
fn check_channels(idx: &[usize], count: usize, what: &str) -> Result<(), LtiError> {
    match idx.iter().find(|&&i| i >= count) {
        Some(&bad) => Err(LtiError::param(
            format!("{what} index"),
            format!("{bad} is out of range for a system with {count} {what}s"),
        )),
        None => Ok(()),
    }
}

/// `out = P·x + Q·u` for row-major `P` (`out.len()` × `x.len()`) and `Q` (`out.len()` ×
/// `u.len()`): one step of the state or output equation.
fn set_sum_of_products(p: &[f64], x: &[f64], q: &[f64], u: &[f64], out: &mut [f64]) {
    let (n, m) = (x.len(), u.len());
    for (i, o) in out.iter_mut().enumerate() {
        let prow = &p[i * n..(i + 1) * n];
        let qrow = &q[i * m..(i + 1) * m];
        let mut acc = 0.0;
        for (pj, xj) in prow.iter().zip(x) {
            acc += pj * xj;
        }
        for (qj, uj) in qrow.iter().zip(u) {
            acc += qj * uj;
        }
        *o = acc;
    }
}

/// `out += Mᵀ·v` for a row-major `M` with `v.len()` rows and `out.len()` columns.
fn add_transposed_product(mat: &[f64], v: &[f64], out: &mut [f64]) {
    let cols = out.len();
    for (i, &vi) in v.iter().enumerate() {
        let row = &mat[i * cols..(i + 1) * cols];
        for (o, r) in out.iter_mut().zip(row) {
            *o += r * vi;
        }
    }
}

/// A continuous-time state-space system `x' = A x + B u`, `y = C x + D u`.
#[derive(Clone, Debug, PartialEq)]
pub struct ContinuousStateSpace {
    a: DMatrix<f64>,
    b: DMatrix<f64>,
    c: DMatrix<f64>,
    d: DMatrix<f64>,
}

impl ContinuousStateSpace {
    /// Creates a validated continuous-time system (same shape and finiteness rules as
    /// [`StateSpace::new`]).
    ///
    /// ```
    /// use nalgebra::DMatrix;
    /// use structid_lti::ContinuousStateSpace;
    /// // x' = -x + u, y = x, sampled with a zero-order hold at ts = 0.1
    /// let sys = ContinuousStateSpace::new(
    ///     DMatrix::from_element(1, 1, -1.0),
    ///     DMatrix::from_element(1, 1, 1.0),
    ///     DMatrix::from_element(1, 1, 1.0),
    ///     DMatrix::zeros(1, 1),
    /// )
    /// .unwrap();
    /// let d = sys.discretize_zoh(0.1).unwrap();
    /// assert!((d.a()[(0, 0)] - (-0.1f64).exp()).abs() < 1e-14);
    /// assert_eq!(d.sample_time(), Some(0.1));
    /// ```
    pub fn new(
        a: DMatrix<f64>,
        b: DMatrix<f64>,
        c: DMatrix<f64>,
        d: DMatrix<f64>,
    ) -> Result<Self, LtiError> {
        validate(&a, &b, &c, &d)?;
        Ok(ContinuousStateSpace { a, b, c, d })
    }

    abcd_accessors!();

    /// Zero-order-hold discretisation with sample time `ts` (positive, finite):
    /// `exp([[A, B], [0, 0]] ts) = [[Ad, Bd], [0, I]]`; the result is `(Ad, Bd, C, D)` with
    /// sample time `ts`.
    pub fn discretize_zoh(&self, ts: f64) -> Result<StateSpace, LtiError> {
        check_sample_time(ts)?;
        let (n, m) = (self.order(), self.inputs());
        let (ad, bd) = if n == 0 {
            (DMatrix::zeros(0, 0), DMatrix::zeros(0, m))
        } else {
            let mut big = DMatrix::zeros(n + m, n + m);
            big.view_mut((0, 0), (n, n)).copy_from(&(&self.a * ts));
            big.view_mut((0, n), (n, m)).copy_from(&(&self.b * ts));
            let e = big.exp();
            (
                e.view((0, 0), (n, n)).into_owned(),
                e.view((0, n), (n, m)).into_owned(),
            )
        };
        check_matrix_finite("discretised A (matrix exponential overflow?)", &ad)?;
        check_matrix_finite("discretised B (matrix exponential overflow?)", &bd)?;
        StateSpace::new(ad, bd, self.c.clone(), self.d.clone())?.with_sample_time(ts)
    }
}
