//! Wiener–Hammerstein models with both LTI blocks unknown, and where their fit starts.
//!
//! The model is `y = G₂·N(G₁·u) + e`: a front block G₁, a static map N, a back block G₂, as
//! one LFT with the state x = [x₁; x₂]
//!
//! ```text
//!   x₁⁺ = A₁x₁ + B₁u,   z = C₁x₁ + D₁u,   w = N(z),   x₂⁺ = A₂x₂ + B₂w,   y = C₂x₂ + D₂w + e.
//! ```
//!
//! Nothing in it is measurable, so the paper's identification cannot reach it; the joint fit
//! can, from a start close enough. The start follows the classical route:
//!
//! 1. the best linear approximation `B/F` of the system, an output-error model of the two
//!    blocks' orders together (by Bussgang's theorem it is `∝ G₂·G₁` for Gaussian-like inputs);
//! 2. every division of its poles and zeros between the blocks
//!    ([`structid_linear::block_splits`]);
//! 3. for each division, N fitted by least squares with both blocks fixed
//!    ([`GaussianFeatures::fitted_through`]: z = G₁u is known, and y is linear in N's
//!    coefficients through G₂). The division whose fit leaves the smallest RMS error on the
//!    estimation data is the start ([`wiener_hammerstein_start`]).
//!
//! In the start each block is in observable canonical form (C = e₁ᵀ, which removes the blocks'
//! similarity freedom), and its denominator and numerator coefficients are free (A's first
//! column and B) except the leading numerator coefficient, D for a block with a direct term or
//! the first non-zero entry of B after the delay. That coefficient is the block's gain, which
//! the map's input and output scales would otherwise trade against it without changing the
//! output; the delay is kept too.

use nalgebra::DMatrix;
use structid_core::{Data, Lft, LftMatrices};
use structid_linear::{BlockSplit, PolynomialModel, block_splits};
use structid_lti::Signal;

use crate::error::{JointError, Result, invalid};
use crate::features::GaussianFeatures;
use crate::features::LinearInParameters;
use crate::model::{JointBlock, JointModel, LftMatrix};

/// How the start's map is laid out: centres, width and dispersion weight.
#[derive(Clone, Debug, PartialEq)]
pub struct WienerHammersteinSettings {
    centres: usize,
    beta: f64,
    margin: f64,
}

impl Default for WienerHammersteinSettings {
    fn default() -> Self {
        Self {
            centres: 15,
            beta: 1e-8,
            margin: 0.1,
        }
    }
}

impl WienerHammersteinSettings {
    /// Defaults: 15 centres, β = 1e-8, a margin of 10 % of z's range on each side.
    pub fn builder() -> WienerHammersteinSettingsBuilder {
        WienerHammersteinSettingsBuilder(Self::default())
    }

    /// Number of centres of N, spread evenly over z's range plus the margins.
    pub fn centres(&self) -> usize {
        self.centres
    }

    /// The dispersion weight β of N (as in [`GaussianFeatures`]).
    pub fn beta(&self) -> f64 {
        self.beta
    }

    /// The fraction of z's range added on each side of it for the centres: the joint fit moves
    /// G₁, and z with it.
    pub fn margin(&self) -> f64 {
        self.margin
    }
}

/// Builder of [`WienerHammersteinSettings`]; [`build`](Self::build) validates.
#[derive(Clone, Debug)]
pub struct WienerHammersteinSettingsBuilder(WienerHammersteinSettings);

impl WienerHammersteinSettingsBuilder {
    /// Number of centres (at least 2).
    pub fn centres(mut self, m: usize) -> Self {
        self.0.centres = m;
        self
    }

    /// Dispersion weight (finite, ≥ 0).
    pub fn beta(mut self, beta: f64) -> Self {
        self.0.beta = beta;
        self
    }

    /// Margin as a fraction of z's range (finite, ≥ 0).
    pub fn margin(mut self, margin: f64) -> Self {
        self.0.margin = margin;
        self
    }

    /// The validated settings.
    ///
    /// ```
    /// use structid_joint::WienerHammersteinSettings;
    /// assert!(WienerHammersteinSettings::builder().centres(1).build().is_err());
    /// assert!(WienerHammersteinSettings::builder().beta(-1.0).build().is_err());
    /// assert_eq!(WienerHammersteinSettings::builder().build().unwrap().centres(), 15);
    /// ```
    pub fn build(self) -> Result<WienerHammersteinSettings> {
        let s = self.0;
        if s.centres < 2 {
            return Err(invalid("centres", s.centres as f64, "at least 2"));
        }
        if !(s.beta.is_finite() && s.beta >= 0.0) {
            return Err(invalid("beta", s.beta, "finite and not negative"));
        }
        if !(s.margin.is_finite() && s.margin >= 0.0) {
            return Err(invalid("margin", s.margin, "finite and not negative"));
        }
        Ok(s)
    }
}

/// One division of the poles and zeros, and how well a map fitted behind it explains the data.
#[derive(Clone, Debug)]
pub struct SplitScore {
    /// The division.
    pub split: BlockSplit,
    /// RMS of y − G₂·N(G₁·u) over the estimation data with N fitted by least squares (∞ when
    /// the fit failed).
    pub rms: f64,
}

/// The start of a Wiener–Hammerstein joint fit and the evidence for it.
#[derive(Clone, Debug)]
pub struct WienerHammersteinStart {
    /// The best division as a joint model with its free entries.
    pub model: JointModel,
    /// Every division, best first.
    pub splits: Vec<SplitScore>,
}

/// The start of a Wiener–Hammerstein fit from the best linear approximation `bla` (a SISO
/// model of the two blocks' orders together): every division of its poles and zeros is scored
/// by the RMS error of a map fitted behind it, and the best becomes a [`JointModel`] (see the
/// [module docs](self)).
///
/// # Errors
/// A model with several inputs or outputs, too many root groups, or data on which no division
/// gives a finite fit.
pub fn wiener_hammerstein_start(
    bla: &PolynomialModel,
    data: &Data,
    settings: &WienerHammersteinSettings,
) -> Result<WienerHammersteinStart> {
    if data.u().channels() != 1 || data.y().channels() != 1 {
        return Err(JointError::InvalidModel(format!(
            "a Wiener–Hammerstein model has one input and one output; the data have {} and {}",
            data.u().channels(),
            data.y().channels()
        )));
    }
    let splits = block_splits(bla).map_err(|e| JointError::InvalidModel(e.to_string()))?;
    let mut scored: Vec<(SplitScore, Option<GaussianFeatures>)> = splits
        .into_iter()
        .map(|split| match fit_map_behind(&split, data, settings) {
            Some((map, rms)) => (SplitScore { split, rms }, Some(map)),
            None => (
                SplitScore {
                    split,
                    rms: f64::INFINITY,
                },
                None,
            ),
        })
        .collect();
    scored.sort_by(|a, b| a.0.rms.total_cmp(&b.0.rms));
    let (best, map) = match scored.first() {
        Some((s, Some(map))) if s.rms.is_finite() => (s.split.clone(), map.clone()),
        _ => {
            return Err(JointError::NoStart {
                record: 1,
                detail: "no division of the poles and zeros gives a finite map fit".into(),
            });
        }
    };
    Ok(WienerHammersteinStart {
        model: wiener_hammerstein_model(&best, map)?,
        splits: scored.into_iter().map(|(s, _)| s).collect(),
    })
}

/// Simulates `m` from rest on each record of `u` (given as one concatenated channel and the
/// record bounds).
fn simulate_records(m: &PolynomialModel, u: &[f64], bounds: &[usize]) -> Option<Vec<f64>> {
    let mut out = Vec::with_capacity(u.len());
    for r in bounds.windows(2) {
        let s = Signal::new(1, u[r[0]..r[1]].to_vec()).ok()?;
        out.extend(m.simulate(&s).ok()?);
    }
    out.iter().all(|v| v.is_finite()).then_some(out)
}

/// N fitted behind one division, and the RMS error it leaves.
fn fit_map_behind(
    split: &BlockSplit,
    data: &Data,
    settings: &WienerHammersteinSettings,
) -> Option<(GaussianFeatures, f64)> {
    let bounds = data.record_bounds();
    let z = simulate_records(&split.front, &data.u().channel(0), bounds)?;
    let lo = z.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = z.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let pad = settings.margin * (hi - lo);
    let (lo, hi) = (lo - pad, hi + pad);
    let m = settings.centres;
    let width = (hi - lo) / (m - 1) as f64;
    let features = GaussianFeatures::on_interval(lo, hi, m, width, settings.beta).ok()?;
    let y = data.y().channel(0);
    let points: Vec<Vec<f64>> = z.iter().map(|v| vec![*v]).collect();
    let mut through_back = |s: &[f64]| {
        simulate_records(&split.back, s, bounds).unwrap_or_else(|| vec![f64::NAN; s.len()])
    };
    let map = features
        .fitted_through(&points, &y, &mut through_back)
        .ok()?;
    let w: Vec<f64> = points
        .iter()
        .map(|p| crate::block::BlockMap::eval(&map, &mut [], p))
        .collect();
    let yhat = through_back(&w);
    let sse: f64 = yhat.iter().zip(&y).map(|(a, b)| (a - b) * (a - b)).sum();
    let rms = (sse / y.len() as f64).sqrt();
    rms.is_finite().then_some((map, rms))
}

/// The Wiener–Hammerstein LFT of a division with map `map`, each block in observable canonical
/// form with its coefficients free (see the [module docs](self)).
///
/// ```
/// use structid_joint::{GaussianFeatures, wiener_hammerstein_model};
/// use structid_linear::{PolynomialModel, block_splits};
/// let bla = PolynomialModel::new(vec![vec![0.0, 0.2, 0.1]], vec![1.0, -1.2, 0.35], None).unwrap();
/// let split = block_splits(&bla).unwrap().remove(1);
/// let map = GaussianFeatures::on_interval(-1.0, 1.0, 5, 0.5, 1e-8).unwrap();
/// let model = wiener_hammerstein_model(&split, map).unwrap();
/// assert_eq!(model.lft().dims().states, 2);
/// assert!(!model.free_entries().is_empty());
/// ```
///
/// # Errors
/// A block that cannot be realised.
pub fn wiener_hammerstein_model(split: &BlockSplit, map: GaussianFeatures) -> Result<JointModel> {
    let realise = |m: &PolynomialModel| {
        m.to_state_space()
            .map_err(|e| JointError::InvalidModel(format!("a block cannot be realised: {e}")))
    };
    let (g1, g2) = (realise(&split.front)?, realise(&split.back)?);
    let (n1, n2) = (g1.order(), g2.order());
    let n = n1 + n2;
    let mut a = DMatrix::zeros(n, n);
    a.view_mut((0, 0), (n1, n1)).copy_from(g1.a());
    a.view_mut((n1, n1), (n2, n2)).copy_from(g2.a());
    let mut bu = DMatrix::zeros(n, 1);
    bu.view_mut((0, 0), (n1, 1)).copy_from(g1.b());
    let mut bw = DMatrix::zeros(n, 1);
    bw.view_mut((n1, 0), (n2, 1)).copy_from(g2.b());
    let mut cy = DMatrix::zeros(1, n);
    cy.view_mut((0, n1), (1, n2)).copy_from(g2.c());
    let mut cz = DMatrix::zeros(1, n);
    cz.view_mut((0, 0), (1, n1)).copy_from(g1.c());
    let lft = Lft::new(LftMatrices {
        a,
        bu,
        be: DMatrix::zeros(n, 1),
        bw,
        cy,
        dyu: DMatrix::zeros(1, 1),
        dye: DMatrix::from_element(1, 1, 1.0),
        dyw: g2.d().clone(),
        cz,
        dzu: g1.d().clone(),
        dze: DMatrix::zeros(1, 1),
        dzw: DMatrix::zeros(1, 1),
    })?;
    let model = JointModel::new(lft, vec![JointBlock::new("N", vec![0], 0, Box::new(map))])?;
    let poles = |m: &PolynomialModel| m.den.len() - 1;
    let model = free_canonical(
        model,
        0,
        n1,
        poles(&split.front),
        LftMatrix::Bu,
        leading_delay(&split.front),
    )?;
    let model = free_canonical(
        model,
        n1,
        n2,
        poles(&split.back),
        LftMatrix::Bw,
        leading_delay(&split.back),
    )?;
    Ok(model)
}

/// The number of leading zero coefficients of a SISO numerator (its delay).
pub(crate) fn leading_delay(m: &PolynomialModel) -> usize {
    m.num[0].iter().take_while(|v| **v == 0.0).count()
}

/// Frees the coefficients of one block realised in observable canonical form at states
/// `offset .. offset + order` of the model, whose input column of `b` is 0: the block's
/// `poles` denominator coefficients (A's first column; states beyond them carry the delay and
/// stay pure delays), and the rows of B after its leading numerator coefficient. That
/// coefficient (D without a delay, else the B row of the delay) stays fixed: it is the block's
/// gain, which the maps' scales would otherwise trade against it without changing the output;
/// the delay stays too.
pub(crate) fn free_canonical(
    mut model: JointModel,
    offset: usize,
    order: usize,
    poles: usize,
    b: LftMatrix,
    delay: usize,
) -> Result<JointModel> {
    for r in 0..order {
        if r < poles {
            model = model.with_free(LftMatrix::A, offset + r, offset)?;
        }
        if delay == 0 || r >= delay {
            model = model.with_free(b, offset + r, 0)?;
        }
    }
    Ok(model)
}
