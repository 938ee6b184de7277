//! One sample of a joint model, with or without its forward sensitivities.
//!
//! With ξ = [x; s] the stacked state and θ the parameters, one sample computes, blocks in
//! evaluation order,
//!
//! ```text
//!   z = C_z·x + D_zu·u + D_zw·w,   w_b = N_b(z_b; θ_b, s_b),   s_b⁺ = S_b(z_b; θ_b, s_b)
//!   y = C_y·x + D_yu·u + D_yw·w,   x⁺ = A·x + B_u·u + B_w·w
//! ```
//!
//! and the tangent step propagates T = ∂ξ/∂(θ, ξ₀) through the same equations (forward
//! sensitivities): every product M·v contributes M·∂v plus, when an entry (r, c) of M is a free
//! parameter, v_c in row r of that parameter's column. Applying G by this recursion keeps the
//! cost of a sensitivity pass at O(L·n_ξ·P) for P tracked columns.

use structid_core::{Signal, Simulation};

use crate::block::BlockJacobian;
use crate::error::{JointError, Result};
use crate::model::{JointModel, LftMatrix};

/// A matrix stored row-major for the per-sample products.
#[derive(Clone, Debug)]
struct Rows {
    cols: usize,
    v: Vec<f64>,
}

impl Rows {
    fn new(m: &nalgebra::DMatrix<f64>) -> Self {
        let mut v = Vec::with_capacity(m.len());
        for i in 0..m.nrows() {
            v.extend((0..m.ncols()).map(|j| m[(i, j)]));
        }
        Self { cols: m.ncols(), v }
    }

    fn row(&self, i: usize) -> &[f64] {
        &self.v[i * self.cols..(i + 1) * self.cols]
    }

    /// out += M·x.
    fn mul_add(&self, x: &[f64], out: &mut [f64]) {
        if self.cols == 0 {
            return;
        }
        for (o, r) in out.iter_mut().zip(self.v.chunks_exact(self.cols)) {
            *o += r.iter().zip(x).map(|(a, b)| a * b).sum::<f64>();
        }
    }

    /// out (rows × p) += M·T for T (cols × p), both row-major.
    fn mul_add_tangent(&self, t: &[f64], p: usize, out: &mut [f64]) {
        if self.cols == 0 || p == 0 {
            return;
        }
        for (o, r) in out.chunks_exact_mut(p).zip(self.v.chunks_exact(self.cols)) {
            for (&a, trow) in r.iter().zip(t.chunks_exact(p)) {
                if a != 0.0 {
                    o.iter_mut().zip(trow).for_each(|(o, t)| *o += a * t);
                }
            }
        }
    }
}

/// The free entries of one matrix: (row, column, parameter column).
type Free = Vec<(usize, usize, usize)>;

/// A joint model prepared for stepping.
pub(crate) struct Stepper<'a> {
    model: &'a JointModel,
    m: [Rows; 9],
    /// B_e, D_ye, D_ze: only a simulation with noise uses them.
    noise: [Rows; 3],
    free: [Free; 9],
    /// Where each block's state starts in ξ.
    state_at: Vec<usize>,
    /// Where each block's parameters start in θ.
    param_at: Vec<usize>,
    n: usize,
    nz: usize,
    nw: usize,
    ny: usize,
    series: bool,
}

/// Scratch buffers of one run.
struct Scratch {
    z: Vec<f64>,
    w: Vec<f64>,
    arg: Vec<f64>,
    xn: Vec<f64>,
    jac: Vec<BlockJacobian>,
    // Tangent buffers (rows × P).
    dz: Vec<f64>,
    dw: Vec<f64>,
    dxn: Vec<f64>,
    dargs: Vec<f64>,
    ds: Vec<f64>,
}

impl<'a> Stepper<'a> {
    pub(crate) fn new(model: &'a JointModel) -> Self {
        let lm = model.lft().matrices();
        let d = model.lft().dims();
        let m = LftMatrix::ALL.map(|k| Rows::new(k.of(lm)));
        let mut free: [Free; 9] = Default::default();
        for (j, e) in model.free_entries().iter().enumerate() {
            let k = LftMatrix::ALL
                .iter()
                .position(|m| *m == e.matrix)
                .expect("listed");
            free[k].push((e.row, e.col, j));
        }
        let mut state_at = vec![d.states];
        for b in model.blocks() {
            state_at.push(state_at.last().expect("non-empty") + b.map.state_len());
        }
        Self {
            model,
            series: lm.dzw.iter().any(|v| *v != 0.0),
            m,
            noise: [Rows::new(&lm.be), Rows::new(&lm.dye), Rows::new(&lm.dze)],
            free,
            state_at,
            param_at: model.parameter_offsets(),
            n: d.states,
            nz: d.z,
            nw: d.w,
            ny: d.y,
        }
    }

    pub(crate) fn stacked_len(&self) -> usize {
        *self.state_at.last().expect("non-empty")
    }

    pub(crate) fn outputs(&self) -> usize {
        self.ny
    }

    fn scratch(&self, p: usize) -> Scratch {
        Scratch {
            z: vec![0.0; self.nz],
            w: vec![0.0; self.nw],
            arg: Vec::new(),
            xn: vec![0.0; self.n],
            jac: self
                .model
                .blocks()
                .iter()
                .map(|b| BlockJacobian::for_map(b.map.as_ref()))
                .collect(),
            dz: vec![0.0; self.nz * p],
            dw: vec![0.0; self.nw * p],
            dxn: vec![0.0; self.n * p],
            dargs: Vec::new(),
            ds: Vec::new(),
        }
    }

    /// The stacked state at rest: x₀ and each block's rest state at its input.
    pub(crate) fn rest_state(&self, u0: &[f64], x0: &[f64]) -> Result<Vec<f64>> {
        let mut xi = vec![0.0; self.stacked_len()];
        xi[..self.n].copy_from_slice(x0);
        let mut sc = self.scratch(0);
        self.base_z(&xi[..self.n], u0, &mut sc.z);
        for &b in self.model.evaluation_order() {
            let block = &self.model.blocks()[b];
            self.block_arg(b, &sc.z, &sc.w, &mut sc.arg);
            let s = &mut xi[self.state_at[b]..self.state_at[b + 1]];
            block.map.initial_state(&sc.arg, s);
            let mut copy = s.to_vec();
            sc.w[block.output] = block.map.eval(&mut copy, &sc.arg);
        }
        Ok(xi)
    }

    fn base_z(&self, x: &[f64], u: &[f64], z: &mut [f64]) {
        z.iter_mut().for_each(|v| *v = 0.0);
        self.m[6].mul_add(x, z);
        self.m[7].mul_add(u, z);
    }

    /// The inputs of block `b`: its z rows plus what D_zw adds from the w's written so far.
    fn block_arg(&self, b: usize, z: &[f64], w: &[f64], arg: &mut Vec<f64>) {
        arg.clear();
        for &i in &self.model.blocks()[b].inputs {
            let through_w = if self.series {
                self.m[8].row(i).iter().zip(w).map(|(a, b)| a * b).sum()
            } else {
                0.0
            };
            arg.push(z[i] + through_w);
        }
    }

    /// One sample without tangents: writes y, advances ξ; `false` when a value is not finite.
    fn step(&self, xi: &mut [f64], u: &[f64], y: &mut [f64], sc: &mut Scratch) -> bool {
        self.step_noisy(xi, u, None, y, sc)
    }

    /// [`Self::step`] with the noise e_k entering through B_e, D_ye and D_ze.
    fn step_noisy(
        &self,
        xi: &mut [f64],
        u: &[f64],
        e: Option<&[f64]>,
        y: &mut [f64],
        sc: &mut Scratch,
    ) -> bool {
        let n = self.n;
        self.base_z(&xi[..n], u, &mut sc.z);
        if let Some(e) = e {
            self.noise[2].mul_add(e, &mut sc.z);
        }
        sc.w.iter_mut().for_each(|v| *v = 0.0);
        for &b in self.model.evaluation_order() {
            let block = &self.model.blocks()[b];
            self.block_arg(b, &sc.z, &sc.w, &mut sc.arg);
            let s = &mut xi[self.state_at[b]..self.state_at[b + 1]];
            sc.w[block.output] = block.map.eval(s, &sc.arg);
        }
        y.iter_mut().for_each(|v| *v = 0.0);
        let x = &xi[..n];
        self.m[3].mul_add(x, y);
        self.m[4].mul_add(u, y);
        self.m[5].mul_add(&sc.w, y);
        sc.xn.iter_mut().for_each(|v| *v = 0.0);
        self.m[0].mul_add(x, &mut sc.xn);
        self.m[1].mul_add(u, &mut sc.xn);
        self.m[2].mul_add(&sc.w, &mut sc.xn);
        if let Some(e) = e {
            self.noise[1].mul_add(e, y);
            self.noise[0].mul_add(e, &mut sc.xn);
        }
        xi[..n].copy_from_slice(&sc.xn);
        sc.w.iter().all(|v| v.is_finite()) && xi.iter().all(|v| v.is_finite())
    }

    /// Adds the free entries' explicit terms of matrix `k` applied to `v` into `out` (rows × p).
    fn explicit(&self, k: usize, v: &[f64], p: usize, out: &mut [f64]) {
        for &(r, c, j) in &self.free[k] {
            out[r * p + j] += v[c];
        }
    }

    /// One sample with tangents: `t` is ∂ξ/∂(columns) (n_ξ × p, row-major) before the sample
    /// and after it; `dy` receives ∂y/∂(columns) (n_y × p).
    fn step_tangent(
        &self,
        xi: &mut [f64],
        t: &mut [f64],
        p: usize,
        u: &[f64],
        y: &mut [f64],
        dy: &mut [f64],
        sc: &mut Scratch,
    ) -> bool {
        let n = self.n;
        self.base_z(&xi[..n], u, &mut sc.z);
        sc.dz.iter_mut().for_each(|v| *v = 0.0);
        self.m[6].mul_add_tangent(&t[..n * p], p, &mut sc.dz);
        self.explicit(6, &xi[..n], p, &mut sc.dz);
        self.explicit(7, u, p, &mut sc.dz);
        sc.w.iter_mut().for_each(|v| *v = 0.0);
        sc.dw.iter_mut().for_each(|v| *v = 0.0);
        for &b in self.model.evaluation_order() {
            if !self.block_tangent(b, xi, t, p, sc) {
                return false;
            }
        }
        let x = &xi[..n];
        y.iter_mut().for_each(|v| *v = 0.0);
        self.m[3].mul_add(x, y);
        self.m[4].mul_add(u, y);
        self.m[5].mul_add(&sc.w, y);
        dy.iter_mut().for_each(|v| *v = 0.0);
        self.m[3].mul_add_tangent(&t[..n * p], p, dy);
        self.m[5].mul_add_tangent(&sc.dw, p, dy);
        self.explicit(3, x, p, dy);
        self.explicit(4, u, p, dy);
        self.explicit(5, &sc.w, p, dy);
        sc.xn.iter_mut().for_each(|v| *v = 0.0);
        self.m[0].mul_add(x, &mut sc.xn);
        self.m[1].mul_add(u, &mut sc.xn);
        self.m[2].mul_add(&sc.w, &mut sc.xn);
        sc.dxn.iter_mut().for_each(|v| *v = 0.0);
        self.m[0].mul_add_tangent(&t[..n * p], p, &mut sc.dxn);
        self.m[2].mul_add_tangent(&sc.dw, p, &mut sc.dxn);
        self.explicit(0, x, p, &mut sc.dxn);
        self.explicit(1, u, p, &mut sc.dxn);
        self.explicit(2, &sc.w, p, &mut sc.dxn);
        xi[..n].copy_from_slice(&sc.xn);
        t[..n * p].copy_from_slice(&sc.dxn);
        sc.w.iter().all(|v| v.is_finite()) && xi.iter().all(|v| v.is_finite())
    }

    /// Block `b`'s output and state with their tangents, within [`Self::step_tangent`].
    fn block_tangent(
        &self,
        b: usize,
        xi: &mut [f64],
        t: &mut [f64],
        p: usize,
        sc: &mut Scratch,
    ) -> bool {
        let block = &self.model.blocks()[b];
        let (s0, s1) = (self.state_at[b], self.state_at[b + 1]);
        let ns = s1 - s0;
        let pin = block.inputs.len();
        self.block_arg(b, &sc.z, &sc.w, &mut sc.arg);
        // ∂(inputs) = ∂z rows + D_zw·∂w + the free D_zw entries' w terms.
        sc.dargs.clear();
        sc.dargs.resize(pin * p, 0.0);
        for (a, &i) in block.inputs.iter().enumerate() {
            let row = &mut sc.dargs[a * p..(a + 1) * p];
            row.copy_from_slice(&sc.dz[i * p..(i + 1) * p]);
            if self.series {
                for (c, &dzw) in self.m[8].row(i).iter().enumerate() {
                    if dzw != 0.0 {
                        row.iter_mut()
                            .zip(&sc.dw[c * p..(c + 1) * p])
                            .for_each(|(r, d)| *r += dzw * d);
                    }
                }
            }
            for &(r, c, j) in &self.free[8] {
                if r == i {
                    row[j] += sc.w[c];
                }
            }
        }
        let jac = &mut sc.jac[b];
        let w = block.map.eval_jacobian(&mut xi[s0..s1], &sc.arg, jac);
        if !w.is_finite() {
            return false;
        }
        sc.w[block.output] = w;
        let pa = self.param_at[b];
        let out = &mut sc.dw[block.output * p..(block.output + 1) * p];
        for (a, &g) in jac.dw_dz.iter().enumerate() {
            out.iter_mut()
                .zip(&sc.dargs[a * p..(a + 1) * p])
                .for_each(|(o, d)| *o += g * d);
        }
        for (s, &g) in jac.dw_ds.iter().enumerate() {
            out.iter_mut()
                .zip(&t[(s0 + s) * p..(s0 + s + 1) * p])
                .for_each(|(o, d)| *o += g * d);
        }
        for (q, &g) in jac.dw_dp.iter().enumerate() {
            out[pa + q] += g;
        }
        if ns > 0 {
            let np = jac.dw_dp.len();
            sc.ds.clear();
            sc.ds.resize(ns * p, 0.0);
            for r in 0..ns {
                let row = &mut sc.ds[r * p..(r + 1) * p];
                for s in 0..ns {
                    let g = jac.ds_ds[r * ns + s];
                    row.iter_mut()
                        .zip(&t[(s0 + s) * p..(s0 + s + 1) * p])
                        .for_each(|(o, d)| *o += g * d);
                }
                for a in 0..pin {
                    let g = jac.ds_dz[r * pin + a];
                    row.iter_mut()
                        .zip(&sc.dargs[a * p..(a + 1) * p])
                        .for_each(|(o, d)| *o += g * d);
                }
                for q in 0..np {
                    row[pa + q] += jac.ds_dp[r * np + q];
                }
            }
            t[s0 * p..s1 * p].copy_from_slice(&sc.ds);
        }
        true
    }

    /// Runs samples `range` of `u` from ξ (advanced in place), calling `emit(k, y)` per sample.
    /// `None` when the run stops being finite.
    pub(crate) fn run(
        &self,
        u: &Signal,
        range: std::ops::Range<usize>,
        xi: &mut [f64],
        mut emit: impl FnMut(usize, &[f64]),
    ) -> Option<()> {
        let mut sc = self.scratch(0);
        let mut y = vec![0.0; self.ny];
        for k in range {
            if !self.step(xi, u.sample(k), &mut y, &mut sc) {
                return None;
            }
            emit(k, &y);
        }
        Some(())
    }

    /// As [`Self::run`] with tangents `t` (n_ξ × p, advanced in place); `emit(k, y, dy)`.
    pub(crate) fn run_tangent(
        &self,
        u: &Signal,
        range: std::ops::Range<usize>,
        xi: &mut [f64],
        t: &mut [f64],
        p: usize,
        mut emit: impl FnMut(usize, &[f64], &[f64]),
    ) -> Option<()> {
        let mut sc = self.scratch(p);
        let mut y = vec![0.0; self.ny];
        let mut dy = vec![0.0; self.ny * p];
        for k in range {
            if !self.step_tangent(xi, t, p, u.sample(k), &mut y, &mut dy, &mut sc) {
                return None;
            }
            emit(k, &y, &dy);
        }
        Some(())
    }

    /// A whole simulation, with z and w recorded; `e` (when given) enters through B_e, D_ye
    /// and D_ze.
    pub(crate) fn simulate(
        &self,
        u: &Signal,
        e: Option<&Signal>,
        xi0: &[f64],
    ) -> Result<Simulation> {
        let len = u.len();
        let (mut ys, mut zs, mut ws) = (
            Signal::zeros(len, self.ny),
            Signal::zeros(len, self.nz),
            Signal::zeros(len, self.nw),
        );
        let mut xi = xi0.to_vec();
        let mut sc = self.scratch(0);
        for k in 0..len {
            let x = xi[..self.n].to_vec();
            let mut y = vec![0.0; self.ny];
            let ek = e.map(|e| e.sample(k));
            if !self.step_noisy(&mut xi, u.sample(k), ek, &mut y, &mut sc) {
                return Err(JointError::Core(structid_core::Error::Unstable(format!(
                    "the simulation diverged: a state or a block output became non-finite at sample {k}"
                ))));
            }
            ys.sample_mut(k).copy_from_slice(&y);
            ws.sample_mut(k).copy_from_slice(&sc.w);
            let z = zs.sample_mut(k);
            self.base_z(&x, u.sample(k), z);
            self.m[8].mul_add(&sc.w, z);
            if let Some(ek) = ek {
                self.noise[2].mul_add(ek, z);
            }
        }
        Ok(Simulation {
            y: ys,
            z: zs,
            w: ws,
            final_state: xi,
        })
    }
}

/// Simulation of the joint model: the stepper run from a stacked initial state.
impl JointModel {
    /// The stacked initial state ξ₀ = [x₀; each block's rest state at the first sample's
    /// input]: x₀ given (zero by default), block states at rest. Blocks read z at rest from
    /// x₀ and u₀ in evaluation order.
    pub fn rest_state(&self, u0: &[f64], x0: Option<&[f64]>) -> Result<Vec<f64>> {
        let n = self.lft().dims().states;
        let x0 = match x0 {
            Some(x) if x.len() != n => {
                return Err(JointError::InvalidModel(format!(
                    "the initial state has {} entries, the LFT has {n} states",
                    x.len()
                )));
            }
            Some(x) => x.to_vec(),
            None => vec![0.0; n],
        };
        Stepper::new(self).rest_state(u0, &x0)
    }

    /// Simulates the model from u alone, with the stacked initial state `xi0` (default: the
    /// zero state, blocks at rest). `Simulation::final_state` is the stacked state.
    pub fn simulate(&self, u: &Signal, xi0: Option<&[f64]>) -> Result<Simulation> {
        self.simulate_noisy(u, None, xi0)
    }

    /// [`JointModel::simulate`] with the noise `e` (L × n_e) entering through B_e, D_ye and D_ze.
    pub fn simulate_noisy(
        &self,
        u: &Signal,
        e: Option<&Signal>,
        xi0: Option<&[f64]>,
    ) -> Result<Simulation> {
        let d = self.lft().dims();
        if let Some(e) = e
            && (e.len() != u.len() || e.channels() != d.e)
        {
            return Err(JointError::InvalidModel(format!(
                "the noise has {} samples × {} channels; the input {} samples and the LFT {} noise channels",
                e.len(),
                e.channels(),
                u.len(),
                d.e
            )));
        }
        let d = self.lft().dims();
        if u.channels() != d.u {
            return Err(JointError::InvalidModel(format!(
                "u has {} channel(s), the LFT {}",
                u.channels(),
                d.u
            )));
        }
        if u.is_empty() {
            return Err(JointError::InvalidModel("u has no samples".into()));
        }
        let xi0 = match xi0 {
            Some(x) if x.len() != self.stacked_state_len() => {
                return Err(JointError::InvalidModel(format!(
                    "the stacked initial state has {} entries, the model {}",
                    x.len(),
                    self.stacked_state_len()
                )));
            }
            Some(x) => x.to_vec(),
            None => self.rest_state(u.sample(0), None)?,
        };
        Stepper::new(self).simulate(u, e, &xi0)
    }
}
