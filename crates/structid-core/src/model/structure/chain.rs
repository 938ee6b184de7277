//! Several blocks in one structure: each block after the first is placed at a site of the model
//! built so far, whose blocks become internal.
//!
//! The model so far is an LFT M with inputs (u, e, w_old) and outputs (y, z_old). A further
//! block N at
//!
//! | site | wraps M as | new z | what the old blocks see |
//! |---|---|---|---|
//! | [`Site::Input`] | y = M(N(u)) | u | M's input u becomes w_new |
//! | [`Site::Output`] | y = N(y_M) + H·e, y_M noise-free | y_M = C_y·x + D_yu·u + D_yw·w_old | the plant's noise-free signals: e now enters at the sensor only |
//! | [`Site::OutputFeedback`] | y = M(u − N(y)) | y | M's input u becomes u − w_new |
//! | [`Site::RateFeedback`] | y = M(u − N(ẏ)) | (y_k − y_(k−1))/T_s | as for output feedback |
//!
//! A new z that reads old w (D_zw ≠ 0), or an old z that now reads u − w_new, makes maps in
//! series; [`crate::Model::new`] orders them and refuses a true cycle (such as a feedback around
//! an input map with direct feedthrough to y), naming the blocks. A sensor after other blocks
//! needs the noise at M's output (B_e = 0): the noise is moved behind the sensor.

use nalgebra::DMatrix;

use super::{Site, no_direct_feedthrough, single_input, with_time};
use crate::error::{Error, Result};
use crate::model::lft::{Lft, LftMatrices};

/// `top` stacked on `bottom`.
fn stack(top: &DMatrix<f64>, bottom: &DMatrix<f64>) -> DMatrix<f64> {
    let mut out = DMatrix::zeros(top.nrows() + bottom.nrows(), top.ncols());
    out.view_mut((0, 0), top.shape()).copy_from(top);
    out.view_mut((top.nrows(), 0), bottom.shape())
        .copy_from(bottom);
    out
}

/// `left` beside `right`.
fn beside(left: &DMatrix<f64>, right: &DMatrix<f64>) -> DMatrix<f64> {
    let mut out = DMatrix::zeros(left.nrows(), left.ncols() + right.ncols());
    out.view_mut((0, 0), left.shape()).copy_from(left);
    out.view_mut((0, left.ncols()), right.shape())
        .copy_from(right);
    out
}

/// The LFT of `so_far` with one more block at `site` (w column and z row appended).
pub(super) fn wrap(site: Site, so_far: &Lft) -> Result<Lft> {
    match site {
        Site::Input => wrap_input(so_far),
        Site::Output => wrap_output(so_far),
        Site::OutputFeedback => wrap_feedback(so_far),
        Site::RateFeedback => wrap_rate(so_far),
        Site::Declared { .. } => Err(Error::InvalidStructure(
            "a declared location belongs to the nominal LFT: it can be the first block of a \
             structure, not a later one"
                .into(),
        )),
    }
}

fn wrap_input(so_far: &Lft) -> Result<Lft> {
    single_input(so_far, "at the input")?;
    let m = so_far.matrices();
    let d = so_far.dims();
    with_time(
        so_far,
        LftMatrices {
            bu: DMatrix::zeros(d.states, 1),
            bw: beside(&m.bw, &m.bu),
            dyu: DMatrix::zeros(d.y, 1),
            dyw: beside(&m.dyw, &m.dyu),
            cz: stack(&m.cz, &DMatrix::zeros(1, d.states)),
            dzu: stack(&DMatrix::zeros(d.z, 1), &DMatrix::identity(1, 1)),
            dze: stack(&m.dze, &DMatrix::zeros(1, d.e)),
            dzw: stack(&beside(&m.dzw, &m.dzu), &DMatrix::zeros(1, d.w + 1)),
            ..m.clone()
        },
    )
}

fn wrap_output(so_far: &Lft) -> Result<Lft> {
    let m = so_far.matrices();
    let d = so_far.dims();
    if d.y != 1 {
        return Err(Error::InvalidStructure(format!(
            "a block at the output is built for a model with one output; this one has {}",
            d.y
        )));
    }
    if m.be.iter().any(|v| *v != 0.0) {
        return Err(Error::InvalidStructure(
            "a sensor map after other blocks needs the noise at the output (B_e = 0): the noise \
             is moved behind the sensor, which a noise model with dynamics of its own does not allow"
                .into(),
        ));
    }
    with_time(
        so_far,
        LftMatrices {
            bw: beside(&m.bw, &DMatrix::zeros(d.states, 1)),
            cy: DMatrix::zeros(1, d.states),
            dyu: DMatrix::zeros(1, d.u),
            dyw: beside(&DMatrix::zeros(1, d.w), &DMatrix::identity(1, 1)),
            cz: stack(&m.cz, &m.cy),
            dzu: stack(&m.dzu, &m.dyu),
            dze: DMatrix::zeros(d.z + 1, d.e),
            dzw: beside(&stack(&m.dzw, &m.dyw), &DMatrix::zeros(d.z + 1, 1)),
            ..m.clone()
        },
    )
}

fn wrap_feedback(so_far: &Lft) -> Result<Lft> {
    single_input(so_far, "in feedback from the output")?;
    no_direct_feedthrough(so_far, "in feedback from the output")?;
    let m = so_far.matrices();
    with_time(
        so_far,
        LftMatrices {
            bw: beside(&m.bw, &-&m.bu),
            dyw: beside(&m.dyw, &DMatrix::zeros(1, 1)),
            cz: stack(&m.cz, &m.cy),
            dzu: stack(&m.dzu, &m.dyu),
            dze: stack(&m.dze, &m.dye),
            dzw: stack(
                &beside(&m.dzw, &-&m.dzu),
                &beside(&m.dyw, &DMatrix::zeros(1, 1)),
            ),
            ..m.clone()
        },
    )
}

fn wrap_rate(so_far: &Lft) -> Result<Lft> {
    single_input(so_far, "in feedback from the output rate")?;
    no_direct_feedthrough(so_far, "in feedback from the output rate")?;
    let ts = so_far.sample_time().unwrap_or(1.0);
    let m = so_far.matrices();
    let d = so_far.dims();
    let n = d.states;
    // States [x; m] with m_k = y_(k−1).
    let a = stack(
        &beside(&m.a, &DMatrix::zeros(n, 1)),
        &beside(&m.cy, &DMatrix::zeros(1, 1)),
    );
    let cy = beside(&m.cy, &DMatrix::zeros(1, 1));
    let mut rate = &cy / ts;
    rate[(0, n)] = -1.0 / ts;
    with_time(
        so_far,
        LftMatrices {
            a,
            bu: stack(&m.bu, &m.dyu),
            be: stack(&m.be, &m.dye),
            bw: stack(
                &beside(&m.bw, &-&m.bu),
                &beside(&m.dyw, &DMatrix::zeros(1, 1)),
            ),
            cy,
            dyw: beside(&m.dyw, &DMatrix::zeros(1, 1)),
            cz: stack(&beside(&m.cz, &DMatrix::zeros(d.z, 1)), &rate),
            dzu: stack(&m.dzu, &DMatrix::zeros(1, 1)),
            dze: stack(&m.dze, &(&m.dye / ts)),
            dzw: stack(
                &beside(&m.dzw, &-&m.dzu),
                &beside(&(&m.dyw / ts), &DMatrix::zeros(1, 1)),
            ),
            ..m.clone()
        },
    )
}
