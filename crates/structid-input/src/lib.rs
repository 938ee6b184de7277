//! # structid-input: input signals for identification experiments
//!
//! The excitation decides what an experiment can reveal: the band it covers, the amplitudes
//! it visits and how long it dwells there. [`generate`] designs one input of a [`Design`]
//! (length, sample time, amplitude, offset, band, seed) and a [`Kind`]:
//!
//! * [`Kind::Prbs`]: a maximum-length pseudo-random binary sequence (period 2ⁿ − 1 bits,
//!   levels offset ± amplitude, one more high bit than low per period), each bit held for
//!   `clock` samples; the band's upper edge sets the clock when the clock is not given.
//! * [`Kind::Multisine`]: a periodic sum of sines of equal amplitude on the harmonics of the
//!   period that lie in the band (all, odd only, or chosen lines), with random phases and,
//!   optionally, phases that minimise the crest factor; no energy elsewhere.
//! * [`Kind::Noise`]: Gaussian noise with its spectrum cut to the band (the DFT of the
//!   record is zero outside it), scaled to an RMS of the amplitude.
//! * [`Kind::Chirp`]: a linear or logarithmic frequency sweep across the band.
//! * [`Kind::Steps`]: random levels in offset ± amplitude held for random times between
//!   two bounds: the amplitude-rich input of static nonlinearities.
//!
//! Everything is deterministic given the seed (the generator is this crate's own, so the
//! signals do not change with a dependency's version). Bad arguments give an
//! [`InputError`] that names the argument.
//!
//! ```
//! use structid_input::{generate, Design, Kind};
//! let design = Design { length: 1023, ..Design::default() };
//! let u = generate(&design, &Kind::Prbs { order: Some(10), clock: None }).unwrap();
//! assert_eq!(u.len(), 1023);
//! // A maximum-length sequence of order 10: 512 high and 511 low bits per period.
//! assert_eq!(u.iter().filter(|&&v| v == 1.0).count(), 512);
//! assert_eq!(u.iter().filter(|&&v| v == -1.0).count(), 511);
//! ```

use std::f64::consts::PI;

use rustfft::FftPlanner;
use rustfft::num_complex::Complex;

/// The longest signal [`generate`] designs (10⁷ samples).
pub const MAX_LENGTH: usize = 10_000_000;

/// Everything that can be wrong with the arguments of a design.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum InputError {
    /// An argument out of its range; the message names it and says what is allowed.
    #[error("invalid {argument}: {message}")]
    Invalid {
        /// The argument (`length`, `band`, `order`, …).
        argument: &'static str,
        /// What is wrong and what is allowed.
        message: String,
    },
}

fn invalid(argument: &'static str, message: impl Into<String>) -> InputError {
    InputError::Invalid {
        argument,
        message: message.into(),
    }
}

/// What every input shares: length, sample time, level and band.
///
/// ```
/// use structid_input::Design;
/// // 10 s at 100 Hz around 2.0 ± 0.5, excited from 1 to 20 Hz.
/// let d = Design { length: 1000, sample_time: 0.01, amplitude: 0.5, offset: 2.0,
///                  band: Some((1.0, 20.0)), seed: 3 };
/// assert_eq!(d.nyquist(), 50.0);
/// assert_eq!(d.band().unwrap(), (1.0, 20.0));
/// assert!(d.check().is_ok());
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct Design {
    /// Number of samples (1 ≤ length ≤ [`MAX_LENGTH`]).
    pub length: usize,
    /// Sample time in seconds (> 0); frequencies are in Hz, up to the Nyquist frequency
    /// 1 / (2 · sample time).
    pub sample_time: f64,
    /// Amplitude (> 0): the level ± amplitude of PRBS and steps, the peak of multisines and
    /// chirps, the RMS of noise.
    pub amplitude: f64,
    /// The level the signal varies around.
    pub offset: f64,
    /// The band `(low, high)` in Hz, `0 ≤ low < high ≤` Nyquist; `None` for the whole band.
    pub band: Option<(f64, f64)>,
    /// Seed of the random choices (phases, noise, levels, hold times, the PRBS start).
    pub seed: u64,
}

impl Default for Design {
    /// 1000 samples of 1 s, amplitude 1 around 0, the whole band, seed 1.
    fn default() -> Self {
        Self {
            length: 1000,
            sample_time: 1.0,
            amplitude: 1.0,
            offset: 0.0,
            band: None,
            seed: 1,
        }
    }
}

impl Design {
    /// The Nyquist frequency 1 / (2 · sample time), in Hz.
    pub fn nyquist(&self) -> f64 {
        0.5 / self.sample_time
    }

    /// The band in Hz, checked (the whole band `(0, Nyquist)` without one).
    ///
    /// ```
    /// use structid_input::Design;
    /// let d = Design { sample_time: 0.01, band: Some((1.0, 60.0)), ..Design::default() };
    /// assert!(d.check().unwrap_err().to_string().contains("Nyquist frequency 50 Hz"));
    /// ```
    pub fn band(&self) -> Result<(f64, f64), InputError> {
        let nyq = self.nyquist();
        match self.band {
            None => Ok((0.0, nyq)),
            Some((lo, hi)) => {
                if !(lo.is_finite() && hi.is_finite() && lo >= 0.0 && lo < hi) {
                    return Err(invalid(
                        "band",
                        format!(
                            "{lo}..{hi} Hz: give 0 ≤ low < high (in Hz, up to the Nyquist frequency {nyq} Hz)"
                        ),
                    ));
                }
                if hi > nyq * (1.0 + 1e-12) {
                    return Err(invalid(
                        "band",
                        format!(
                            "the upper edge {hi} Hz is above the Nyquist frequency {nyq} Hz of the sample time {} s",
                            self.sample_time
                        ),
                    ));
                }
                Ok((lo, hi.min(nyq)))
            }
        }
    }

    /// Checks the length, sample time, amplitude, offset and band.
    pub fn check(&self) -> Result<(), InputError> {
        if self.length == 0 || self.length > MAX_LENGTH {
            return Err(invalid(
                "length",
                format!("{}: give 1 to {MAX_LENGTH} samples", self.length),
            ));
        }
        if !(self.sample_time.is_finite() && self.sample_time > 0.0) {
            return Err(invalid(
                "sample time",
                format!("{}: give a finite time > 0 in seconds", self.sample_time),
            ));
        }
        if !(self.amplitude.is_finite() && self.amplitude > 0.0 && self.amplitude < 1e150) {
            return Err(invalid(
                "amplitude",
                format!("{}: give a finite amplitude > 0", self.amplitude),
            ));
        }
        if !(self.offset.is_finite() && self.offset.abs() < 1e150) {
            return Err(invalid(
                "offset",
                format!("{}: give a finite offset", self.offset),
            ));
        }
        self.band().map(|_| ())
    }
}

/// Which harmonics of its period a multisine excites.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Lines {
    /// Every harmonic in the band.
    All,
    /// The odd harmonics in the band (even nonlinear distortions then fall on unexcited lines).
    Odd,
    /// These harmonics (1 ≤ k < period / 2), whatever the band.
    Chosen(Vec<usize>),
}

/// The frequency law of a chirp.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Sweep {
    /// Frequency linear in time.
    Linear,
    /// Frequency exponential in time (equal time per decade; needs a band above 0 Hz).
    Logarithmic,
}

/// The kind of input to design.
///
/// ```
/// use structid_input::{generate, Design, Kind, Lines, Sweep};
/// let d = Design { length: 256, ..Design::default() };
/// for kind in [
///     Kind::Prbs { order: None, clock: Some(2) },
///     Kind::Multisine { period: Some(64), lines: Lines::Chosen(vec![1, 3, 5]), minimise_crest: false },
///     Kind::Noise,
///     Kind::Chirp { sweep: Sweep::Linear },
///     Kind::Steps { min_hold: 4, max_hold: 16 },
/// ] {
///     let u = generate(&d, &kind).unwrap();
///     assert_eq!(u.len(), 256);
///     assert!(u.iter().all(|v| v.is_finite()));
/// }
/// ```
#[derive(Clone, Debug, PartialEq)]
pub enum Kind {
    /// A maximum-length binary sequence.
    Prbs {
        /// Order n (2 ≤ n ≤ 24): the period is 2ⁿ − 1 bits. Default: the smallest order
        /// whose period (times the clock) covers the length, at most 24.
        order: Option<u32>,
        /// Samples per bit (≥ 1). Default: from the band's upper edge, ⌊Nyquist / high⌋
        /// (1 for the whole band); the band's lower edge must be 0.
        clock: Option<usize>,
    },
    /// A random-phase multisine.
    Multisine {
        /// The period in samples (≥ 4); the length need not be a multiple of it, but only
        /// whole periods have the designed spectrum. Default: the length.
        period: Option<usize>,
        /// Which harmonics are excited.
        lines: Lines,
        /// Choose phases that minimise the crest factor (iterative clipping) instead of
        /// random ones.
        minimise_crest: bool,
    },
    /// Band-limited Gaussian noise.
    Noise,
    /// A sine sweep across the band.
    Chirp {
        /// The frequency law.
        sweep: Sweep,
    },
    /// Random levels held for random times.
    Steps {
        /// Shortest hold, in samples (≥ 1).
        min_hold: usize,
        /// Longest hold, in samples (≥ `min_hold`).
        max_hold: usize,
    },
}

/// Designs one input signal: `design.length` samples of the given kind.
///
/// ```
/// use structid_input::{crest_factor, generate, Design, Kind, Lines};
/// let design = Design { length: 1024, sample_time: 0.01, band: Some((1.0, 10.0)), ..Design::default() };
/// let kind = Kind::Multisine { period: None, lines: Lines::Odd, minimise_crest: true };
/// let u = generate(&design, &kind).unwrap();
/// assert!((u.iter().fold(0.0f64, |m, v| m.max(v.abs())) - 1.0).abs() < 1e-12); // peak = amplitude
/// assert!(crest_factor(&u) < 1.8);
/// ```
pub fn generate(design: &Design, kind: &Kind) -> Result<Vec<f64>, InputError> {
    design.check()?;
    let mut rng = Rng::new(design.seed);
    let a = design.amplitude;
    let x = match kind {
        Kind::Prbs { order, clock } => prbs_signal(design, *order, *clock)?,
        Kind::Multisine {
            period,
            lines,
            minimise_crest,
        } => multisine(design, *period, lines, *minimise_crest, &mut rng)?,
        Kind::Noise => noise(design, &mut rng)?,
        Kind::Chirp { sweep } => chirp(design, *sweep)?,
        Kind::Steps { min_hold, max_hold } => steps(design, *min_hold, *max_hold, &mut rng)?,
    };
    Ok(x.into_iter().map(|v| design.offset + a * v).collect())
}

/// The crest factor max |x − x̄| / RMS(x − x̄) of a signal (about its mean); 1 for a binary
/// signal, √2 for a sine, 0 for a constant or empty signal.
///
/// ```
/// let s: Vec<f64> = (0..1000).map(|k| (2.0 * std::f64::consts::PI * k as f64 / 100.0).sin()).collect();
/// assert!((structid_input::crest_factor(&s) - 2f64.sqrt()).abs() < 1e-9);
/// ```
pub fn crest_factor(x: &[f64]) -> f64 {
    if x.is_empty() {
        return 0.0;
    }
    let mean = x.iter().sum::<f64>() / x.len() as f64;
    let peak = x.iter().fold(0.0f64, |m, v| m.max((v - mean).abs()));
    let rms = (x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / x.len() as f64).sqrt();
    if rms > 0.0 { peak / rms } else { 0.0 }
}

/// Feedback taps of a maximum-length Fibonacci shift register of order n (index n − 2).
const TAPS: [&[u32]; 23] = [
    &[2, 1],
    &[3, 2],
    &[4, 3],
    &[5, 3],
    &[6, 5],
    &[7, 6],
    &[8, 6, 5, 4],
    &[9, 5],
    &[10, 7],
    &[11, 9],
    &[12, 11, 10, 4],
    &[13, 12, 11, 8],
    &[14, 13, 12, 2],
    &[15, 14],
    &[16, 15, 13, 4],
    &[17, 14],
    &[18, 11],
    &[19, 18, 17, 14],
    &[20, 17],
    &[21, 19],
    &[22, 21],
    &[23, 18],
    &[24, 23, 22, 17],
];

/// The orders of maximum-length sequences [`prbs_bits`] knows.
pub const PRBS_ORDERS: std::ops::RangeInclusive<u32> = 2..=24;

/// One period (2ⁿ − 1 bits) of the maximum-length sequence of order n, starting from the
/// register state `start` (any non-zero n-bit value; other starts are cyclic shifts).
///
/// ```
/// let bits = structid_input::prbs_bits(4, 1).unwrap();
/// assert_eq!(bits.len(), 15);
/// assert_eq!(bits.iter().filter(|&&b| b).count(), 8);
/// assert!(structid_input::prbs_bits(25, 1).is_err());
/// ```
pub fn prbs_bits(order: u32, start: u32) -> Result<Vec<bool>, InputError> {
    if !PRBS_ORDERS.contains(&order) {
        return Err(invalid(
            "order",
            format!(
                "{order}: maximum-length sequences of order {} to {} are known (period 2^n − 1 bits)",
                PRBS_ORDERS.start(),
                PRBS_ORDERS.end()
            ),
        ));
    }
    let n = order;
    let mask = (1u32 << n) - 1;
    let mut s = start & mask;
    if s == 0 {
        s = mask;
    }
    let taps = TAPS[(n - 2) as usize];
    let period = mask as usize;
    let mut out = Vec::with_capacity(period);
    for _ in 0..period {
        out.push(s & 1 == 1);
        let fb = taps.iter().fold(0u32, |f, &t| f ^ (s >> (n - t))) & 1;
        s = (s >> 1) | (fb << (n - 1));
    }
    Ok(out)
}

fn prbs_signal(
    design: &Design,
    order: Option<u32>,
    clock: Option<usize>,
) -> Result<Vec<f64>, InputError> {
    let (lo, hi) = design.band()?;
    let clock = match clock {
        Some(0) => return Err(invalid("clock", "0 samples per bit: give 1 or more")),
        Some(c) => c,
        None => {
            if lo > 0.0 {
                return Err(invalid(
                    "band",
                    format!(
                        "a PRBS has its energy from 0 Hz up; its band is 0..high (the lower edge {lo} Hz must be 0)"
                    ),
                ));
            }
            ((design.nyquist() / hi).floor() as usize).max(1)
        }
    };
    let order = match order {
        Some(n) => n,
        None => {
            let bits = design.length.div_ceil(clock);
            let mut n = *PRBS_ORDERS.start();
            while ((1usize << n) - 1) < bits && n < *PRBS_ORDERS.end() {
                n += 1;
            }
            n
        }
    };
    let start = (design.seed as u32) ^ ((design.seed >> 32) as u32);
    let bits = prbs_bits(order, start)?;
    Ok((0..design.length)
        .map(|k| {
            if bits[(k / clock) % bits.len()] {
                1.0
            } else {
                -1.0
            }
        })
        .collect())
}

/// The harmonics (1 ≤ k < period/2) of a multisine.
fn harmonics(design: &Design, period: usize, lines: &Lines) -> Result<Vec<usize>, InputError> {
    let top = period.div_ceil(2); // k < period/2
    let ks: Vec<usize> = match lines {
        Lines::Chosen(ks) => {
            if ks.is_empty() {
                return Err(invalid("lines", "no harmonic chosen"));
            }
            let mut ks = ks.clone();
            ks.sort_unstable();
            ks.dedup();
            if let Some(&k) = ks.iter().find(|&&k| k == 0 || 2 * k >= period) {
                return Err(invalid(
                    "lines",
                    format!(
                        "harmonic {k} of a period of {period} samples: give harmonics 1 to {} (below half the period)",
                        top.saturating_sub(1).max(1)
                    ),
                ));
            }
            ks
        }
        Lines::All | Lines::Odd => {
            let (lo, hi) = design.band()?;
            let df = 1.0 / (period as f64 * design.sample_time);
            let ks: Vec<usize> = (1..period)
                .take_while(|&k| 2 * k < period)
                .filter(|&k| {
                    let f = k as f64 * df;
                    f >= lo * (1.0 - 1e-12) && f <= hi * (1.0 + 1e-12)
                })
                .filter(|&k| *lines == Lines::All || k % 2 == 1)
                .collect();
            if ks.is_empty() {
                return Err(invalid(
                    "band",
                    format!(
                        "no {}harmonic of the period ({period} samples, lines every {df:.6} Hz) lies in {lo}..{hi} Hz: widen the band or lengthen the period",
                        if *lines == Lines::Odd { "odd " } else { "" }
                    ),
                ));
            }
            ks
        }
    };
    Ok(ks)
}

fn multisine(
    design: &Design,
    period: Option<usize>,
    lines: &Lines,
    minimise_crest: bool,
    rng: &mut Rng,
) -> Result<Vec<f64>, InputError> {
    let p = period.unwrap_or(design.length);
    if !(4..=MAX_LENGTH).contains(&p) {
        return Err(invalid(
            "period",
            format!("{p} samples: give 4 to {MAX_LENGTH}"),
        ));
    }
    let ks = harmonics(design, p, lines)?;
    let mut phases: Vec<f64> = ks.iter().map(|_| 2.0 * PI * rng.uniform()).collect();
    let mut planner = FftPlanner::<f64>::new();
    let inverse = planner.plan_fft_inverse(p);
    let forward = planner.plan_fft_forward(p);
    let synth = |phases: &[f64]| -> Vec<f64> {
        let mut spec = vec![Complex::new(0.0, 0.0); p];
        for (&k, &ph) in ks.iter().zip(phases) {
            spec[k] = Complex::from_polar(1.0, ph);
            spec[p - k] = Complex::from_polar(1.0, -ph);
        }
        inverse.process(&mut spec);
        spec.iter().map(|c| c.re).collect()
    };
    let mut x = synth(&phases);
    if minimise_crest && ks.len() > 1 {
        // Iterative clipping: clip the peaks, keep the phases the clipped signal has on the
        // excited lines, restore the flat amplitudes; keep the best crest factor seen.
        let mut best = (crest_factor(&x), phases.clone());
        for it in 0..200 {
            let peak = x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            let rms = (x.iter().map(|v| v * v).sum::<f64>() / p as f64).sqrt();
            let level = (rms * (1.0 + 0.6 * (1.0 - it as f64 / 200.0))).min(peak);
            let mut spec: Vec<Complex<f64>> = x
                .iter()
                .map(|&v| Complex::new(v.clamp(-level, level), 0.0))
                .collect();
            forward.process(&mut spec);
            for (ph, &k) in phases.iter_mut().zip(&ks) {
                if spec[k].norm() > 0.0 {
                    *ph = spec[k].arg();
                }
            }
            x = synth(&phases);
            let cf = crest_factor(&x);
            if cf < best.0 {
                best = (cf, phases.clone());
            }
        }
        x = synth(&best.1);
    }
    let peak = x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let x: Vec<f64> = x.iter().map(|v| v / peak).collect();
    Ok((0..design.length).map(|k| x[k % p]).collect())
}

fn noise(design: &Design, rng: &mut Rng) -> Result<Vec<f64>, InputError> {
    let n = design.length;
    let (lo, hi) = design.band()?;
    let mut spec: Vec<Complex<f64>> = (0..n).map(|_| Complex::new(rng.normal(), 0.0)).collect();
    let mut planner = FftPlanner::<f64>::new();
    planner.plan_fft_forward(n).process(&mut spec);
    let df = 1.0 / (n as f64 * design.sample_time);
    let mut kept = 0;
    for k in 0..n {
        let kk = k.min(n - k); // the frequency of bin k is kk·df
        let f = kk as f64 * df;
        let inside = f >= lo * (1.0 - 1e-12) && f <= hi * (1.0 + 1e-12) && (kk > 0 || lo == 0.0);
        if inside {
            kept += 1;
        } else {
            spec[k] = Complex::new(0.0, 0.0);
        }
    }
    // DC alone (or nothing) is not noise.
    if kept <= usize::from(lo == 0.0) {
        return Err(invalid(
            "band",
            format!(
                "{lo}..{hi} Hz holds no frequency of a record of {n} samples (bins every {df:.6} Hz): widen the band or lengthen the record"
            ),
        ));
    }
    planner.plan_fft_inverse(n).process(&mut spec);
    let x: Vec<f64> = spec.iter().map(|c| c.re).collect();
    let rms = (x.iter().map(|v| v * v).sum::<f64>() / n as f64).sqrt();
    if rms == 0.0 {
        return Err(invalid("band", "the band-limited noise is zero"));
    }
    Ok(x.iter().map(|v| v / rms).collect())
}

fn chirp(design: &Design, sweep: Sweep) -> Result<Vec<f64>, InputError> {
    let (lo, hi) = design.band()?;
    let n = design.length;
    let ts = design.sample_time;
    let duration = n as f64 * ts;
    Ok(match sweep {
        Sweep::Linear => (0..n)
            .map(|k| {
                let t = k as f64 * ts;
                (2.0 * PI * (lo * t + (hi - lo) * t * t / (2.0 * duration))).sin()
            })
            .collect(),
        Sweep::Logarithmic => {
            if lo <= 0.0 {
                return Err(invalid(
                    "band",
                    "a logarithmic chirp needs a lower edge above 0 Hz (e.g. a band of 0.01 to 1 Hz)",
                ));
            }
            let r = (hi / lo).ln();
            (0..n)
                .map(|k| {
                    let t = k as f64 * ts;
                    let phase = if r > 0.0 {
                        lo * duration / r * ((r * t / duration).exp() - 1.0)
                    } else {
                        lo * t
                    };
                    (2.0 * PI * phase).sin()
                })
                .collect()
        }
    })
}

fn steps(
    design: &Design,
    min_hold: usize,
    max_hold: usize,
    rng: &mut Rng,
) -> Result<Vec<f64>, InputError> {
    if min_hold == 0 || max_hold < min_hold {
        return Err(invalid(
            "hold",
            format!("{min_hold}..{max_hold} samples: give 1 ≤ shortest ≤ longest"),
        ));
    }
    let mut out = Vec::with_capacity(design.length);
    let mut last = f64::NAN;
    while out.len() < design.length {
        let span = (max_hold - min_hold + 1) as u64;
        let hold = min_hold + (rng.next_u64() % span) as usize;
        // A new level, never equal to the last (so every hold is a step).
        let mut level = 2.0 * rng.uniform() - 1.0;
        while level == last {
            level = 2.0 * rng.uniform() - 1.0;
        }
        last = level;
        let take = hold.min(design.length - out.len());
        out.extend(std::iter::repeat_n(level, take));
    }
    Ok(out)
}

/// SplitMix64: small, fast and fixed, so that a seed gives the same signal in every version.
struct Rng(u64);

impl Rng {
    fn new(seed: u64) -> Self {
        Self(seed ^ 0x5DEE_CE66_D1A4_F87D)
    }

    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Standard normal (Box–Muller).
    fn normal(&mut self) -> f64 {
        let u1 = 1.0 - self.uniform(); // (0, 1]
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (2.0 * PI * u2).cos()
    }
}
