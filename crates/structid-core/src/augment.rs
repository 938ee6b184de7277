//! Augmenting a nominal linear model with one unknown static block.
//!
//! A nominal model is an LFT without maps (its w and z channels, if any, are *declared*
//! injection points and signals, unused until a block is put there): with state x,
//!
//! ```text
//!   x⁺ = A·x + B_u·u + B_e·e,    y = C_y·x + D_yu·u + D_ye·e
//! ```
//!
//! so y = G·u + H·e with G the deterministic and H the noise path. Each function here returns
//! the LFT of the nominal model with one block N inserted at a place of the structure; the
//! noise path H is kept as it is.
//!
//! | function | model | z (measurable because) |
//! |---|---|---|
//! | [`at_input`] | y = G·N(u) + H·e | z = u |
//! | [`at_output`] | y = N(G·u) + H·e (a sensor map) | z = G·u depends on u only |
//! | [`output_feedback`] | y = G·(u − N(y)) + H·e | z = y is measured |
//! | [`rate_feedback`] | y = G·(u − N(ẏ)) + H·e, ẏ_k = (y_k − y_(k−1))/T_s | z = Ψ(q)·y with Ψ = (1 − q⁻¹)/T_s (dynamic) |
//! | [`declared`] | the nominal LFT's own w column j and z row i | checked by [`Lft::measurability`] |
//!
//! The sensor map needs G·u without the noise: when the noise path has dynamics of its own
//! (B_e ≠ 0), the state is doubled into a deterministic copy driven by u (read by z) and a
//! stochastic copy driven by e (read by y). The rate needs the previous output, carried as an
//! extra state m_k = y_(k−1).

use nalgebra::DMatrix;

use crate::error::{Error, Result};
use crate::lft::{Lft, LftMatrices};

fn single_input(nominal: &Lft, what: &str) -> Result<()> {
    let d = nominal.dims();
    if d.u != 1 || d.y != 1 {
        return Err(Error::InvalidStructure(format!(
            "a block {what} is built for a nominal model with one input and one output; this one \
             has {} input(s) and {} output(s)",
            d.u, d.y
        )));
    }
    Ok(())
}

fn no_direct_feedthrough(nominal: &Lft, what: &str) -> Result<()> {
    let m = nominal.matrices();
    if m.dyu.iter().any(|v| *v != 0.0) {
        return Err(Error::InvalidStructure(format!(
            "a block {what} needs G to have an input delay (D_yu = 0); otherwise y_k depends on \
             the map of y_k itself, an algebraic loop"
        )));
    }
    Ok(())
}

fn with_time(nominal: &Lft, m: LftMatrices) -> Result<Lft> {
    let lft = Lft::new(m)?;
    match nominal.sample_time() {
        Some(ts) => lft.with_sample_time(ts),
        None => Ok(lft),
    }
}

/// y = G·N(u) + H·e: an actuator map ahead of the nominal model (one input).
///
/// ```
/// use nalgebra::{DMatrix, dmatrix};
/// use structid_core::{Lft, LftMatrices, augment};
/// // y = 0.5/(q − 0.8)·u + e
/// let nominal = Lft::new(LftMatrices {
///     a: dmatrix![0.8], bu: dmatrix![0.5], be: dmatrix![0.0], bw: DMatrix::zeros(1, 0),
///     cy: dmatrix![1.0], dyu: dmatrix![0.0], dye: dmatrix![1.0], dyw: DMatrix::zeros(1, 0),
///     cz: DMatrix::zeros(0, 1), dzu: DMatrix::zeros(0, 1), dze: DMatrix::zeros(0, 1),
///     dzw: DMatrix::zeros(0, 0),
/// }).unwrap();
/// let lft = augment::at_input(&nominal).unwrap();
/// assert_eq!((lft.dims().w, lft.dims().z), (1, 1));
/// ```
pub fn at_input(nominal: &Lft) -> Result<Lft> {
    single_input(nominal, "at the input")?;
    let m = nominal.matrices();
    let n = nominal.dims().states;
    with_time(
        nominal,
        LftMatrices {
            a: m.a.clone(),
            bu: DMatrix::zeros(n, 1),
            be: m.be.clone(),
            bw: m.bu.clone(),
            cy: m.cy.clone(),
            dyu: DMatrix::zeros(1, 1),
            dye: m.dye.clone(),
            dyw: m.dyu.clone(),
            cz: DMatrix::zeros(1, n),
            dzu: DMatrix::identity(1, 1),
            dze: DMatrix::zeros(1, m.dye.ncols()),
            dzw: DMatrix::zeros(1, 1),
        },
    )
}

/// y = N(G·u) + H·e: a sensor map of the noise-free linear output (one output, any number of
/// inputs).
pub fn at_output(nominal: &Lft) -> Result<Lft> {
    if nominal.dims().y != 1 {
        return Err(Error::InvalidStructure(format!(
            "a block at the output is built for a nominal model with one output; this one has {}",
            nominal.dims().y
        )));
    }
    let m = nominal.matrices();
    let n = nominal.dims().states;
    let nu = nominal.dims().u;
    let ne = m.dye.ncols();
    let noise_dynamics = m.be.iter().any(|v| *v != 0.0);
    let matrices = if noise_dynamics {
        let mut a = DMatrix::zeros(2 * n, 2 * n);
        a.view_mut((0, 0), (n, n)).copy_from(&m.a);
        a.view_mut((n, n), (n, n)).copy_from(&m.a);
        let mut bu = DMatrix::zeros(2 * n, nu);
        bu.view_mut((0, 0), (n, nu)).copy_from(&m.bu);
        let mut be = DMatrix::zeros(2 * n, ne);
        be.view_mut((n, 0), (n, ne)).copy_from(&m.be);
        let mut cy = DMatrix::zeros(1, 2 * n);
        cy.view_mut((0, n), (1, n)).copy_from(&m.cy);
        let mut cz = DMatrix::zeros(1, 2 * n);
        cz.view_mut((0, 0), (1, n)).copy_from(&m.cy);
        LftMatrices {
            a,
            bu,
            be,
            bw: DMatrix::zeros(2 * n, 1),
            cy,
            dyu: DMatrix::zeros(1, nu),
            dye: m.dye.clone(),
            dyw: DMatrix::identity(1, 1),
            cz,
            dzu: m.dyu.clone(),
            dze: DMatrix::zeros(1, ne),
            dzw: DMatrix::zeros(1, 1),
        }
    } else {
        LftMatrices {
            a: m.a.clone(),
            bu: m.bu.clone(),
            be: m.be.clone(),
            bw: DMatrix::zeros(n, 1),
            cy: DMatrix::zeros(1, n),
            dyu: DMatrix::zeros(1, nu),
            dye: m.dye.clone(),
            dyw: DMatrix::identity(1, 1),
            cz: m.cy.clone(),
            dzu: m.dyu.clone(),
            dze: DMatrix::zeros(1, ne),
            dzw: DMatrix::zeros(1, 1),
        }
    };
    with_time(nominal, matrices)
}

/// y = G·(u − N(y)) + H·e: stiffness-like feedback from the measured output (G needs a delay).
pub fn output_feedback(nominal: &Lft) -> Result<Lft> {
    single_input(nominal, "in feedback from the output")?;
    no_direct_feedthrough(nominal, "in feedback from the output")?;
    let m = nominal.matrices();
    with_time(
        nominal,
        LftMatrices {
            a: m.a.clone(),
            bu: m.bu.clone(),
            be: m.be.clone(),
            bw: -&m.bu,
            cy: m.cy.clone(),
            dyu: DMatrix::zeros(1, 1),
            dye: m.dye.clone(),
            dyw: DMatrix::zeros(1, 1),
            cz: m.cy.clone(),
            dzu: DMatrix::zeros(1, 1),
            dze: m.dye.clone(),
            dzw: DMatrix::zeros(1, 1),
        },
    )
}

/// y = G·(u − N(ẏ)) + H·e with ẏ_k = (y_k − y_(k−1))/T_s (T_s the nominal model's sample time,
/// 1 when it has none, y_(−1) = 0): friction-like feedback from the output's rate. G needs a
/// delay.
pub fn rate_feedback(nominal: &Lft) -> Result<Lft> {
    single_input(nominal, "in feedback from the output rate")?;
    no_direct_feedthrough(nominal, "in feedback from the output rate")?;
    let ts = nominal.sample_time().unwrap_or(1.0);
    let m = nominal.matrices();
    let n = nominal.dims().states;
    let ne = m.dye.ncols();
    // States [x; m] with m_k = y_(k−1).
    let mut a = DMatrix::zeros(n + 1, n + 1);
    a.view_mut((0, 0), (n, n)).copy_from(&m.a);
    a.view_mut((n, 0), (1, n)).copy_from(&m.cy);
    let mut bu = DMatrix::zeros(n + 1, 1);
    bu.view_mut((0, 0), (n, 1)).copy_from(&m.bu);
    let mut be = DMatrix::zeros(n + 1, ne);
    be.view_mut((0, 0), (n, ne)).copy_from(&m.be);
    be.view_mut((n, 0), (1, ne)).copy_from(&m.dye);
    let bw = -&bu;
    let mut cy = DMatrix::zeros(1, n + 1);
    cy.view_mut((0, 0), (1, n)).copy_from(&m.cy);
    let mut cz = &cy / ts;
    cz[(0, n)] = -1.0 / ts;
    with_time(
        nominal,
        LftMatrices {
            a,
            bu,
            be,
            bw,
            cy,
            dyu: DMatrix::zeros(1, 1),
            dye: m.dye.clone(),
            dyw: DMatrix::zeros(1, 1),
            cz,
            dzu: DMatrix::zeros(1, 1),
            dze: &m.dye / ts,
            dzw: DMatrix::zeros(1, 1),
        },
    )
}

/// The nominal LFT with only its declared w column `w` and z row `z`: a block at a location
/// the model file names.
pub fn declared(nominal: &Lft, z: usize, w: usize) -> Result<Lft> {
    let d = nominal.dims();
    if z >= d.z || w >= d.w {
        return Err(Error::InvalidStructure(format!(
            "declared location (z row {z}, w column {w}) is outside the nominal model's {} z \
             row(s) and {} w column(s)",
            d.z, d.w
        )));
    }
    let m = nominal.matrices();
    with_time(
        nominal,
        LftMatrices {
            a: m.a.clone(),
            bu: m.bu.clone(),
            be: m.be.clone(),
            bw: m.bw.columns(w, 1).into_owned(),
            cy: m.cy.clone(),
            dyu: m.dyu.clone(),
            dye: m.dye.clone(),
            dyw: m.dyw.columns(w, 1).into_owned(),
            cz: m.cz.rows(z, 1).into_owned(),
            dzu: m.dzu.rows(z, 1).into_owned(),
            dze: m.dze.rows(z, 1).into_owned(),
            dzw: DMatrix::from_element(1, 1, m.dzw[(z, w)]),
        },
    )
}

/// The nominal LFT without its declared w and z channels (the model without any block).
pub fn without_blocks(nominal: &Lft) -> Result<Lft> {
    let m = nominal.matrices();
    let d = nominal.dims();
    with_time(
        nominal,
        LftMatrices {
            a: m.a.clone(),
            bu: m.bu.clone(),
            be: m.be.clone(),
            bw: DMatrix::zeros(d.states, 0),
            cy: m.cy.clone(),
            dyu: m.dyu.clone(),
            dye: m.dye.clone(),
            dyw: DMatrix::zeros(d.y, 0),
            cz: DMatrix::zeros(0, d.states),
            dzu: DMatrix::zeros(0, d.u),
            dze: DMatrix::zeros(0, d.e),
            dzw: DMatrix::zeros(0, 0),
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::MapBinding;
    use nalgebra::dmatrix;
    use structid_lti::Signal;

    /// A nominal model with a coloured noise path: y = 0.4q⁻¹/(1 − 0.7q⁻¹)·u + (1 + 0.5q⁻¹)/(1 − 0.7q⁻¹)·e
    /// in one state (innovations form: B_e = 0.5 + 0.7 = 1.2).
    fn nominal() -> Lft {
        Lft::new(LftMatrices {
            a: dmatrix![0.7],
            bu: dmatrix![0.4],
            be: dmatrix![1.2],
            bw: DMatrix::zeros(1, 0),
            cy: dmatrix![1.0],
            dyu: dmatrix![0.0],
            dye: dmatrix![1.0],
            dyw: DMatrix::zeros(1, 0),
            cz: DMatrix::zeros(0, 1),
            dzu: DMatrix::zeros(0, 1),
            dze: DMatrix::zeros(0, 1),
            dzw: DMatrix::zeros(0, 0),
        })
        .unwrap()
        .with_sample_time(0.1)
        .unwrap()
    }

    /// Reference simulation of each structure by direct recursion of the transfer functions.
    fn reference(kind: &str, f: fn(f64) -> f64, u: &[f64], e: &[f64]) -> Vec<f64> {
        let n = u.len();
        let (mut xg, mut xh) = (0.0, 0.0); // G's and H's states (separate realisations)
        let mut y = vec![0.0; n];
        let mut prev_y = 0.0;
        for k in 0..n {
            let yh = xh + e[k];
            let yk = match kind {
                "input" => xg + yh,
                "output" => f(xg) + yh,
                _ => xg + yh,
            };
            y[k] = yk;
            let drive = match kind {
                "input" => f(u[k]),
                "output" => u[k],
                "output-feedback" => u[k] - f(yk),
                _ => u[k] - f((yk - prev_y) / 0.1),
            };
            prev_y = yk;
            xg = 0.7 * xg + 0.4 * drive;
            xh = 0.7 * xh + 1.2 * e[k];
        }
        y
    }

    #[test]
    fn every_location_simulates_its_equation_with_the_noise_path_kept() {
        let u: Vec<f64> = (0..200).map(|k| (0.13 * k as f64).sin() * 1.5).collect();
        let e: Vec<f64> = (0..200)
            .map(|k| 0.05 * ((k * 37 % 11) as f64 - 5.0))
            .collect();
        let f: fn(f64) -> f64 = |z| z.tanh() + 0.1 * z;
        let us = Signal::from_fn(u.len(), 1, |k, _| u[k]);
        let es = Signal::from_fn(e.len(), 1, |k, _| e[k]);
        let map = |z: &[f64]| f(z[0]);
        for (kind, lft) in [
            ("input", at_input(&nominal()).unwrap()),
            ("output", at_output(&nominal()).unwrap()),
            ("output-feedback", output_feedback(&nominal()).unwrap()),
            ("rate-feedback", rate_feedback(&nominal()).unwrap()),
        ] {
            let sim = lft
                .simulate(
                    &[MapBinding {
                        inputs: &[0],
                        output: 0,
                        map: &map,
                    }],
                    &us,
                    Some(&es),
                    None,
                )
                .unwrap();
            let want = reference(kind, f, &u, &e);
            let worst = (0..u.len())
                .map(|k| (sim.y.get(k, 0) - want[k]).abs())
                .fold(0.0, f64::max);
            assert!(worst < 1e-12, "{kind}: differs by {worst}");
            // z is computable from u and y alone.
            let (z, _) = lft.compute_z(&us, &sim.y).unwrap();
            let dz = (0..u.len())
                .map(|k| (z.get(k, 0) - sim.z.get(k, 0)).abs())
                .fold(0.0, f64::max);
            assert!(dz < 1e-9, "{kind}: measured z differs by {dz}");
        }
    }

    #[test]
    fn feedback_needs_a_delay_and_declared_channels_must_exist() {
        let mut m = nominal().matrices().clone();
        m.dyu = dmatrix![0.3];
        let direct = Lft::new(m).unwrap();
        assert!(
            output_feedback(&direct)
                .unwrap_err()
                .to_string()
                .contains("delay")
        );
        assert!(rate_feedback(&direct).is_err());
        assert!(at_input(&direct).is_ok());
        assert!(declared(&nominal(), 0, 0).is_err());
    }
}
