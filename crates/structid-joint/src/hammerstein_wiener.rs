//! Hammerstein–Wiener models with the LTI block and both maps unknown (MATLAB's `nlhw`).
//!
//! The model is `y = N₂(G·N₁(u)) + e`: an input map N₁, a linear block G, an output map N₂, as
//! one LFT with G's state x
//!
//! ```text
//!   w₁ = N₁(u),   x⁺ = A·x + B·w₁,   z₂ = C·x + D·w₁,   w₂ = N₂(z₂),   y = w₂ + e.
//! ```
//!
//! When G has a direct term the two maps are in series through D_zw = D. The start
//! ([`hammerstein_wiener_start`]) is the best linear approximation: G is the BLA (observable
//! canonical form, its coefficients free but its leading numerator coefficient, the gain), and
//! both maps start as the identity over the ranges of u and of the BLA's output. The joint fit
//! then moves everything. The data fix the maps only up to affine changes of the signals
//! between the blocks (a gain and an offset through G).

use nalgebra::DMatrix;
use structid_core::{Data, Lft, LftMatrices};
use structid_linear::PolynomialModel;
use structid_lti::Signal;

use crate::block::BlockMap;
use crate::error::{JointError, Result};
use crate::features::GaussianFeatures;
use crate::features::LinearInParameters;
use crate::model::{JointBlock, JointModel, LftMatrix};
use crate::wiener_hammerstein::{WienerHammersteinSettings, free_canonical, leading_delay};

/// The identity on `[lo, hi]` widened by `margin` of its width, as features of `settings`.
fn identity(lo: f64, hi: f64, settings: &WienerHammersteinSettings) -> Result<GaussianFeatures> {
    let pad = settings.margin() * (hi - lo);
    let (lo, hi) = (lo - pad, hi + pad);
    let m = settings.centres();
    let f = GaussianFeatures::on_interval(lo, hi, m, (hi - lo) / (m - 1) as f64, settings.beta())?;
    let z: Vec<Vec<f64>> = (0..2 * m)
        .map(|k| vec![lo + (hi - lo) * k as f64 / (2 * m - 1) as f64])
        .collect();
    let w: Vec<f64> = z.iter().map(|z| z[0]).collect();
    f.fitted_to(&z, &w)
}

fn span(v: &[f64]) -> Result<(f64, f64)> {
    let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if hi > lo && hi.is_finite() && lo.is_finite() {
        Ok((lo, hi))
    } else {
        Err(JointError::InvalidModel(
            "a map's input does not move over the data (or diverges), so the map cannot be placed"
                .into(),
        ))
    }
}

/// The Hammerstein–Wiener LFT of `g` with blocks `input` and `output`, G's coefficients free
/// but its gain (see the [module docs](self)). Either block may be any [`BlockMap`] of one
/// input: a kernel expansion, or a hysteresis operator (a backlash ahead of G, say).
///
/// ```
/// use structid_joint::{GaussianFeatures, hammerstein_wiener_model};
/// use structid_linear::PolynomialModel;
/// let g = PolynomialModel::new(vec![vec![0.0, 0.5]], vec![1.0, -0.5], None).unwrap();
/// let n = || GaussianFeatures::on_interval(-1.0, 1.0, 5, 0.5, 1e-8).unwrap();
/// let model = hammerstein_wiener_model(&g, Box::new(n()), Box::new(n())).unwrap();
/// assert_eq!(model.blocks().len(), 2);
/// assert_eq!(model.free_entries().len(), 1); // the pole; the gain 0.5 stays
/// ```
///
/// # Errors
/// A G with several inputs, or one that cannot be realised.
pub fn hammerstein_wiener_model(
    g: &PolynomialModel,
    input: Box<dyn BlockMap>,
    output: Box<dyn BlockMap>,
) -> Result<JointModel> {
    if g.inputs() != 1 || input.input_len() != 1 || output.input_len() != 1 {
        return Err(JointError::InvalidModel(format!(
            "a Hammerstein–Wiener model has one input and scalar maps; G has {} input(s), the maps {} and {}",
            g.inputs(),
            input.input_len(),
            output.input_len()
        )));
    }
    let ss = g
        .to_state_space()
        .map_err(|e| JointError::InvalidModel(format!("G cannot be realised: {e}")))?;
    let n = ss.order();
    let lft = Lft::new(LftMatrices {
        a: ss.a().clone(),
        bu: DMatrix::zeros(n, 1),
        be: DMatrix::zeros(n, 1),
        bw: DMatrix::from_fn(n, 2, |r, c| if c == 0 { ss.b()[(r, 0)] } else { 0.0 }),
        cy: DMatrix::zeros(1, n),
        dyu: DMatrix::zeros(1, 1),
        dye: DMatrix::from_element(1, 1, 1.0),
        dyw: DMatrix::from_row_slice(1, 2, &[0.0, 1.0]),
        cz: DMatrix::from_fn(2, n, |r, c| if r == 1 { ss.c()[(0, c)] } else { 0.0 }),
        dzu: DMatrix::from_row_slice(2, 1, &[1.0, 0.0]),
        dze: DMatrix::zeros(2, 1),
        dzw: DMatrix::from_row_slice(2, 2, &[0.0, 0.0, ss.d()[(0, 0)], 0.0]),
    })?;
    let model = JointModel::new(
        lft,
        vec![
            JointBlock::new("input", vec![0], 0, input),
            JointBlock::new("output", vec![1], 1, output),
        ],
    )?;
    free_canonical(
        model,
        0,
        n,
        g.den.len() - 1,
        LftMatrix::Bw,
        leading_delay(g),
    )
}

/// The start of a Hammerstein–Wiener fit from the best linear approximation `bla`: G = the
/// BLA, both maps the identity over the ranges of u and of the BLA's simulated output (plus
/// the settings' margin), so the start simulates exactly as the BLA does.
///
/// # Errors
/// Data with several inputs or outputs, a BLA that diverges on the data, and
/// [`hammerstein_wiener_model`]'s errors.
pub fn hammerstein_wiener_start(
    bla: &PolynomialModel,
    data: &Data,
    settings: &WienerHammersteinSettings,
) -> Result<JointModel> {
    if data.u().channels() != 1 || data.y().channels() != 1 {
        return Err(JointError::InvalidModel(format!(
            "a Hammerstein–Wiener model has one input and one output; the data have {} and {}",
            data.u().channels(),
            data.y().channels()
        )));
    }
    let u = data.u().channel(0);
    let mut z = Vec::with_capacity(u.len());
    for r in data.record_bounds().windows(2) {
        let rec = Signal::new(1, u[r[0]..r[1]].to_vec())?;
        z.extend(
            bla.simulate(&rec)
                .map_err(|e| JointError::InvalidModel(e.to_string()))?,
        );
    }
    let (u_lo, u_hi) = span(&u)?;
    let (z_lo, z_hi) = span(&z)?;
    hammerstein_wiener_model(
        bla,
        Box::new(identity(u_lo, u_hi, settings)?),
        Box::new(identity(z_lo, z_hi, settings)?),
    )
}
