//! The entry point shared by the fuzz target `lft_problem` (`fuzz/fuzz_targets/lft_problem.rs`,
//! which includes this file) and the stable-toolchain harness `tests/random_matrices.rs`.
//!
//! [`lft_and_problem`] decodes arbitrary bytes into small dimensions and f64 entries (NaN,
//! ±∞, ±`f64::MAX`, subnormals and raw bit patterns among them), builds an [`Lft`] and a
//! [`Problem`] from them and drives what follows construction: the sub-systems, measurability,
//! z and the residual, simulation, the model, `Problem::from_model` and a tiny
//! identification. Errors are expected and collected; only a panic (or a hang) is a failure.

#![allow(dead_code)]

use std::sync::Arc;

use nalgebra::DMatrix;
use structid_core::{
    Data, Dispersion, IdentifySettings, KernelDispersion, Lft, LftMatrices, MapBinding, Model,
    NonlinearBlock, PolynomialDispersion, Problem, ProblemBlock, identify_problem,
};
use structid_lti::{LinearSystem, Signal, StateSpace};

/// Largest state dimension decoded.
pub const MAX_STATES: usize = 4;
/// Largest signal dimension (u, e, w, y, z) decoded.
pub const MAX_CHANNELS: usize = 3;
/// Largest record length decoded.
pub const MAX_SAMPLES: usize = 8;

/// Reads the fuzz bytes in order; past the end every read gives 0.
///
/// The first byte chooses the mode: one input in four is *wild* (non-finite and extreme
/// entries are common, and matrix shapes are sometimes off by one), the others are *tame*
/// (finite entries of moderate size with an occasional huge one, consistent shapes), so that
/// construction succeeds often enough for the paths behind it to be reached.
pub struct Decoder<'a> {
    bytes: &'a [u8],
    at: usize,
    wild: bool,
}

impl<'a> Decoder<'a> {
    /// A decoder over `bytes`.
    pub fn new(bytes: &'a [u8]) -> Self {
        let mut d = Self {
            bytes,
            at: 0,
            wild: false,
        };
        d.wild = d.byte().is_multiple_of(4);
        d
    }

    /// The next byte (0 past the end).
    pub fn byte(&mut self) -> u8 {
        let b = self.bytes.get(self.at).copied().unwrap_or(0);
        self.at += 1;
        b
    }

    /// A number in `0..n` (`n` > 0).
    pub fn below(&mut self, n: usize) -> usize {
        usize::from(self.byte()) % n
    }

    /// A structural glitch (a wrong length, a repeated block output): one chance in four in
    /// wild mode, never in tame mode (the byte is read either way).
    pub fn glitch(&mut self) -> bool {
        let b = self.byte();
        self.wild && b.is_multiple_of(4)
    }

    /// One chance in `n` (`n` > 0).
    pub fn one_in(&mut self, n: u8) -> bool {
        self.byte().is_multiple_of(n)
    }

    /// An f64. Wild: often a special value (0, ±1, NaN, ±∞, ±`f64::MAX`, the smallest normal,
    /// a subnormal, ±1e±300) or a raw bit pattern. Tame: a small multiple of 1/16, 0, ±1, and
    /// one time in 64 a huge finite value.
    pub fn f64(&mut self) -> f64 {
        if !self.wild {
            return match self.byte() % 64 {
                0 => 1e300,
                1..=4 => 0.0,
                5..=8 => 1.0,
                9..=10 => -1.0,
                _ => self.moderate(),
            };
        }
        match self.byte() % 16 {
            0 => 0.0,
            1 => 1.0,
            2 => -1.0,
            3 => f64::NAN,
            4 => f64::INFINITY,
            5 => f64::NEG_INFINITY,
            6 => f64::MAX,
            7 => f64::MIN,
            8 => f64::MIN_POSITIVE,
            9 => 4.9e-324,
            10 => 1e300,
            11 => -1e-300,
            12 | 13 => {
                let mut raw = [0u8; 8];
                raw.iter_mut().for_each(|b| *b = self.byte());
                f64::from_le_bytes(raw)
            }
            _ => self.moderate(),
        }
    }

    /// A finite f64 of moderate size (data samples that the validated paths accept).
    pub fn moderate(&mut self) -> f64 {
        f64::from(self.byte() as i8) / 16.0
    }

    /// A `rows × cols` matrix of [`Decoder::f64`] entries; in wild mode one time in four a
    /// dimension is off by one, so that shape checks are exercised too.
    pub fn matrix(&mut self, rows: usize, cols: usize) -> DMatrix<f64> {
        let shape = if self.wild { self.byte() % 16 } else { 15 };
        let (rows, cols) = match shape {
            0 => (rows + 1, cols),
            1 => (rows.saturating_sub(1), cols),
            2 => (rows, cols + 1),
            3 => (rows, cols.saturating_sub(1)),
            _ => (rows, cols),
        };
        DMatrix::from_fn(rows, cols, |_, _| self.f64())
    }

    /// A signal of `len` samples and `channels` channels: moderate values when `finite` or in
    /// tame mode, [`Decoder::f64`] values otherwise.
    pub fn signal(&mut self, len: usize, channels: usize, finite: bool) -> Signal {
        if finite || !self.wild {
            Signal::from_fn(len, channels, |_, _| self.moderate())
        } else {
            Signal::from_fn(len, channels, |_, _| self.f64())
        }
    }
}

/// What [`lft_and_problem`] reached: how far construction went, and the messages of every
/// error met (each of which must be non-empty).
#[derive(Debug, Default)]
pub struct Outcome {
    /// `Lft::new` accepted the decoded matrices.
    pub lft: bool,
    /// `Problem::new` accepted the decoded operators.
    pub problem: bool,
    /// Identifications that ran to the end.
    pub solved: usize,
    /// Displayed error messages.
    pub errors: Vec<String>,
}

/// Builds an [`Lft`] and a [`Problem`] from `bytes` and drives everything downstream of
/// their construction.
pub fn lft_and_problem(bytes: &[u8]) -> Outcome {
    let mut d = Decoder::new(bytes);
    let mut out = Outcome::default();
    lft_part(&mut d, &mut out);
    problem_part(&mut d, &mut out);
    out
}

fn record<T>(out: &mut Outcome, r: Result<T, structid_core::Error>) -> Option<T> {
    match r {
        Ok(v) => Some(v),
        Err(e) => {
            out.errors.push(e.to_string());
            None
        }
    }
}

fn lft_part(d: &mut Decoder<'_>, out: &mut Outcome) {
    let n = d.below(MAX_STATES + 1);
    let nu = d.below(MAX_CHANNELS + 1);
    let ne = d.below(MAX_CHANNELS + 1);
    let nw = d.below(MAX_CHANNELS + 1);
    let ny = d.below(MAX_CHANNELS + 1);
    let nz = d.below(MAX_CHANNELS + 1);
    let m = LftMatrices {
        a: d.matrix(n, n),
        bu: d.matrix(n, nu),
        be: d.matrix(n, ne),
        bw: d.matrix(n, nw),
        cy: d.matrix(ny, n),
        dyu: d.matrix(ny, nu),
        dye: d.matrix(ny, ne),
        dyw: d.matrix(ny, nw),
        cz: d.matrix(nz, n),
        dzu: d.matrix(nz, nu),
        dze: d.matrix(nz, ne),
        dzw: d.matrix(nz, nw),
    };
    let Some(lft) = record(out, Lft::new(m)) else {
        return;
    };
    out.lft = true;
    let dims = lft.dims();
    let _ = lft.state_space();
    let _ = (lft.t_yu(), lft.t_ye(), lft.t_yw(), lft.t_zu());
    for c in 0..dims.w {
        let _ = lft.t_yw_channel(c);
    }
    let ts = d.f64();
    record(out, lft.clone().with_sample_time(ts));
    record(out, lft.check_no_algebraic_loop());
    record(out, lft.measurability());

    let len = 1 + d.below(MAX_SAMPLES);
    let finite = !d.one_in(4);
    let u = d.signal(len, dims.u, finite);
    let y = d.signal(len, dims.y, finite);
    record(out, lft.residual(&u, &y));
    record(out, lft.compute_z(&u, &y));

    // Simulation with a saturation in every w channel (when z exists to feed it).
    if dims.z > 0 {
        let sat = |z: &[f64]| z[0].clamp(-1.0, 1.0);
        let inputs: Vec<[usize; 1]> = (0..dims.w).map(|c| [c % dims.z]).collect();
        let maps: Vec<MapBinding<'_>> = inputs
            .iter()
            .enumerate()
            .map(|(c, i)| MapBinding {
                inputs: i,
                output: c,
                map: &sat,
            })
            .collect();
        let e = d.signal(len, dims.e, finite);
        record(out, lft.simulate(&maps, &u, Some(&e), None));
    }

    // The model: one block per w channel, reading a z channel chosen by the bytes.
    let blocks: Vec<NonlinearBlock> = (0..dims.w)
        .map(|c| {
            let input = d.below(MAX_CHANNELS + 1);
            let dispersion: Arc<dyn Dispersion> = if d.one_in(2) {
                Arc::new(KernelDispersion::gaussian(0.5).expect("σ = 0.5 is valid"))
            } else {
                Arc::new(
                    PolynomialDispersion::new(1 + d.below(3)).expect("a small degree is valid"),
                )
            };
            NonlinearBlock::new(format!("n{c}"), vec![input], c, dispersion)
        })
        .collect();
    let Some(model) = record(out, Model::new(lft, blocks)) else {
        return;
    };
    let Some(data) = record(out, Data::new(u, y)) else {
        return;
    };
    if let Some(p) = record(out, Problem::from_model(&model, &data)) {
        out.solved += solve(d, &p, out);
    }
    if let Some(p) = record(out, Problem::from_model_with_initial_state(&model, &data)) {
        out.solved += solve(d, &p, out);
    }
}

fn solve(d: &mut Decoder<'_>, p: &Problem, out: &mut Outcome) -> usize {
    if !d.one_in(2) {
        return 0;
    }
    let beta = if d.one_in(4) { d.f64() } else { 0.1 };
    let settings = IdentifySettings::builder().beta(beta).build();
    if let Some(settings) = record(out, settings)
        && let Some(id) = record(out, identify_problem(p, &settings))
    {
        for b in &id.blocks {
            let z: Vec<f64> = (0..b.z.channels()).map(|_| d.f64()).collect();
            let _ = b.predict(&z);
            let _ = b.map.eval_many(&b.z);
        }
        return 1;
    }
    0
}

fn state_space(
    d: &mut Decoder<'_>,
    inputs: usize,
    outputs: usize,
    out: &mut Outcome,
) -> Option<StateSpace> {
    let n = d.below(MAX_STATES + 1);
    let sys = StateSpace::new(
        d.matrix(n, n),
        d.matrix(n, inputs),
        d.matrix(outputs, n),
        d.matrix(outputs, inputs),
    );
    match sys {
        Ok(s) => Some(s),
        Err(e) => {
            out.errors.push(e.to_string());
            None
        }
    }
}

fn problem_part(d: &mut Decoder<'_>, out: &mut Outcome) {
    let len = d.below(MAX_SAMPLES + 1);
    let ny = d.below(MAX_CHANNELS + 1);
    let ne = d.below(MAX_CHANNELS + 1);
    let finite = !d.one_in(4);
    let residual = d.signal(len, ny, finite);
    let noise_outputs = if d.glitch() { ny + 1 } else { ny };
    let Some(noise) = state_space(d, ne, noise_outputs, out) else {
        return;
    };
    let count = d.below(MAX_CHANNELS + 1);
    let mut blocks = Vec::with_capacity(count);
    for i in 0..count {
        let output = if d.glitch() { d.below(5) } else { i };
        let path_inputs = if d.glitch() { 2 } else { 1 };
        let Some(path) = state_space(d, path_inputs, ny, out) else {
            return;
        };
        let z_len = if d.glitch() { len + 1 } else { len };
        let p = 1 + d.below(2);
        let z = d.signal(z_len, p, finite);
        let sigma = if d.one_in(4) { d.f64() } else { 0.5 };
        let Some(kernel) = record(out, KernelDispersion::gaussian(sigma)) else {
            return;
        };
        blocks.push(ProblemBlock {
            name: format!("b{i}"),
            output,
            path: Arc::new(path) as Arc<dyn LinearSystem>,
            z,
            dispersion: Arc::new(kernel),
        });
    }
    let Some(problem) = record(out, Problem::new(residual, Arc::new(noise), blocks)) else {
        return;
    };
    out.problem = true;
    let _ = (problem.len(), problem.outputs(), problem.is_empty());
    let rows = problem.len() * problem.outputs();
    let mask_len = if d.glitch() { rows + 1 } else { rows };
    let mask: Vec<bool> = (0..mask_len).map(|_| d.one_in(3)).collect();
    if let Some(p) = record(out, problem.clone().with_held_out(mask)) {
        out.solved += solve(d, &p, out);
    }
    let o_rows = if d.glitch() { rows + 1 } else { rows };
    let o_cols = d.below(3);
    let o = faer::Mat::<f64>::from_fn(o_rows, o_cols, |_, _| d.moderate());
    if let Some(p) = record(out, problem.clone().with_free_response(o)) {
        out.solved += solve(d, &p, out);
    }
    out.solved += solve(d, &problem, out);
}
