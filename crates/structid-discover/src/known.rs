//! The LFTs of a nominal model that already carries maps: a new unknown block wrapped around
//! the whole nominal model, its maps kept inside.
//!
//! A nominal model with known maps is an LFT P whose w columns and z rows are those of the
//! known blocks (w_k = N_k(z_k), fixed functions):
//!
//! ```text
//!   x⁺ = A·x + B_u·u + B_e·e + B_w·w_k,   y = C_y·x + D_yu·u + D_ye·e + D_yw·w_k,
//!   z_k = C_z·x + D_zu·u + D_ze·e + D_zw·w_k
//! ```
//!
//! The new block N sits *around* P, at w column 0 and z row 0, with the known channels after it:
//!
//! | location | model | what changes in P |
//! |---|---|---|
//! | input | P driven by v = N(u) | every column of u becomes N's w column; z₀ = u |
//! | output | y = N(ŷ) + D_ye·e, ŷ = C_y·x + D_yu·u + D_yw·w_k | y reads w₀; z₀ = ŷ (P's noise path must be static) |
//! | output feedback | y = G·(u − N(y)) with P's maps | N's w column is −(the input path of G), z₀ = y (needs a delay) |
//! | rate feedback | y = G·(u − N(ẏ)) with P's maps | as output feedback, plus the state m = y_(k−1), z₀ = (y − m)/T_s |
//! | declared | P's own declared w column and z row | the declared channels are kept with the known ones |
//!
//! The input path of G, where feedback enters, is B_u when u reaches the dynamics directly;
//! when u enters only through a known actuator map (a block reading u alone, e.g. the input
//! saturation of an earlier discovery), it is that map's w column: a spring or a friction
//! force acts after the actuator, y = G·(sat(u) − N(y)).
//!
//! Without known channels these are the LFTs of [`structid_core::Site::insert`] (which the
//! callers then use, so that a nominal model without maps is handled exactly as before).
//!
//! For identification the known maps are *inputs*: every z_k is measurable (z is computed from
//! u and y, or measured), so w_k = N_k(z_k) is a known signal on a record, and the LFT of N
//! alone sees it as extra input columns ([`crate::hypotheses::Hypothesis::block_lft`]). That is exact for a
//! one-step-ahead (equation-error) criterion, which is what identification minimises; the
//! simulations that rank and name hypotheses use the full LFT with every map in the loop.

use nalgebra::DMatrix;
use structid_core::{Error, Lft, LftMatrices, Result, Site};

/// `rows` stacked on top of each other (all with the same number of columns `cols`).
fn vstack(parts: &[&DMatrix<f64>], cols: usize) -> DMatrix<f64> {
    let rows: usize = parts.iter().map(|p| p.nrows()).sum();
    let mut out = DMatrix::zeros(rows, cols);
    let mut r = 0;
    for p in parts {
        out.view_mut((r, 0), (p.nrows(), cols)).copy_from(*p);
        r += p.nrows();
    }
    out
}

/// `parts` side by side (all with `rows` rows).
fn hstack(parts: &[&DMatrix<f64>], rows: usize) -> DMatrix<f64> {
    let cols: usize = parts.iter().map(|p| p.ncols()).sum();
    let mut out = DMatrix::zeros(rows, cols);
    let mut c = 0;
    for p in parts {
        out.view_mut((0, c), (rows, p.ncols())).copy_from(*p);
        c += p.ncols();
    }
    out
}

fn with_time(like: &Lft, m: LftMatrices) -> Result<Lft> {
    let lft = Lft::new(m)?;
    match like.sample_time() {
        Some(ts) => lft.with_sample_time(ts),
        None => Ok(lft),
    }
}

/// The LFT `lft` with only the z rows `z` and w columns `w`, in that order.
pub(crate) fn select_channels(lft: &Lft, z: &[usize], w: &[usize]) -> Result<Lft> {
    let d = lft.dims();
    if let Some(bad) = z.iter().find(|&&r| r >= d.z) {
        return Err(Error::InvalidStructure(format!(
            "z row {bad} does not exist (the LFT has {} z row(s))",
            d.z
        )));
    }
    if let Some(bad) = w.iter().find(|&&c| c >= d.w) {
        return Err(Error::InvalidStructure(format!(
            "w column {bad} does not exist (the LFT has {} w column(s))",
            d.w
        )));
    }
    let m = lft.matrices();
    let cols = |a: &DMatrix<f64>| a.select_columns(w.iter());
    let rows = |a: &DMatrix<f64>| a.select_rows(z.iter());
    with_time(
        lft,
        LftMatrices {
            a: m.a.clone(),
            bu: m.bu.clone(),
            be: m.be.clone(),
            bw: cols(&m.bw),
            cy: m.cy.clone(),
            dyu: m.dyu.clone(),
            dye: m.dye.clone(),
            dyw: cols(&m.dyw),
            cz: rows(&m.cz),
            dzu: rows(&m.dzu),
            dze: rows(&m.dze),
            dzw: rows(&m.dzw).select_columns(w.iter()),
        },
    )
}

/// The LFT with a new block at `site` around `p`, the nominal LFT whose w columns and z rows
/// are exactly those of its known blocks (see the [module documentation](self)): the new
/// block at w column 0 and z row 0, the known ones after it in their order. A declared site
/// is not handled here (its channels are selected from the nominal LFT instead). The new
/// block may read a known block's output (D_zw ≠ 0): maps in series.
pub(crate) fn wrap(p: &Lft, site: Site) -> Result<Lft> {
    let d = p.dims();
    if d.u != 1 || d.y != 1 {
        return Err(Error::InvalidStructure(format!(
            "a block around a model with maps is built for one input and one output; this one \
             has {} input(s) and {} output(s)",
            d.u, d.y
        )));
    }
    let m = p.matrices();
    let (n, nk, ne) = (d.states, d.w, d.e);
    let zeros = DMatrix::<f64>::zeros;
    let one = DMatrix::<f64>::identity(1, 1);
    // Feedback enters where u enters G: through B_u when u reaches the dynamics directly,
    // else after a known actuator map (a block that reads u alone), as a spring or a friction
    // force acts after the actuator that saturates.
    let (entry_b, entry_dy, entry_dz) = match actuator(p) {
        Some(a) if m.bu.iter().chain(m.dyu.iter()).all(|v| *v == 0.0) => (
            m.bw.columns(a, 1).into_owned(),
            m.dyw.columns(a, 1).into_owned(),
            m.dzw.columns(a, 1).into_owned(),
        ),
        _ => (m.bu.clone(), m.dyu.clone(), m.dzu.clone()),
    };
    let direct = entry_dy.iter().any(|v| *v != 0.0);
    let feedback_needs_delay = |what: &str| {
        Error::InvalidStructure(format!(
            "a block {what} needs G to have an input delay (D_yu = 0); otherwise y_k depends on \
             the map of y_k itself, an algebraic loop"
        ))
    };
    let matrices = match site {
        Site::Input => LftMatrices {
            a: m.a.clone(),
            bu: zeros(n, 1),
            be: m.be.clone(),
            bw: hstack(&[&m.bu, &m.bw], n),
            cy: m.cy.clone(),
            dyu: zeros(1, 1),
            dye: m.dye.clone(),
            dyw: hstack(&[&m.dyu, &m.dyw], 1),
            cz: vstack(&[&zeros(1, n), &m.cz], n),
            dzu: vstack(&[&one, &zeros(nk, 1)], 1),
            dze: vstack(&[&zeros(1, ne), &m.dze], ne),
            dzw: vstack(&[&zeros(1, 1 + nk), &hstack(&[&m.dzu, &m.dzw], nk)], 1 + nk),
        },
        Site::Output => {
            if m.be.iter().any(|v| *v != 0.0) {
                return Err(Error::InvalidStructure(
                    "a sensor map around a model with maps needs a static noise path (B_e = 0): \
                     with noise inside the loop, the noise-free output it reads is not a \
                     signal of the model"
                        .into(),
                ));
            }
            LftMatrices {
                a: m.a.clone(),
                bu: m.bu.clone(),
                be: m.be.clone(),
                bw: hstack(&[&zeros(n, 1), &m.bw], n),
                cy: zeros(1, n),
                dyu: zeros(1, 1),
                dye: m.dye.clone(),
                dyw: hstack(&[&one, &zeros(1, nk)], 1),
                cz: vstack(&[&m.cy, &m.cz], n),
                dzu: vstack(&[&m.dyu, &m.dzu], 1),
                dze: vstack(&[&zeros(1, ne), &m.dze], ne),
                dzw: vstack(
                    &[
                        &hstack(&[&zeros(1, 1), &m.dyw], 1),
                        &hstack(&[&zeros(nk, 1), &m.dzw], nk),
                    ],
                    1 + nk,
                ),
            }
        }
        Site::OutputFeedback => {
            if direct {
                return Err(feedback_needs_delay("in feedback from the output"));
            }
            LftMatrices {
                a: m.a.clone(),
                bu: m.bu.clone(),
                be: m.be.clone(),
                bw: hstack(&[&(-&entry_b), &m.bw], n),
                cy: m.cy.clone(),
                dyu: m.dyu.clone(),
                dye: m.dye.clone(),
                dyw: hstack(&[&(-&entry_dy), &m.dyw], 1),
                cz: vstack(&[&m.cy, &m.cz], n),
                dzu: vstack(&[&m.dyu, &m.dzu], 1),
                dze: vstack(&[&m.dye, &m.dze], ne),
                dzw: vstack(
                    &[
                        &hstack(&[&(-&entry_dy), &m.dyw], 1),
                        &hstack(&[&(-&entry_dz), &m.dzw], nk),
                    ],
                    1 + nk,
                ),
            }
        }
        Site::RateFeedback => {
            if direct {
                return Err(feedback_needs_delay("in feedback from the output rate"));
            }
            let ts = p.sample_time().unwrap_or(1.0);
            // States [x; m] with m_k = y_(k−1).
            let mut a = zeros(n + 1, n + 1);
            a.view_mut((0, 0), (n, n)).copy_from(&m.a);
            a.view_mut((n, 0), (1, n)).copy_from(&m.cy);
            let bu = vstack(&[&m.bu, &m.dyu], 1);
            let be = vstack(&[&m.be, &m.dye], ne);
            let bw = vstack(
                &[
                    &hstack(&[&(-&entry_b), &m.bw], n),
                    &hstack(&[&(-&entry_dy), &m.dyw], 1),
                ],
                1 + nk,
            );
            let cy = hstack(&[&m.cy, &zeros(1, 1)], 1);
            let mut rate = &cy / ts;
            rate[(0, n)] = -1.0 / ts;
            let cz = vstack(&[&rate, &hstack(&[&m.cz, &zeros(nk, 1)], nk)], n + 1);
            LftMatrices {
                a,
                bu,
                be,
                bw,
                cy,
                dyu: m.dyu.clone(),
                dye: m.dye.clone(),
                dyw: hstack(&[&(-&entry_dy), &m.dyw], 1),
                cz,
                dzu: vstack(&[&(&m.dyu / ts), &m.dzu], 1),
                dze: vstack(&[&(&m.dye / ts), &m.dze], ne),
                dzw: vstack(
                    &[
                        &hstack(&[&(-&entry_dy / ts), &(&m.dyw / ts)], 1),
                        &hstack(&[&(-&entry_dz), &m.dzw], nk),
                    ],
                    1 + nk,
                ),
            }
        }
        Site::Declared { .. } => {
            return Err(Error::InvalidStructure(
                "a declared location is selected from the nominal LFT, not wrapped around it"
                    .into(),
            ));
        }
    };
    // A new block in series with a known one (D_zw ≠ 0) is simulated in order and fitted by
    // simulation error; only a cycle of maps is refused, by the model built on this LFT.
    with_time(p, matrices)
}

/// The known block that is an actuator map, if exactly one is: its z row reads u alone
/// (C_z, D_ze and D_zw zero on the row, D_zu not).
fn actuator(p: &Lft) -> Option<usize> {
    let m = p.matrices();
    let zero_row = |a: &DMatrix<f64>, r: usize| a.row(r).iter().all(|v| *v == 0.0);
    let reads_u_alone = |r: usize| {
        zero_row(&m.cz, r) && zero_row(&m.dze, r) && zero_row(&m.dzw, r) && !zero_row(&m.dzu, r)
    };
    // Known block i reads z row i and writes w column i (see `wrap`).
    let found: Vec<usize> = (0..p.dims().w.min(p.dims().z))
        .filter(|&i| reads_u_alone(i))
        .collect();
    match found[..] {
        [a] => Some(a),
        _ => None,
    }
}

/// The LFT of block 0 alone, with the w columns `1..` (the known blocks' outputs) turned into
/// inputs after u: u' = [u; w_1; …], and only z row 0 kept. On a record, those inputs are the
/// known maps evaluated at their (measurable) z.
pub(crate) fn with_known_inputs(lft: &Lft) -> Result<Lft> {
    let d = lft.dims();
    let m = lft.matrices();
    let known: Vec<usize> = (1..d.w).collect();
    let first = [0usize];
    with_time(
        lft,
        LftMatrices {
            a: m.a.clone(),
            bu: hstack(&[&m.bu, &m.bw.select_columns(known.iter())], d.states),
            be: m.be.clone(),
            bw: m.bw.select_columns(first.iter()),
            cy: m.cy.clone(),
            dyu: hstack(&[&m.dyu, &m.dyw.select_columns(known.iter())], d.y),
            dye: m.dye.clone(),
            dyw: m.dyw.select_columns(first.iter()),
            cz: m.cz.select_rows(first.iter()),
            dzu: hstack(
                &[
                    &m.dzu.select_rows(first.iter()),
                    &m.dzw.select_rows(first.iter()).select_columns(known.iter()),
                ],
                1,
            ),
            dze: m.dze.select_rows(first.iter()),
            dzw: m.dzw.select_rows(first.iter()).select_columns(first.iter()),
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use structid_core::model::structure::realise;
    use structid_linear::PolynomialModel;

    fn g() -> Lft {
        realise(&PolynomialModel {
            den: vec![1.0, -1.5, 0.7],
            num: vec![vec![0.0, 0.1, 0.1]],
            sample_time: Some(0.05),
        })
        .unwrap()
    }

    /// x_k = 1.5·x_(k−1) − 0.7·x_(k−2) + 0.1·(f_(k−1) + f_(k−2)) from rest, with the force
    /// f_k = force(k, u_k, y_k, y_(k−1)) and y_k = sensor(x_k): the plant written out, to
    /// compare the wrapped LFTs with.
    fn plant(
        u: &[f64],
        force: impl Fn(f64, f64, f64) -> f64,
        sensor: impl Fn(f64) -> f64,
    ) -> Vec<f64> {
        let n = u.len();
        let (mut x, mut f, mut y) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
        for k in 0..n {
            let at = |v: &[f64], lag: usize| if k >= lag { v[k - lag] } else { 0.0 };
            x[k] = 1.5 * at(&x, 1) - 0.7 * at(&x, 2) + 0.1 * (at(&f, 1) + at(&f, 2));
            y[k] = sensor(x[k]);
            f[k] = force(u[k], y[k], at(&y, 1));
        }
        y
    }

    /// Each site around a nominal model with a known map simulates as the plant it stands
    /// for: feedback after the known actuator, an actuator ahead of the known feedback, a
    /// sensor after both.
    #[test]
    fn wrapped_sites_simulate_as_the_plant() {
        use crate::hypotheses::{Nominal, Site, hypothesis};
        use std::sync::Arc;
        use structid_core::{Interpolant, PolynomialDispersion, Signal};
        let g = PolynomialModel {
            den: vec![1.0, -1.5, 0.7],
            num: vec![vec![0.0, 0.1, 0.1]],
            sample_time: Some(0.05),
        };
        let d = || Arc::new(PolynomialDispersion::new(1).unwrap());
        let sat = |v: f64| (1.5 * v).clamp(-0.8, 0.8);
        let cubic = |v: f64| 0.2 * v.powi(3);
        let friction = |v: f64| 0.01 * v + 0.02 * v.signum();
        let u: Vec<f64> = (0..400)
            .map(|k| 1.2 * (0.07 * k as f64).sin() + 0.5 * (0.31 * k as f64).cos())
            .collect();
        let us = Signal::from_fn(u.len(), 1, |k, _| u[k]);
        let known = |location: Site, map: fn(f64) -> f64| {
            let first = hypothesis(&g, location, d()).unwrap();
            let m: Arc<dyn Interpolant> = Arc::new(move |z: &[f64]| map(z[0]));
            Nominal::from_model(&first.model, vec![m]).unwrap()
        };
        let ts = 0.05;
        type Case = (Nominal, Site, fn(f64) -> f64, Vec<f64>);
        let cases: Vec<Case> = vec![
            (
                known(Site::Input, sat),
                Site::OutputFeedback,
                cubic,
                plant(&u, |u, y, _| sat(u) - cubic(y), |x| x),
            ),
            (
                known(Site::Input, sat),
                Site::RateFeedback,
                friction,
                plant(&u, |u, y, y1| sat(u) - friction((y - y1) / ts), |x| x),
            ),
            (
                known(Site::OutputFeedback, cubic),
                Site::Input,
                sat,
                plant(&u, |u, y, _| sat(u) - cubic(y), |x| x),
            ),
            (
                known(Site::Input, sat),
                Site::Output,
                cubic,
                plant(&u, |u, _, _| sat(u), cubic),
            ),
            // Maps in series: each new block reads the known sensor map's output or sits
            // before it, and simulates in order.
            (
                known(Site::Output, cubic),
                Site::Input,
                sat,
                plant(&u, |u, _, _| sat(u), cubic),
            ),
            (
                known(Site::Output, sat),
                Site::OutputFeedback,
                cubic,
                plant(&u, |u, y, _| u - cubic(y), sat),
            ),
            (
                known(Site::Output, sat),
                Site::RateFeedback,
                friction,
                plant(&u, |u, y, y1| u - friction((y - y1) / ts), sat),
            ),
            (
                known(Site::Output, sat),
                Site::Output,
                cubic,
                plant(&u, |u, _, _| u, |x| cubic(sat(x))),
            ),
        ];
        for (nominal, location, map, expected) in cases {
            let h = nominal.hypothesis(location, d()).unwrap();
            let f = move |z: &[f64]| map(z[0]);
            let y = h.simulate(&f, &us, None).unwrap().y.channel(0);
            let worst = y
                .iter()
                .zip(&expected)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            let scale = expected.iter().map(|v| v.abs()).fold(0.0, f64::max);
            assert!(
                scale > 0.1 && worst < 1e-12 * scale.max(1.0),
                "{location:?}: {worst}"
            );
        }
    }

    /// Around a nominal model with no known channels, every built-in site gives the LFT of
    /// [`Site::insert`] (the one construction the single-effect workflow uses).
    #[test]
    fn without_known_channels_wrap_is_site_insert() {
        let p = g();
        for site in Site::ALL {
            let a = wrap(&p, site).unwrap();
            let b = site.insert(&p).unwrap();
            let (ma, mb) = (a.matrices(), b.matrices());
            for (x, y) in [
                (&ma.a, &mb.a),
                (&ma.bu, &mb.bu),
                (&ma.be, &mb.be),
                (&ma.bw, &mb.bw),
                (&ma.cy, &mb.cy),
                (&ma.dyu, &mb.dyu),
                (&ma.dye, &mb.dye),
                (&ma.dyw, &mb.dyw),
                (&ma.cz, &mb.cz),
                (&ma.dzu, &mb.dzu),
                (&ma.dze, &mb.dze),
                (&ma.dzw, &mb.dzw),
            ] {
                assert_eq!(x, y, "{site:?}");
            }
        }
    }
}
