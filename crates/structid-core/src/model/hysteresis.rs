//! Hysteresis operators: scalar blocks of the LFT with memory.
//!
//! A static block maps z_k to w_k. A hysteresis operator w = H\[z\] also remembers the past of
//! its input through an internal state s: from the state before sample k and z_k, one step gives
//! w_k and the state after sample k. Every operator here is a [`HysteresisOperator`]; its
//! [`step_jacobian`](HysteresisOperator::step_jacobian) gives the exact partial derivatives of
//! one step ([`OperatorJacobian`]), so that a fit by simulation error can carry forward
//! sensitivities through the operator.
//!
//! # The operators
//!
//! **Play** ([`Play`], backlash) of half-width c ≥ 0. Its state is the follower b, which stays
//! put until the input has crossed the gap and is then dragged along at distance c:
//!
//! ```text
//!   b_k = min(max(b_(k−1), z_k − c), z_k + c),      w_k = b_k
//! ```
//!
//! Parameters: `[half_width]`. Relaxed state at rest in z₀: b = z₀ (the gap centred on z₀).
//!
//! **Stop** ([`Stop`], elastic–perfectly plastic) of threshold c > 0: what the play lets through
//! of the input, w = z − play_c\[z\]; it follows the increments of z and yields at ±c,
//! s_k = clamp(s_(k−1) + z_k − z_(k−1), −c, c). Its state is the follower b of the play it
//! complements, and w_k = clamp(z_k − b_(k−1), −c, c). Storing b rather than s keeps the stop
//! free of accumulated rounding (s is never summed from increments) and makes
//! [`PrandtlIshlinskii`] exactly rate independent. Parameters: `[threshold]`. Relaxed state: the
//! play centred on z₀, so the stop starts at 0.
//!
//! **Prandtl–Ishlinskii** ([`PrandtlIshlinskii`]): a linear term plus m stops of fixed thresholds
//! 0 < r₁ < … < r_m,
//!
//! ```text
//!   w = a·z + Σ_i b_i·stop_(r_i)[z]
//! ```
//!
//! It is the Preisach model whose weight lives on the diagonal of the Preisach plane (each stop
//! is a continuum of relays with its threshold as their half-width), so it inherits the
//! Preisach properties: rate independence (only the path of z matters, not its sampling) and
//! wiping-out (a new extremum erases the memory of the smaller reversals before it). The output
//! is linear in the parameters `[gain, weight_1, …, weight_m]` = \[a, b₁, …, b_m\], which are of
//! any sign. State: the m followers `[b_1, …, b_m]` of the plays behind the stops; relaxed
//! state: all centred on z₀.
//!
//! **Bouc–Wen** ([`BoucWen`]): w = a·z + b·h with h driven by the input increments,
//!
//! ```text
//!   dh = (1 − (β·sign(dz·h) + γ)·|h|^n)·dz
//! ```
//!
//! Bouc's A is normalised to 1 because b scales h. Parameters: `[gain, weight, beta, gamma]` =
//! \[a, b, β, γ\]; the exponent n ≥ 1 is fixed at construction (1 by default). The range is the
//! class of Ikhouane, Mañosa & Rodellar (J. Sound Vib. 2007) in which the model is bounded
//! input–bounded output for every input and initial h and its loops are those of a physical
//! (passive) hysteresis: A > 0 (here A = 1), β + γ > 0 and β − γ ≥ 0. Then
//! |h| ≤ max(|h₀|, h̄) with h̄ = (1/(β + γ))^(1/n), and dh/dz ≥ 0 while |h| ≤ h̄ (h never moves
//! against the input). State: `[h, z_prev]`; relaxed state: `[0, z₀]`.
//!
//! # Bouc–Wen discretisation
//!
//! The model is rate independent, so a sample is an ODE in z, not in time: h′(ζ) = f(h) =
//! 1 − β·σ·h·|h|^(n−1) − γ·|h|^n over ζ from z_(k−1) to z_k, with σ = sign(z_k − z_(k−1))
//! (+1 for a zero increment) fixed within the sample, since sign(dz·h)·|h|^n = σ·h·|h|^(n−1).
//! The increment Δz is split into N equal substeps δ = Δz/N integrated by Heun's method
//! (explicit trapezoid, second order):
//!
//! ```text
//!   k₁ = f(h),   k₂ = f(h + δ·k₁),   h ← h + δ·(k₁ + k₂)/2
//! ```
//!
//! N = ⌈|Δz|/δ_max⌉ (at least 1, at most [`BoucWen::MAX_SUBSTEPS`]) with
//! δ_max = ε·h̄·(β + γ)/(2·β·n) and ε the resolution (default
//! [`BoucWen::DEFAULT_RESOLUTION`]). On |h| ≤ h̄, |f| ≤ 2β/(β + γ), so one substep changes h by
//! at most ε·h̄/n, and δ·|∂f/∂h| ≤ ε keeps Heun's method far inside its stability interval. N
//! depends on Δz and on β + γ through a ceiling: the map of one sample is smooth for a fixed N
//! except where some substep's h crosses 0 (for n = 1), and the derivatives of
//! [`step_jacobian`](HysteresisOperator::step_jacobian) are exact for the N used (the jumps of N
//! are a measure-zero set where they are one-sided).
//!
//! # Signals
//!
//! [`apply_into`] runs an operator over a whole signal from a given state and
//! [`apply_from_rest_into`] from the relaxed state at the signal's first value.

use crate::error::{Error, Result};

/// A hysteresis operator w = H\[z\]: a scalar block of the LFT with memory (state).
///
/// ```
/// use structid_core::{HysteresisOperator, Play};
/// let op: Box<dyn HysteresisOperator> = Box::new(Play::new(0.5).unwrap());
/// let mut state = vec![0.0; op.state_len()];
/// op.initial_state(0.0, &mut state);
/// let w: Vec<f64> = [0.0, 1.0, 0.8].iter().map(|&z| op.step(&mut state, z)).collect();
/// assert_eq!(w, [0.0, 0.5, 0.5]);
/// ```
pub trait HysteresisOperator: Send + Sync + std::fmt::Debug {
    /// Short kind name: "play", "stop", "prandtl-ishlinskii", "bouc-wen".
    fn kind(&self) -> &'static str;
    /// Length of the internal state.
    fn state_len(&self) -> usize;
    /// The fitted parameters, in the order documented by each operator.
    fn parameters(&self) -> Vec<f64>;
    /// Their names, same order (e.g. "half_width", "gain", "weight_2", "beta").
    fn parameter_names(&self) -> Vec<String>;
    /// The same operator with other parameters (what is fixed at construction, such as the
    /// thresholds of a [`PrandtlIshlinskii`], is kept).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming a parameter out of its range,
    /// [`Error::DimensionMismatch`] when `p` has not [`parameters`](Self::parameters)' length.
    fn with_parameters(&self, p: &[f64]) -> Result<Box<dyn HysteresisOperator>>;
    /// A copy in a box.
    fn boxed(&self) -> Box<dyn HysteresisOperator>;
    /// Writes the state of the relaxed operator whose input has rested at `z0` (documented per
    /// operator).
    fn initial_state(&self, z0: f64, state: &mut [f64]);
    /// One sample: from the state before sample k and the input z_k, overwrites the state with
    /// the state after sample k and returns w_k.
    fn step(&self, state: &mut [f64], z: f64) -> f64;
    /// The same step (same state after it, same w_k), also overwriting every entry of `jac`
    /// with the partial derivatives with respect to the state before the step, z_k and the
    /// parameters. `jac` must be sized by [`OperatorJacobian::for_operator`].
    fn step_jacobian(&self, state: &mut [f64], z: f64, jac: &mut OperatorJacobian) -> f64;
}

impl Clone for Box<dyn HysteresisOperator> {
    fn clone(&self) -> Self {
        self.boxed()
    }
}

/// Partial derivatives of one step, dense row-major, with s the state before the step, s⁺ the
/// state after it and p the parameters (ns = state length, np = number of parameters).
///
/// ```
/// use structid_core::{HysteresisOperator, OperatorJacobian, Stop};
/// let stop = Stop::new(0.5).unwrap();
/// let mut jac = OperatorJacobian::for_operator(&stop);
/// let mut state = [0.0];
/// // Inside the elastic range w = z − b: ∂w/∂z = 1, ∂w/∂b = −1.
/// let w = stop.step_jacobian(&mut state, 0.2, &mut jac);
/// assert_eq!((w, jac.dw_dz, jac.dw_ds[0], jac.dw_dp[0]), (0.2, 1.0, -1.0, 0.0));
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct OperatorJacobian {
    /// ∂s⁺/∂s, ns × ns.
    pub ds_ds: Vec<f64>,
    /// ∂s⁺/∂z, ns.
    pub ds_dz: Vec<f64>,
    /// ∂s⁺/∂p, ns × np.
    pub ds_dp: Vec<f64>,
    /// ∂w/∂s, ns.
    pub dw_ds: Vec<f64>,
    /// ∂w/∂z.
    pub dw_dz: f64,
    /// ∂w/∂p, np.
    pub dw_dp: Vec<f64>,
}

impl OperatorJacobian {
    /// Zeroed buffers sized for `op`.
    ///
    /// ```
    /// use structid_core::{BoucWen, OperatorJacobian};
    /// let jac = OperatorJacobian::for_operator(&BoucWen::new(1.0, 1.0, 0.5, 0.5).unwrap());
    /// assert_eq!((jac.ds_ds.len(), jac.ds_dp.len(), jac.dw_dp.len()), (4, 8, 4));
    /// ```
    pub fn for_operator(op: &dyn HysteresisOperator) -> Self {
        let (ns, np) = (op.state_len(), op.parameters().len());
        Self {
            ds_ds: vec![0.0; ns * ns],
            ds_dz: vec![0.0; ns],
            ds_dp: vec![0.0; ns * np],
            dw_ds: vec![0.0; ns],
            dw_dz: 0.0,
            dw_dp: vec![0.0; np],
        }
    }

    fn clear(&mut self) {
        for v in [
            &mut self.ds_ds,
            &mut self.ds_dz,
            &mut self.ds_dp,
            &mut self.dw_ds,
            &mut self.dw_dp,
        ] {
            v.fill(0.0);
        }
        self.dw_dz = 0.0;
    }
}

/// Runs `op` over the signal `z` from `state` (the state before z\[0\]), writing w into `out`;
/// `state` ends as the state after the last sample, so a signal can be run in pieces.
///
/// ```
/// use structid_core::{HysteresisOperator, Play};
/// use structid_core::model::hysteresis::apply_into;
/// let play = Play::new(0.5).unwrap();
/// let mut state = [0.0];
/// play.initial_state(0.0, &mut state);
/// let mut w = [0.0; 3];
/// apply_into(&play, &[0.0, 1.0, 2.0], &mut state, &mut w);
/// assert_eq!((w, state), ([0.0, 0.5, 1.5], [1.5]));
/// ```
///
/// # Panics
/// When `out` is not as long as `z` or `state` is not [`state_len`](HysteresisOperator::state_len)
/// long.
pub fn apply_into(op: &dyn HysteresisOperator, z: &[f64], state: &mut [f64], out: &mut [f64]) {
    assert_eq!(z.len(), out.len(), "apply_into: z and out lengths differ");
    assert_eq!(
        state.len(),
        op.state_len(),
        "apply_into: wrong state length"
    );
    for (o, &x) in out.iter_mut().zip(z) {
        *o = op.step(state, x);
    }
}

/// Runs `op` over `z` from its relaxed state at rest in z\[0\], writing w into `out`.
///
/// ```
/// use structid_core::Stop;
/// use structid_core::model::hysteresis::apply_from_rest_into;
/// let mut w = [0.0; 4];
/// apply_from_rest_into(&Stop::new(0.5).unwrap(), &[1.0, 1.25, 2.0, 1.0], &mut w);
/// assert_eq!(w, [0.0, 0.25, 0.5, -0.5]);
/// ```
///
/// # Panics
/// When `out` is not as long as `z`.
pub fn apply_from_rest_into(op: &dyn HysteresisOperator, z: &[f64], out: &mut [f64]) {
    assert_eq!(z.len(), out.len(), "apply_from_rest_into: lengths differ");
    let Some(&first) = z.first() else {
        return;
    };
    let mut state = vec![0.0; op.state_len()];
    op.initial_state(first, &mut state);
    apply_into(op, z, &mut state, out);
}

fn invalid(name: impl Into<String>, value: f64, reason: impl Into<String>) -> Error {
    Error::InvalidParameter {
        name: name.into(),
        value,
        reason: reason.into(),
    }
}

fn finite(name: &str, value: f64) -> Result<f64> {
    if value.is_finite() {
        Ok(value)
    } else {
        Err(invalid(name, value, "must be a finite number"))
    }
}

fn check_count(what: &str, p: &[f64], expected: usize) -> Result<()> {
    if p.len() == expected {
        return Ok(());
    }
    Err(Error::DimensionMismatch {
        what: format!("number of {what} parameters"),
        expected: expected.to_string(),
        found: p.len().to_string(),
    })
}

/// Which way z drags a play's follower in one step.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Drag {
    /// z − c has passed the follower from below: b⁺ = z − c.
    Up,
    /// The follower is within c of z and stays.
    Still,
    /// z + c has passed the follower from above: b⁺ = z + c.
    Down,
}

impl Drag {
    /// The same comparisons as `b.clamp(z − c, z + c)`, so a play reproduces a clamp bit for bit.
    fn of(b: f64, z: f64, c: f64) -> Self {
        if b < z - c {
            Drag::Up
        } else if b > z + c {
            Drag::Down
        } else {
            Drag::Still
        }
    }

    fn follower(self, b: f64, z: f64, c: f64) -> f64 {
        match self {
            Drag::Up => z - c,
            Drag::Down => z + c,
            Drag::Still => b,
        }
    }

    /// (∂b⁺/∂b, ∂b⁺/∂z, ∂b⁺/∂c).
    fn follower_partials(self) -> [f64; 3] {
        match self {
            Drag::Up => [0.0, 1.0, -1.0],
            Drag::Down => [0.0, 1.0, 1.0],
            Drag::Still => [1.0, 0.0, 0.0],
        }
    }

    /// The stop's output: exactly ±c when yielding, so |w| ≤ c holds without rounding excess.
    fn stop(self, b: f64, z: f64, c: f64) -> f64 {
        match self {
            Drag::Up => c,
            Drag::Down => -c,
            Drag::Still => (z - b).clamp(-c, c),
        }
    }

    /// (∂w/∂b, ∂w/∂z, ∂w/∂c) of [`Drag::stop`].
    fn stop_partials(self) -> [f64; 3] {
        match self {
            Drag::Up => [0.0, 0.0, 1.0],
            Drag::Down => [0.0, 0.0, -1.0],
            Drag::Still => [-1.0, 1.0, 0.0],
        }
    }
}

/// The play (backlash) operator of half-width c ≥ 0: b_k = min(max(b_(k−1), z_k − c), z_k + c),
/// w = b. State `[b]`, relaxed state `[z0]`, parameters `[half_width]`.
///
/// ```
/// use structid_core::{HysteresisOperator, Play};
/// let play = Play::new(0.5).unwrap();
/// let mut w = [0.0; 6];
/// structid_core::model::hysteresis::apply_from_rest_into(&play, &[0.0, 1.0, 2.0, 1.5, 1.0, 0.0], &mut w);
/// assert_eq!(w, [0.0, 0.5, 1.5, 1.5, 1.5, 0.5]);
/// assert_eq!(play.parameter_names(), ["half_width"]);
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct Play {
    half_width: f64,
}

impl Play {
    /// A play of half-width `half_width` (0 is the identity).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] named `half_width` when it is negative or not finite.
    ///
    /// ```
    /// use structid_core::{Error, Play};
    /// let e = Play::new(-0.1).unwrap_err();
    /// assert!(matches!(e, Error::InvalidParameter { ref name, .. } if name == "half_width"));
    /// ```
    pub fn new(half_width: f64) -> Result<Self> {
        let c = finite("half_width", half_width)?;
        if c < 0.0 {
            return Err(invalid("half_width", c, "must not be negative"));
        }
        Ok(Self { half_width: c })
    }

    /// The half-width c.
    ///
    /// ```
    /// assert_eq!(structid_core::Play::new(0.3).unwrap().half_width(), 0.3);
    /// ```
    pub fn half_width(&self) -> f64 {
        self.half_width
    }
}

/// The [`HysteresisOperator`] methods of an operator with one parameter (the field `$param`,
/// checked by `Self::new`) and one state, the follower `b`, relaxed to `z0`: [`Play`] and
/// [`Stop`].
macro_rules! one_follower_operator {
    ($kind:literal, $param:ident) => {
        fn kind(&self) -> &'static str {
            $kind
        }

        fn state_len(&self) -> usize {
            1
        }

        fn parameters(&self) -> Vec<f64> {
            vec![self.$param]
        }

        fn parameter_names(&self) -> Vec<String> {
            vec![stringify!($param).into()]
        }

        fn with_parameters(&self, p: &[f64]) -> Result<Box<dyn HysteresisOperator>> {
            check_count($kind, p, 1)?;
            Ok(Box::new(Self::new(p[0])?))
        }

        fn boxed(&self) -> Box<dyn HysteresisOperator> {
            Box::new(self.clone())
        }

        fn initial_state(&self, z0: f64, state: &mut [f64]) {
            state[0] = z0;
        }
    };
}

impl HysteresisOperator for Play {
    one_follower_operator!("play", half_width);

    fn step(&self, state: &mut [f64], z: f64) -> f64 {
        let c = self.half_width;
        state[0] = Drag::of(state[0], z, c).follower(state[0], z, c);
        state[0]
    }

    fn step_jacobian(&self, state: &mut [f64], z: f64, jac: &mut OperatorJacobian) -> f64 {
        let drag = Drag::of(state[0], z, self.half_width);
        let [db, dz, dc] = drag.follower_partials();
        (jac.ds_ds[0], jac.ds_dz[0], jac.ds_dp[0]) = (db, dz, dc);
        (jac.dw_ds[0], jac.dw_dz, jac.dw_dp[0]) = (db, dz, dc);
        self.step(state, z)
    }
}

/// The stop (elastic–perfectly plastic) operator of threshold c > 0: w = z − play_c\[z\], which
/// follows the increments of z and yields at ±c. State `[b]`, the complementary play's follower;
/// relaxed state `[z0]` (the stop starts at 0); parameters `[threshold]`.
///
/// ```
/// use structid_core::Stop;
/// let mut w = [0.0; 6];
/// let z = [0.0, 1.0, 2.0, 1.5, 1.0, 0.0];
/// structid_core::model::hysteresis::apply_from_rest_into(&Stop::new(0.5).unwrap(), &z, &mut w);
/// assert_eq!(w, [0.0, 0.5, 0.5, 0.0, -0.5, -0.5]);
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct Stop {
    threshold: f64,
}

impl Stop {
    /// A stop of threshold `threshold`.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] named `threshold` when it is not a finite number > 0.
    ///
    /// ```
    /// use structid_core::{Error, Stop};
    /// let e = Stop::new(f64::NAN).unwrap_err();
    /// assert!(matches!(e, Error::InvalidParameter { ref name, .. } if name == "threshold"));
    /// ```
    pub fn new(threshold: f64) -> Result<Self> {
        Ok(Self {
            threshold: positive("threshold", threshold)?,
        })
    }

    /// The threshold c.
    ///
    /// ```
    /// assert_eq!(structid_core::Stop::new(0.3).unwrap().threshold(), 0.3);
    /// ```
    pub fn threshold(&self) -> f64 {
        self.threshold
    }
}

fn positive(name: &str, value: f64) -> Result<f64> {
    let v = finite(name, value)?;
    if v > 0.0 {
        Ok(v)
    } else {
        Err(invalid(name, v, "must be greater than zero"))
    }
}

impl HysteresisOperator for Stop {
    one_follower_operator!("stop", threshold);

    fn step(&self, state: &mut [f64], z: f64) -> f64 {
        let (b, c) = (state[0], self.threshold);
        let drag = Drag::of(b, z, c);
        state[0] = drag.follower(b, z, c);
        drag.stop(b, z, c)
    }

    fn step_jacobian(&self, state: &mut [f64], z: f64, jac: &mut OperatorJacobian) -> f64 {
        let drag = Drag::of(state[0], z, self.threshold);
        let [db, dz, dc] = drag.follower_partials();
        (jac.ds_ds[0], jac.ds_dz[0], jac.ds_dp[0]) = (db, dz, dc);
        let [db, dz, dc] = drag.stop_partials();
        (jac.dw_ds[0], jac.dw_dz, jac.dw_dp[0]) = (db, dz, dc);
        self.step(state, z)
    }
}

/// The Prandtl–Ishlinskii operator w = a·z + Σ_i b_i·stop_(r_i)\[z\] with thresholds
/// 0 < r₁ < … < r_m fixed at construction. State `[b_1, …, b_m]`, the followers of the stops'
/// plays; relaxed state all `z0`; parameters `[gain, weight_1, …, weight_m]` = \[a, b₁, …, b_m\]
/// (w is linear in them).
///
/// ```
/// use structid_core::{HysteresisOperator, PrandtlIshlinskii};
/// let pi = PrandtlIshlinskii::new(vec![0.5, 1.0], 1.0, vec![0.5, 0.25]).unwrap();
/// assert_eq!(pi.parameter_names(), ["gain", "weight_1", "weight_2"]);
/// let mut w = [0.0; 3];
/// structid_core::model::hysteresis::apply_from_rest_into(&pi, &[0.0, 1.0, 0.0], &mut w);
/// // At z = 1 the first stop yields at 0.5, the second reaches 1; back at 0 the first is at
/// // −0.5 and the second at 0.
/// assert_eq!(w, [0.0, 1.5, -0.25]);
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct PrandtlIshlinskii {
    thresholds: Vec<f64>,
    gain: f64,
    weights: Vec<f64>,
}

impl PrandtlIshlinskii {
    /// The operator with stops of `thresholds`, linear gain `gain` and stop weights `weights`
    /// (one per threshold).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] named `threshold_i` (numbered from 1) for a threshold not
    /// finite, not > 0 or not above the previous one, `thresholds` for none at all, `gain` or
    /// `weight_i` for a value not finite; [`Error::DimensionMismatch`] when the counts differ.
    ///
    /// ```
    /// use structid_core::{Error, PrandtlIshlinskii};
    /// let e = PrandtlIshlinskii::new(vec![0.5, 0.5], 1.0, vec![1.0, 1.0]).unwrap_err();
    /// assert!(matches!(e, Error::InvalidParameter { ref name, .. } if name == "threshold_2"));
    /// ```
    pub fn new(thresholds: Vec<f64>, gain: f64, weights: Vec<f64>) -> Result<Self> {
        check_thresholds(&thresholds)?;
        if weights.len() != thresholds.len() {
            return Err(Error::DimensionMismatch {
                what: "Prandtl–Ishlinskii weights".into(),
                expected: format!("one per threshold ({})", thresholds.len()),
                found: weights.len().to_string(),
            });
        }
        let (gain, weights) = check_weights(gain, weights)?;
        Ok(Self {
            thresholds,
            gain,
            weights,
        })
    }

    /// m = `weights.len()` stops with thresholds spread uniformly over (0, `max_threshold`]:
    /// r_i = i·max_threshold/m.
    ///
    /// # Errors
    /// As [`PrandtlIshlinskii::new`], and `max_threshold` when it is not a finite number > 0.
    ///
    /// ```
    /// use structid_core::PrandtlIshlinskii;
    /// let pi = PrandtlIshlinskii::uniform(1.0, 1.0, vec![0.0; 4]).unwrap();
    /// assert_eq!(pi.thresholds(), [0.25, 0.5, 0.75, 1.0]);
    /// ```
    pub fn uniform(max_threshold: f64, gain: f64, weights: Vec<f64>) -> Result<Self> {
        let r = positive("max_threshold", max_threshold)?;
        let m = weights.len() as f64;
        let thresholds = (1..=weights.len()).map(|i| r * (i as f64 / m)).collect();
        Self::new(thresholds, gain, weights)
    }

    /// The thresholds r_i.
    pub fn thresholds(&self) -> &[f64] {
        &self.thresholds
    }

    /// The linear gain a.
    pub fn gain(&self) -> f64 {
        self.gain
    }

    /// The stop weights b_i.
    pub fn weights(&self) -> &[f64] {
        &self.weights
    }
}

fn check_thresholds(thresholds: &[f64]) -> Result<()> {
    if thresholds.is_empty() {
        return Err(invalid("thresholds", 0.0, "at least one stop is needed"));
    }
    for (i, &r) in thresholds.iter().enumerate() {
        let name = format!("threshold_{}", i + 1);
        positive(&name, r)?;
        if i > 0 && r <= thresholds[i - 1] {
            let reason = format!("must exceed threshold_{i} = {}", thresholds[i - 1]);
            return Err(invalid(name, r, reason));
        }
    }
    Ok(())
}

fn check_weights(gain: f64, weights: Vec<f64>) -> Result<(f64, Vec<f64>)> {
    finite("gain", gain)?;
    for (i, &b) in weights.iter().enumerate() {
        finite(&format!("weight_{}", i + 1), b)?;
    }
    Ok((gain, weights))
}

impl HysteresisOperator for PrandtlIshlinskii {
    fn kind(&self) -> &'static str {
        "prandtl-ishlinskii"
    }

    fn state_len(&self) -> usize {
        self.thresholds.len()
    }

    fn parameters(&self) -> Vec<f64> {
        std::iter::once(self.gain)
            .chain(self.weights.iter().copied())
            .collect()
    }

    fn parameter_names(&self) -> Vec<String> {
        let weights = (1..=self.weights.len()).map(|i| format!("weight_{i}"));
        std::iter::once("gain".to_string()).chain(weights).collect()
    }

    fn with_parameters(&self, p: &[f64]) -> Result<Box<dyn HysteresisOperator>> {
        check_count("Prandtl–Ishlinskii", p, 1 + self.weights.len())?;
        let (gain, weights) = check_weights(p[0], p[1..].to_vec())?;
        Ok(Box::new(Self {
            thresholds: self.thresholds.clone(),
            gain,
            weights,
        }))
    }

    fn boxed(&self) -> Box<dyn HysteresisOperator> {
        Box::new(self.clone())
    }

    fn initial_state(&self, z0: f64, state: &mut [f64]) {
        state.fill(z0);
    }

    fn step(&self, state: &mut [f64], z: f64) -> f64 {
        let mut w = self.gain * z;
        for ((b, &r), &weight) in state.iter_mut().zip(&self.thresholds).zip(&self.weights) {
            let drag = Drag::of(*b, z, r);
            w += weight * drag.stop(*b, z, r);
            *b = drag.follower(*b, z, r);
        }
        w
    }

    fn step_jacobian(&self, state: &mut [f64], z: f64, jac: &mut OperatorJacobian) -> f64 {
        // The thresholds are fixed, so the state does not depend on the parameters: ds_dp = 0.
        jac.clear();
        let m = self.thresholds.len();
        let mut w = self.gain * z;
        jac.dw_dz = self.gain;
        jac.dw_dp[0] = z;
        for i in 0..m {
            let (b, r, weight) = (state[i], self.thresholds[i], self.weights[i]);
            let drag = Drag::of(b, z, r);
            let stop = drag.stop(b, z, r);
            w += weight * stop;
            let [fb, fz, _] = drag.follower_partials();
            let [sb, sz, _] = drag.stop_partials();
            (jac.ds_ds[i * m + i], jac.ds_dz[i]) = (fb, fz);
            jac.dw_ds[i] = weight * sb;
            jac.dw_dz += weight * sz;
            jac.dw_dp[1 + i] = stop;
            state[i] = drag.follower(b, z, r);
        }
        w
    }
}

/// The Bouc–Wen operator w = a·z + b·h, dh = (1 − (β·sign(dz·h) + γ)·|h|^n)·dz, integrated in z
/// by Heun substeps (see the [module documentation](self)). State `[h, z_prev]`, relaxed state
/// `[0, z0]`; parameters `[gain, weight, beta, gamma]` = \[a, b, β, γ\]; the exponent n and the
/// resolution ε of the substeps are fixed at construction.
///
/// ```
/// use structid_core::{BoucWen, HysteresisOperator};
/// let bw = BoucWen::new(0.0, 1.0, 0.5, 0.5).unwrap();
/// assert_eq!(bw.bound(), 1.0);
/// let z: Vec<f64> = (0..400).map(|k| 5.0 * (k as f64 * 0.05).sin()).collect();
/// let mut h = vec![0.0; z.len()];
/// structid_core::model::hysteresis::apply_from_rest_into(&bw, &z, &mut h);
/// // Driven far beyond the yield point, h saturates at the bound ±(1/(β + γ))^(1/n).
/// assert!(h.iter().all(|v| v.abs() <= 1.0 + 1e-9));
/// assert!(h.iter().any(|v| v.abs() > 0.99));
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct BoucWen {
    gain: f64,
    weight: f64,
    beta: f64,
    gamma: f64,
    exponent: f64,
    resolution: f64,
}

impl BoucWen {
    /// The resolution ε used unless [`BoucWen::with_resolution`] sets another: a substep changes
    /// h by at most ε·h̄/n.
    pub const DEFAULT_RESOLUTION: f64 = 0.05;

    /// The most substeps one sample is split into, so a huge input jump cannot stall a
    /// simulation (beyond it the substeps grow longer than the resolution asks).
    pub const MAX_SUBSTEPS: usize = 10_000;

    /// The operator with exponent n = 1.
    ///
    /// # Errors
    /// As [`BoucWen::with_exponent`].
    ///
    /// ```
    /// use structid_core::{BoucWen, Error};
    /// let e = BoucWen::new(1.0, 1.0, 0.2, -0.3).unwrap_err();
    /// assert!(matches!(e, Error::InvalidParameter { ref name, .. } if name == "beta + gamma"));
    /// ```
    pub fn new(gain: f64, weight: f64, beta: f64, gamma: f64) -> Result<Self> {
        Self::with_exponent(gain, weight, beta, gamma, 1.0)
    }

    /// The operator with exponent `exponent` = n ≥ 1.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] named `gain`, `weight`, `beta`, `gamma` or `exponent` for a
    /// value not finite, `exponent` below 1, `beta + gamma` when β + γ ≤ 0 (unbounded h) and
    /// `beta - gamma` when β − γ < 0 (outside the bounded, passive class).
    ///
    /// ```
    /// use structid_core::{BoucWen, HysteresisOperator};
    /// let bw = BoucWen::with_exponent(1.0, 2.0, 0.75, 0.25, 2.0).unwrap();
    /// assert_eq!(bw.parameters(), [1.0, 2.0, 0.75, 0.25]);
    /// assert_eq!(bw.exponent(), 2.0);
    /// ```
    pub fn with_exponent(
        gain: f64,
        weight: f64,
        beta: f64,
        gamma: f64,
        exponent: f64,
    ) -> Result<Self> {
        let n = finite("exponent", exponent)?;
        if n < 1.0 {
            return Err(invalid("exponent", n, "must be at least 1"));
        }
        let op = Self {
            gain: 0.0,
            weight: 0.0,
            beta: 0.0,
            gamma: 0.0,
            exponent: n,
            resolution: Self::DEFAULT_RESOLUTION,
        };
        op.reparametrised(&[gain, weight, beta, gamma])
    }

    /// The same operator with substeps of resolution `resolution` = ε in (0, 1]: each substep
    /// changes h by at most ε·h̄/n (smaller is more accurate and slower).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] named `resolution` when it is not in (0, 1].
    ///
    /// ```
    /// use structid_core::BoucWen;
    /// let bw = BoucWen::new(1.0, 1.0, 0.5, 0.5).unwrap();
    /// assert_eq!(bw.substeps(1.0), 20);
    /// assert_eq!(bw.with_resolution(0.01).unwrap().substeps(1.0), 100);
    /// ```
    pub fn with_resolution(self, resolution: f64) -> Result<Self> {
        let eps = positive("resolution", resolution)?;
        if eps > 1.0 {
            return Err(invalid("resolution", eps, "must be at most 1"));
        }
        Ok(Self {
            resolution: eps,
            ..self
        })
    }

    fn reparametrised(&self, p: &[f64]) -> Result<Self> {
        let names = ["gain", "weight", "beta", "gamma"];
        for (name, &v) in names.iter().zip(p) {
            finite(name, v)?;
        }
        let (beta, gamma) = (p[2], p[3]);
        if beta + gamma <= 0.0 {
            let reason = format!("must be > 0, or h grows without bound (β = {beta}, γ = {gamma})");
            return Err(invalid("beta + gamma", beta + gamma, reason));
        }
        if beta - gamma < 0.0 {
            let reason = format!(
                "must be ≥ 0 for a bounded, passive loop (β = {beta}, γ = {gamma}; \
                 Ikhouane, Mañosa & Rodellar 2007)"
            );
            return Err(invalid("beta - gamma", beta - gamma, reason));
        }
        Ok(Self {
            gain: p[0],
            weight: p[1],
            beta,
            gamma,
            ..self.clone()
        })
    }

    /// The exponent n.
    pub fn exponent(&self) -> f64 {
        self.exponent
    }

    /// The resolution ε of the substeps.
    pub fn resolution(&self) -> f64 {
        self.resolution
    }

    /// The bound h̄ = (1/(β + γ))^(1/n) of |h| from a relaxed start.
    pub fn bound(&self) -> f64 {
        (self.beta + self.gamma).powf(-1.0 / self.exponent)
    }

    /// The number of substeps N of an input increment `dz`:
    /// ⌈|dz|/δ_max⌉ within \[1, [`BoucWen::MAX_SUBSTEPS`]\], δ_max = ε·h̄·(β + γ)/(2·β·n).
    ///
    /// ```
    /// use structid_core::BoucWen;
    /// let bw = BoucWen::new(1.0, 1.0, 0.5, 0.5).unwrap();
    /// // δ_max = 0.05·1·1/(2·0.5·1) = 0.05.
    /// assert_eq!((bw.substeps(0.0), bw.substeps(0.05), bw.substeps(-0.0501)), (1, 1, 2));
    /// ```
    pub fn substeps(&self, dz: f64) -> usize {
        let max_step = self.resolution * self.bound() * (self.beta + self.gamma)
            / (2.0 * self.beta * self.exponent);
        // `as` saturates: NaN gives 0 and +∞ the maximum, both then clamped.
        ((dz.abs() / max_step).ceil() as usize).clamp(1, Self::MAX_SUBSTEPS)
    }

    /// f(h) = dh/dz for an increment of sign `sign`.
    fn rate(&self, h: f64, sign: f64) -> f64 {
        let n = self.exponent;
        let a = h.abs();
        1.0 - self.beta * sign * h * a.powf(n - 1.0) - self.gamma * a.powf(n)
    }

    /// (∂f/∂h, ∂f/∂β, ∂f/∂γ) of [`BoucWen::rate`].
    fn rate_partials(&self, h: f64, sign: f64) -> [f64; 3] {
        let n = self.exponent;
        let a = h.abs();
        let pow1 = a.powf(n - 1.0);
        let dh = -n * pow1 * (self.beta * sign + self.gamma * h.signum());
        [dh, -sign * h * pow1, -a * pow1]
    }

    /// One Heun substep of length `delta` from `h`.
    fn substep(&self, h: f64, delta: f64, sign: f64) -> f64 {
        let k1 = self.rate(h, sign);
        let k2 = self.rate(h + delta * k1, sign);
        h + 0.5 * delta * (k1 + k2)
    }

    /// [`BoucWen::substep`] with its partials with respect to (h, δ, β, γ).
    fn substep_partials(&self, h: f64, delta: f64, sign: f64) -> (f64, [f64; 4]) {
        let k1 = self.rate(h, sign);
        let h1 = h + delta * k1;
        let k2 = self.rate(h1, sign);
        let [g1h, g1b, g1g] = self.rate_partials(h, sign);
        let [g2h, g2b, g2g] = self.rate_partials(h1, sign);
        // k₂ depends on every input through h₁ = h + δ·k₁ as well as directly.
        let d = [
            1.0 + 0.5 * delta * (g1h + g2h * (1.0 + delta * g1h)),
            0.5 * (k1 + k2) + 0.5 * delta * g2h * k1,
            0.5 * delta * (g1b + g2b + g2h * delta * g1b),
            0.5 * delta * (g1g + g2g + g2h * delta * g1g),
        ];
        (h + 0.5 * delta * (k1 + k2), d)
    }

    /// The sign σ of an increment, +1 for 0.
    fn sign_of(dz: f64) -> f64 {
        if dz < 0.0 { -1.0 } else { 1.0 }
    }

    /// h after the increment `dz` from `h`.
    fn advance(&self, mut h: f64, dz: f64) -> f64 {
        let count = self.substeps(dz);
        let (delta, sign) = (dz / count as f64, Self::sign_of(dz));
        for _ in 0..count {
            h = self.substep(h, delta, sign);
        }
        h
    }

    /// h after the increment `dz` from `h`, with its partials with respect to (h, Δz, β, γ) for
    /// the substep count of `dz` held fixed.
    fn advance_partials(&self, mut h: f64, dz: f64) -> (f64, [f64; 4]) {
        let count = self.substeps(dz);
        let (delta, sign) = (dz / count as f64, Self::sign_of(dz));
        let mut total = [1.0, 0.0, 0.0, 0.0];
        for _ in 0..count {
            let (next, [dh, dd, db, dg]) = self.substep_partials(h, delta, sign);
            let direct = [0.0, dd / count as f64, db, dg];
            for (t, d) in total.iter_mut().zip(direct) {
                *t = dh * *t + d;
            }
            h = next;
        }
        (h, total)
    }
}

impl HysteresisOperator for BoucWen {
    fn kind(&self) -> &'static str {
        "bouc-wen"
    }

    fn state_len(&self) -> usize {
        2
    }

    fn parameters(&self) -> Vec<f64> {
        vec![self.gain, self.weight, self.beta, self.gamma]
    }

    fn parameter_names(&self) -> Vec<String> {
        ["gain", "weight", "beta", "gamma"]
            .map(String::from)
            .to_vec()
    }

    fn with_parameters(&self, p: &[f64]) -> Result<Box<dyn HysteresisOperator>> {
        check_count("Bouc–Wen", p, 4)?;
        Ok(Box::new(self.reparametrised(p)?))
    }

    fn boxed(&self) -> Box<dyn HysteresisOperator> {
        Box::new(self.clone())
    }

    fn initial_state(&self, z0: f64, state: &mut [f64]) {
        state[0] = 0.0;
        state[1] = z0;
    }

    fn step(&self, state: &mut [f64], z: f64) -> f64 {
        let h = self.advance(state[0], z - state[1]);
        (state[0], state[1]) = (h, z);
        self.gain * z + self.weight * h
    }

    fn step_jacobian(&self, state: &mut [f64], z: f64, jac: &mut OperatorJacobian) -> f64 {
        let (h, [dh, ddz, dbeta, dgamma]) = self.advance_partials(state[0], z - state[1]);
        let b = self.weight;
        // State (h, z_prev) → (h⁺, z): Δz = z − z_prev, so ∂/∂z_prev = −∂/∂Δz.
        jac.ds_ds.copy_from_slice(&[dh, -ddz, 0.0, 0.0]);
        jac.ds_dz.copy_from_slice(&[ddz, 1.0]);
        jac.ds_dp
            .copy_from_slice(&[0.0, 0.0, dbeta, dgamma, 0.0, 0.0, 0.0, 0.0]);
        jac.dw_ds.copy_from_slice(&[b * dh, -b * ddz]);
        jac.dw_dz = self.gain + b * ddz;
        jac.dw_dp.copy_from_slice(&[z, h, b * dbeta, b * dgamma]);
        (state[0], state[1]) = (h, z);
        self.gain * z + self.weight * h
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::f64::consts::PI;
    use structid_lti::testing::SplitMix64;

    fn run(op: &dyn HysteresisOperator, z: &[f64]) -> Vec<f64> {
        let mut w = vec![0.0; z.len()];
        apply_from_rest_into(op, z, &mut w);
        w
    }

    /// The states after each sample, from rest at z[0].
    fn states(op: &dyn HysteresisOperator, z: &[f64]) -> Vec<Vec<f64>> {
        let mut s = vec![0.0; op.state_len()];
        op.initial_state(z[0], &mut s);
        z.iter()
            .map(|&x| {
                op.step(&mut s, x);
                s.clone()
            })
            .collect()
    }

    fn name_of(e: Error) -> String {
        match e {
            Error::InvalidParameter { name, .. } => name,
            other => panic!("not an invalid parameter: {other:?}"),
        }
    }

    /// The play's output on A·sin(2πk/P) is, after the first quarter period, z − c while rising
    /// past the last minimum by 2c, z + c while falling past the last maximum by 2c, and the
    /// constant A − c (after a maximum) or −A + c (after a minimum) in between.
    #[test]
    fn a_play_on_a_sine_follows_the_closed_form() {
        for (amplitude, c, period) in [(1.0, 0.3, 200usize), (2.5, 1.0, 64), (0.7, 0.05, 1000)] {
            let omega = 2.0 * PI / period as f64;
            let z: Vec<f64> = (0..3 * period)
                .map(|k| amplitude * (omega * k as f64).sin())
                .collect();
            let w = run(&Play::new(c).unwrap(), &z);
            for k in period / 4..z.len() {
                let rising = (omega * k as f64).cos() > 0.0;
                let expected = match rising {
                    true if z[k] >= -amplitude + 2.0 * c => z[k] - c,
                    true => -amplitude + c,
                    false if z[k] <= amplitude - 2.0 * c => z[k] + c,
                    false => amplitude - c,
                };
                assert!(
                    (w[k] - expected).abs() < 1e-12,
                    "A = {amplitude}, c = {c}, k = {k}: w = {}, expected {expected}",
                    w[k]
                );
            }
        }
    }

    /// Each operator's constructor, `with_parameters` and `parameters` agree, and a signal run
    /// in two pieces gives what it gives in one.
    #[test]
    fn parameters_round_trip_and_signals_run_in_pieces() {
        let ops: Vec<Box<dyn HysteresisOperator>> = vec![
            Box::new(Play::new(0.4).unwrap()),
            Box::new(Stop::new(0.4).unwrap()),
            Box::new(PrandtlIshlinskii::uniform(1.0, 0.5, vec![1.0, -0.5, 2.0]).unwrap()),
            Box::new(BoucWen::with_exponent(0.3, 1.2, 0.8, 0.1, 2.0).unwrap()),
        ];
        let z: Vec<f64> = (0..300).map(|k| 2.0 * (k as f64 * 0.07).sin()).collect();
        for op in &ops {
            let p = op.parameters();
            assert_eq!(p.len(), op.parameter_names().len(), "{op:?}");
            let again = op.with_parameters(&p).unwrap();
            assert_eq!(format!("{again:?}"), format!("{op:?}"));
            let whole = run(op.as_ref(), &z);
            let mut state = vec![0.0; op.state_len()];
            op.initial_state(z[0], &mut state);
            let mut pieces = vec![0.0; z.len()];
            let (a, b) = pieces.split_at_mut(117);
            apply_into(op.as_ref(), &z[..117], &mut state, a);
            apply_into(op.as_ref(), &z[117..], &mut state, b);
            assert_eq!(whole, pieces, "{}", op.kind());
            assert!(op.clone().with_parameters(&p[..p.len() - 1]).is_err());
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]

        /// The stop against the play it complements (w = z − play), against its own increment
        /// form s_k = clamp(s_(k−1) + z_k − z_(k−1), −c, c), and within its threshold.
        #[test]
        fn prop_a_stop_is_z_minus_the_play_and_stays_within_its_threshold(
            seed in any::<u64>(),
            c in 0.01f64..3.0,
            len in 2usize..300,
        ) {
            let mut rng = SplitMix64::new(seed);
            let mut z = vec![rng.uniform_in(-5.0, 5.0)];
            for _ in 1..len {
                let last = z[z.len() - 1];
                z.push(last + rng.uniform_in(-1.5, 1.5));
            }
            let stop = run(&Stop::new(c).unwrap(), &z);
            let play = run(&Play::new(c).unwrap(), &z);
            let mut s = 0.0;
            for k in 0..len {
                if k > 0 {
                    s = (s + z[k] - z[k - 1]).clamp(-c, c);
                }
                prop_assert!(stop[k].abs() <= c, "|{}| > {c}", stop[k]);
                prop_assert!((stop[k] - (z[k] - play[k])).abs() < 1e-12, "k = {k}");
                prop_assert!((stop[k] - s).abs() < 1e-12, "k = {k}: {} vs {s}", stop[k]);
            }
        }
    }

    /// A random Prandtl–Ishlinskii operator: m stops up to `r_max` with weights of either sign.
    fn random_pi(rng: &mut SplitMix64, m: usize, r_max: f64) -> PrandtlIshlinskii {
        let mut r: Vec<f64> = (0..m).map(|_| rng.uniform_in(0.01, r_max)).collect();
        r.sort_by(f64::total_cmp);
        r.dedup();
        let weights = r.iter().map(|_| rng.uniform_in(-1.0, 2.0)).collect();
        PrandtlIshlinskii::new(r, rng.uniform_in(-1.0, 1.0), weights).unwrap()
    }

    /// A random walk of 1 to `max_len` samples from `start`.
    fn random_walk(rng: &mut SplitMix64, start: f64, max_len: usize, step: f64) -> Vec<f64> {
        let len = 1 + (rng.next_u64() % max_len as u64) as usize;
        let mut z = Vec::with_capacity(len);
        let mut v = start;
        for _ in 0..len {
            v += rng.uniform_in(-step, step);
            z.push(v);
        }
        z
    }

    /// Outputs equal up to rounding: the stop yields exactly at ±r from one history and gets
    /// there as z − b from the other (see the module's notes on the stop's output).
    fn assert_close(a: &[f64], b: &[f64]) -> std::result::Result<(), TestCaseError> {
        for (k, (x, y)) in a.iter().zip(b).enumerate() {
            prop_assert!(
                (x - y).abs() <= 1e-12 * (1.0 + x.abs()),
                "k = {k}: {x} vs {y}"
            );
        }
        Ok(())
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]

        /// Wiping-out: two histories from the same rest point that differ only before a common
        /// new extremum M give the same outputs from M on. M lies beyond every earlier input and
        /// at least r_m beyond the rest point z₀ (the relaxed state remembers a reversal r_i
        /// away from z₀, which M must wipe out too). The followers (the memory) agree exactly.
        #[test]
        fn prop_prandtl_ishlinskii_wipes_out_smaller_reversals(
            seed in any::<u64>(),
            m in 1usize..6,
            upward in any::<bool>(),
        ) {
            let mut rng = SplitMix64::new(seed);
            let pi = random_pi(&mut rng, m, 1.5);
            let r_max = pi.thresholds()[pi.thresholds().len() - 1];
            let z0 = rng.uniform_in(-1.0, 1.0);
            let prefix = random_walk(&mut rng, z0, 20, 1.0);
            let end = prefix[prefix.len() - 1];
            let inner_a = random_walk(&mut rng, end, 20, 1.0);
            let inner_b = random_walk(&mut rng, end, 20, 1.0);
            let suffix = random_walk(&mut rng, 0.0, 30, 1.0);
            let sign = if upward { 1.0 } else { -1.0 };
            let beyond = [&prefix, &inner_a, &inner_b]
                .iter()
                .flat_map(|v| v.iter())
                .fold(sign * z0 + r_max, |acc, &v| acc.max(sign * v));
            let extremum = sign * (beyond + rng.uniform_in(1e-3, 0.5));
            let history = |inner: &[f64]| -> Vec<f64> {
                let mut z = vec![z0];
                z.extend_from_slice(&prefix);
                z.extend_from_slice(inner);
                z.push(extremum);
                z.extend(suffix.iter().map(|s| extremum + s));
                z
            };
            let (za, zb) = (history(&inner_a), history(&inner_b));
            let (wa, wb) = (run(&pi, &za), run(&pi, &zb));
            let tail = suffix.len() + 1;
            assert_close(&wa[wa.len() - tail..], &wb[wb.len() - tail..])?;
            let (sa, sb) = (states(&pi, &za), states(&pi, &zb));
            prop_assert_eq!(&sa[sa.len() - tail..], &sb[sb.len() - tail..]);
        }

        /// Rate independence: the same piecewise-monotone path sampled at its reversal points
        /// only, and with extra samples inserted on its monotone segments, gives the same
        /// outputs at the common points and exactly the same followers.
        #[test]
        fn prop_prandtl_ishlinskii_is_rate_independent(
            seed in any::<u64>(),
            m in 1usize..6,
            reversals in 2usize..12,
        ) {
            let mut rng = SplitMix64::new(seed);
            let pi = random_pi(&mut rng, m, 1.5);
            let coarse = random_walk(&mut rng, 0.0, reversals, 3.0);
            let mut fine = vec![coarse[0]];
            let mut common = vec![0];
            for pair in coarse.windows(2) {
                let (lo, hi) = (pair[0].min(pair[1]), pair[0].max(pair[1]));
                let mut t: Vec<f64> = (0..rng.next_u64() % 6).map(|_| rng.uniform()).collect();
                t.sort_by(f64::total_cmp);
                // Clamped so that rounding cannot step past the segment's ends.
                fine.extend(t.iter().map(|t| (pair[0] + t * (pair[1] - pair[0])).clamp(lo, hi)));
                fine.push(pair[1]);
                common.push(fine.len() - 1);
            }
            let (wc, wf) = (run(&pi, &coarse), run(&pi, &fine));
            let picked: Vec<f64> = common.iter().map(|&k| wf[k]).collect();
            assert_close(&wc, &picked)?;
            let (sc, sf) = (states(&pi, &coarse), states(&pi, &fine));
            let picked: Vec<Vec<f64>> = common.iter().map(|&k| sf[k].clone()).collect();
            prop_assert_eq!(sc, picked);
        }
    }

    /// A random Bouc–Wen operator of the bounded class, β + γ ≥ 0.1·β.
    fn random_bouc_wen(rng: &mut SplitMix64, exponent: f64) -> BoucWen {
        let beta = rng.uniform_in(0.2, 2.0);
        let gamma = rng.uniform_in(-0.9 * beta, beta);
        let (a, b) = (rng.uniform_in(-1.0, 1.0), rng.uniform_in(0.2, 2.0));
        BoucWen::with_exponent(a, b, beta, gamma, exponent).unwrap()
    }

    /// h along z from rest at z[0].
    fn bouc_wen_h(op: &BoucWen, z: &[f64]) -> Vec<f64> {
        states(op, z).into_iter().map(|s| s[0]).collect()
    }

    /// Driven far beyond yielding, h reaches its bound h̄ = (1/(β + γ))^(1/n) and never exceeds
    /// it.
    #[test]
    fn bouc_wen_stays_within_its_bound() {
        let mut rng = SplitMix64::new(11);
        for exponent in [1.0, 1.5, 2.0, 4.0] {
            for _ in 0..10 {
                let op = random_bouc_wen(&mut rng, exponent);
                let bound = (1.0 / (op.beta + op.gamma)).powf(1.0 / exponent);
                assert!((op.bound() - bound).abs() < 1e-12 * bound);
                let z: Vec<f64> = (0..2000)
                    .map(|k| 20.0 * bound * (k as f64 * 0.013).sin())
                    .collect();
                let h = bouc_wen_h(&op, &z);
                let peak = h.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                assert!(peak <= bound * (1.0 + 1e-9), "{op:?}: {peak} > {bound}");
                assert!(peak > 0.999 * bound, "{op:?}: {peak} never near {bound}");
            }
        }
    }

    /// A periodic input of 10·h̄ with 400 samples a period: the first cycle (from the virgin
    /// state) differs from the second, and every later cycle repeats the second.
    #[test]
    fn bouc_wen_loop_closes_after_the_first_cycle() {
        let mut rng = SplitMix64::new(5);
        for exponent in [1.0, 2.0] {
            let op = random_bouc_wen(&mut rng, exponent);
            let period = 400;
            // From k mod P so the input repeats bit for bit.
            let z: Vec<f64> = (0..4 * period)
                .map(|k| 10.0 * op.bound() * (2.0 * PI * (k % period) as f64 / period as f64).sin())
                .collect();
            let w = run(&op, &z);
            let cycle = |i: usize| &w[i * period..(i + 1) * period];
            let gap = |a: &[f64], b: &[f64]| {
                a.iter()
                    .zip(b)
                    .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
            };
            let scale = op.weight * op.bound();
            assert!(gap(cycle(0), cycle(1)) > 0.1 * scale, "{op:?}");
            for i in 2..4 {
                assert!(gap(cycle(1), cycle(i)) < 1e-7 * scale, "{op:?}, cycle {i}");
            }
        }
    }

    /// For n = 1 the loop is piecewise exponential: from rest, loading gives
    /// h = (1 − e^(−(β+γ)·Δ))/(β+γ); from h₀ > 0, unloading by u gives
    /// h = (h₀ + 1/(β−γ))·e^(−(β−γ)·u) − 1/(β−γ) until h reaches 0. The substeps converge to
    /// it at second order.
    #[test]
    fn bouc_wen_converges_to_the_closed_form_for_n_1() {
        let (beta, gamma) = (0.9, 0.3);
        let (sum, diff) = (beta + gamma, beta - gamma);
        let load: Vec<f64> = (0..=40).map(|k| k as f64 * 0.1).collect();
        let h0 = (1.0 - (-sum * 4.0f64).exp()) / sum;
        // Unloading from z = 4 stops before h reaches 0 (at u = ln(1 + (β−γ)h₀)/(β−γ)).
        let u_zero = (1.0 + diff * h0).ln() / diff;
        let unload: Vec<f64> = (1..=20).map(|k| 4.0 - k as f64 * 0.0499 * u_zero).collect();
        let z: Vec<f64> = load.iter().chain(&unload).copied().collect();
        let exact: Vec<f64> = z
            .iter()
            .enumerate()
            .map(|(k, &zk)| match k < load.len() {
                true => (1.0 - (-sum * zk).exp()) / sum,
                false => (h0 + 1.0 / diff) * (-diff * (4.0 - zk)).exp() - 1.0 / diff,
            })
            .collect();
        let error = |resolution: f64| {
            let op = BoucWen::new(0.0, 1.0, beta, gamma)
                .unwrap()
                .with_resolution(resolution)
                .unwrap();
            let h = bouc_wen_h(&op, &z);
            h.iter()
                .zip(&exact)
                .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()))
        };
        // δ_max from 0.056 down to 0.007 in z: about twice the substeps each time.
        let errors: Vec<f64> = [0.1, 0.05, 0.025, 0.0125].map(error).to_vec();
        for pair in errors.windows(2) {
            // Heun is second order: halving the substeps divides the error by about 4.
            assert!(pair[1] < 0.35 * pair[0], "{errors:?}");
        }
        // The default resolution is within 10⁻⁴ of the bound h̄ = 1/(β+γ).
        assert!(errors[1] < 1e-4 / sum, "{errors:?}");
    }

    /// Central differences of every output of one step (state after, w) with respect to the
    /// state before, z and the parameters, against `step_jacobian`, which must also agree with
    /// `step` exactly.
    fn check_jacobian(
        op: &dyn HysteresisOperator,
        state: &[f64],
        z: f64,
        e: f64,
        tol: f64,
    ) -> std::result::Result<(), TestCaseError> {
        let (ns, p) = (op.state_len(), op.parameters());
        let np = p.len();
        let eval = |op: &dyn HysteresisOperator, s: &[f64], z: f64| {
            let mut s = s.to_vec();
            let w = op.step(&mut s, z);
            (s, w)
        };
        let mut jac = OperatorJacobian::for_operator(op);
        jac.ds_ds.fill(f64::NAN);
        jac.ds_dp.fill(f64::NAN);
        let mut after = state.to_vec();
        let w = op.step_jacobian(&mut after, z, &mut jac);
        prop_assert_eq!((after.clone(), w), eval(op, state, z));
        let diff = |plus: (Vec<f64>, f64), minus: (Vec<f64>, f64)| {
            let ds: Vec<f64> = plus
                .0
                .iter()
                .zip(&minus.0)
                .map(|(a, b)| (a - b) / (2.0 * e))
                .collect();
            (ds, (plus.1 - minus.1) / (2.0 * e))
        };
        let close = |name: String, a: f64, b: f64| {
            prop_assert!(
                (a - b).abs() <= tol * (1.0 + b.abs()),
                "{}: analytic {} vs numeric {}",
                name,
                a,
                b
            );
            Ok(())
        };
        for j in 0..ns {
            let moved = |d: f64| {
                let mut s = state.to_vec();
                s[j] += d;
                eval(op, &s, z)
            };
            let (ds, dw) = diff(moved(e), moved(-e));
            for i in 0..ns {
                close(format!("ds{i}/ds{j}"), jac.ds_ds[i * ns + j], ds[i])?;
            }
            close(format!("dw/ds{j}"), jac.dw_ds[j], dw)?;
        }
        let (ds, dw) = diff(eval(op, state, z + e), eval(op, state, z - e));
        for i in 0..ns {
            close(format!("ds{i}/dz"), jac.ds_dz[i], ds[i])?;
        }
        close("dw/dz".into(), jac.dw_dz, dw)?;
        for j in 0..np {
            let moved = |d: f64| {
                let mut q = p.clone();
                q[j] += d;
                eval(op.with_parameters(&q).unwrap().as_ref(), state, z)
            };
            let (ds, dw) = diff(moved(e), moved(-e));
            for i in 0..ns {
                close(format!("ds{i}/dp{j}"), jac.ds_dp[i * np + j], ds[i])?;
            }
            close(format!("dw/dp{j}"), jac.dw_dp[j], dw)?;
        }
        Ok(())
    }

    /// Whether b is within `margin` of a play's kinks z ± c.
    fn near_kink(b: f64, z: f64, c: f64, margin: f64) -> bool {
        (b - (z - c)).abs() < margin || (b - (z + c)).abs() < margin
    }

    /// Whether one Bouc–Wen step passes within `margin` of a non-smooth point: a change of the
    /// substep count under the finite-difference moves, or (n = 1) a substep's h or predictor
    /// near 0.
    fn bouc_wen_near_kink(op: &BoucWen, h: f64, z_prev: f64, z: f64, e: f64, margin: f64) -> bool {
        let dz = z - z_prev;
        let count = op.substeps(dz);
        let moved = [dz + e, dz - e].map(|d| op.substeps(d));
        let sums = [e, -e].map(|d| {
            let other = BoucWen {
                beta: op.beta + d,
                ..op.clone()
            };
            let gamma = BoucWen {
                gamma: op.gamma + d,
                ..op.clone()
            };
            (other.substeps(dz), gamma.substeps(dz))
        });
        if moved.iter().any(|&n| n != count) || sums.iter().any(|&(a, b)| a != count || b != count)
        {
            return true;
        }
        if op.exponent != 1.0 {
            return false;
        }
        let (delta, sign) = (dz / count as f64, BoucWen::sign_of(dz));
        let mut h = h;
        for _ in 0..count {
            let predictor = h + delta * op.rate(h, sign);
            if h.abs() < margin || predictor.abs() < margin {
                return true;
            }
            h = op.substep(h, delta, sign);
        }
        false
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(200))]

        #[test]
        fn prop_play_and_stop_jacobians_match_finite_differences(
            c in 0.01f64..2.0,
            b in -3.0f64..3.0,
            z in -3.0f64..3.0,
        ) {
            prop_assume!(!near_kink(b, z, c, 1e-6));
            check_jacobian(&Play::new(c).unwrap(), &[b], z, 1e-8, 1e-6)?;
            check_jacobian(&Stop::new(c).unwrap(), &[b], z, 1e-8, 1e-6)?;
        }

        #[test]
        fn prop_prandtl_ishlinskii_jacobian_matches_finite_differences(
            seed in any::<u64>(),
            m in 1usize..6,
            z in -3.0f64..3.0,
        ) {
            let mut rng = SplitMix64::new(seed);
            let pi = random_pi(&mut rng, m, 2.0);
            let state: Vec<f64> = pi.thresholds().iter().map(|_| rng.uniform_in(-3.0, 3.0)).collect();
            let near = state.iter().zip(pi.thresholds()).any(|(&b, &r)| near_kink(b, z, r, 1e-6));
            prop_assume!(!near);
            check_jacobian(&pi, &state, z, 1e-8, 1e-6)?;
        }

        #[test]
        fn prop_bouc_wen_jacobian_matches_finite_differences(
            seed in any::<u64>(),
            exponent in prop::sample::select(vec![1.0, 1.5, 2.0, 3.0]),
            fraction in -1.0f64..1.0,
            z_prev in -2.0f64..2.0,
            increment in -3.0f64..3.0,
        ) {
            let mut rng = SplitMix64::new(seed);
            let op = random_bouc_wen(&mut rng, exponent);
            let bound = op.bound();
            let (h, z) = (fraction * bound, z_prev + increment * bound);
            let e = 1e-6 * bound.max(1.0);
            prop_assume!(!bouc_wen_near_kink(&op, h, z_prev, z, 10.0 * e, 1e-3 * bound));
            check_jacobian(&op, &[h, z_prev], z, e, 1e-5)?;
        }
    }

    #[test]
    fn out_of_range_parameters_are_named() {
        let cases: Vec<(Error, &str)> = vec![
            (Play::new(-0.1).unwrap_err(), "half_width"),
            (Play::new(f64::NAN).unwrap_err(), "half_width"),
            (Stop::new(0.0).unwrap_err(), "threshold"),
            (Stop::new(f64::INFINITY).unwrap_err(), "threshold"),
            (
                PrandtlIshlinskii::new(vec![], 1.0, vec![]).unwrap_err(),
                "thresholds",
            ),
            (
                PrandtlIshlinskii::new(vec![-1.0], 1.0, vec![1.0]).unwrap_err(),
                "threshold_1",
            ),
            (
                PrandtlIshlinskii::new(vec![0.5, 0.4], 1.0, vec![1.0; 2]).unwrap_err(),
                "threshold_2",
            ),
            (
                PrandtlIshlinskii::new(vec![0.5, f64::NAN], 1.0, vec![1.0; 2]).unwrap_err(),
                "threshold_2",
            ),
            (
                PrandtlIshlinskii::new(vec![0.5], f64::NAN, vec![1.0]).unwrap_err(),
                "gain",
            ),
            (
                PrandtlIshlinskii::new(vec![0.5, 1.0], 1.0, vec![1.0, f64::NAN]).unwrap_err(),
                "weight_2",
            ),
            (
                PrandtlIshlinskii::uniform(0.0, 1.0, vec![1.0]).unwrap_err(),
                "max_threshold",
            ),
            (
                BoucWen::new(1.0, 1.0, 0.5, -0.5).unwrap_err(),
                "beta + gamma",
            ),
            (
                BoucWen::new(1.0, 1.0, 0.2, 0.5).unwrap_err(),
                "beta - gamma",
            ),
            (BoucWen::new(1.0, 1.0, f64::NAN, 0.5).unwrap_err(), "beta"),
            (
                BoucWen::new(1.0, f64::INFINITY, 0.5, 0.5).unwrap_err(),
                "weight",
            ),
            (
                BoucWen::with_exponent(1.0, 1.0, 0.5, 0.5, 0.5).unwrap_err(),
                "exponent",
            ),
            (
                BoucWen::new(1.0, 1.0, 0.5, 0.5)
                    .unwrap()
                    .with_resolution(0.0)
                    .unwrap_err(),
                "resolution",
            ),
        ];
        for (e, name) in cases {
            let text = e.to_string();
            assert_eq!(name_of(e), name, "{text}");
        }
        let pi = PrandtlIshlinskii::uniform(1.0, 1.0, vec![1.0; 2]).unwrap();
        assert_eq!(
            name_of(pi.with_parameters(&[1.0, f64::NAN, 0.0]).unwrap_err()),
            "weight_1"
        );
        let bw = BoucWen::new(1.0, 1.0, 0.5, 0.5).unwrap();
        assert_eq!(
            name_of(bw.with_parameters(&[1.0, 1.0, -1.0, 0.5]).unwrap_err()),
            "beta + gamma"
        );
        assert_eq!(
            name_of(
                Play::new(0.1)
                    .unwrap()
                    .with_parameters(&[-1.0])
                    .unwrap_err()
            ),
            "half_width"
        );
        assert!(matches!(
            Stop::new(0.1).unwrap().with_parameters(&[]),
            Err(Error::DimensionMismatch { .. })
        ));
        assert!(matches!(
            PrandtlIshlinskii::new(vec![0.5], 1.0, vec![1.0, 2.0]),
            Err(Error::DimensionMismatch { .. })
        ));
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(256))]

        /// Any f64s, NaN and infinities included: an error or an operator in range, no panic.
        #[test]
        fn prop_constructors_refuse_without_panicking(
            p in prop::array::uniform5(prop_oneof![
                any::<f64>(),
                Just(f64::NAN),
                Just(0.0),
                -2.0f64..2.0,
            ]),
        ) {
            if let Ok(op) = BoucWen::with_exponent(p[0], p[1], p[2], p[3], p[4]) {
                prop_assert!(op.beta + op.gamma > 0.0 && op.beta >= op.gamma && op.exponent >= 1.0);
                prop_assert!(op.parameters().iter().all(|v| v.is_finite()));
            }
            if let Ok(play) = Play::new(p[0]) {
                prop_assert!(play.half_width() >= 0.0 && play.half_width().is_finite());
            }
            if let Ok(stop) = Stop::new(p[0]) {
                prop_assert!(stop.threshold() > 0.0 && stop.threshold().is_finite());
            }
            if let Ok(pi) = PrandtlIshlinskii::new(p[..2].to_vec(), p[2], p[3..].to_vec()) {
                prop_assert!(pi.thresholds()[0] > 0.0 && pi.thresholds()[1] > pi.thresholds()[0]);
                prop_assert!(pi.parameters().iter().all(|v| v.is_finite()));
            }
        }
    }
}
