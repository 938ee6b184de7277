//! Which polynomial G a declared location of a nominal LFT puts its map around.
//!
//! A general LFT's coefficients are not "G": G is defined only for the built-in structures,
//! where one linear block carries u and the map's output to y. So a declared location is
//! refined when the LFT restricted to it equals, transfer for transfer, one of those
//! structures around the polynomial block read off the LFT. Two LTI systems of orders n₁
//! and n₂ are equal when their first n₁ + n₂ + 1 Markov parameters (D, C·B, C·A·B, …) are, so
//! the comparison is exact up to rounding.

use nalgebra::DMatrix;
use structid_linear::PolynomialModel;

use super::LinearStructure;
use crate::error::{Error, Result};
use crate::model::lft::Lft;
use crate::model::structure::Site;

/// The Markov parameters D, C·B, C·A·B, … (`count` of them) of (A, B, C, D).
fn markov(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    c: &DMatrix<f64>,
    d: &DMatrix<f64>,
    count: usize,
) -> Vec<DMatrix<f64>> {
    let mut out = vec![d.clone()];
    let mut ab = b.clone();
    for _ in 1..count {
        out.push(c * &ab);
        ab = a * ab;
    }
    out
}

/// All Markov parameters of (u, w, e) → (y, z) of an LFT with one w and one z channel.
fn lft_markov(l: &Lft, count: usize) -> Vec<DMatrix<f64>> {
    let m = l.matrices();
    let b = concat_columns(&[&m.bu, &m.bw, &m.be]);
    let c = concat_rows(&[&m.cy, &m.cz]);
    let d = concat_rows(&[
        &concat_columns(&[&m.dyu, &m.dyw, &m.dye]),
        &concat_columns(&[&m.dzu, &m.dzw, &m.dze]),
    ]);
    markov(&m.a, &b, &c, &d, count)
}

fn concat_columns(parts: &[&DMatrix<f64>]) -> DMatrix<f64> {
    let rows = parts[0].nrows();
    let cols = parts.iter().map(|p| p.ncols()).sum();
    let mut out = DMatrix::zeros(rows, cols);
    let mut at = 0;
    for p in parts {
        out.view_mut((0, at), (rows, p.ncols())).copy_from(p);
        at += p.ncols();
    }
    out
}

fn concat_rows(parts: &[&DMatrix<f64>]) -> DMatrix<f64> {
    let cols = parts[0].ncols();
    let rows = parts.iter().map(|p| p.nrows()).sum();
    let mut out = DMatrix::zeros(rows, cols);
    let mut at = 0;
    for p in parts {
        out.view_mut((at, 0), (p.nrows(), cols)).copy_from(p);
        at += p.nrows();
    }
    out
}

/// det(I − A·q⁻¹) = 1 + c₁q⁻¹ + … + c_n·q⁻ⁿ, by Faddeev–LeVerrier.
fn characteristic(a: &DMatrix<f64>) -> Vec<f64> {
    let n = a.nrows();
    let mut coef = vec![1.0];
    let mut m = DMatrix::<f64>::zeros(n, n);
    let eye = DMatrix::<f64>::identity(n, n);
    for k in 1..=n {
        m = a * &m + &eye * coef[k - 1];
        let am = a * &m;
        coef.push(-am.trace() / k as f64);
    }
    coef
}

/// The transfers of (A, B, C, D) (one output, each input a column of B) as numerators over
/// F = det(I − A·q⁻¹); coefficients at rounding level are set to zero (they carry the
/// delays), and trailing terms that vanish in F and every numerator (modes at the origin
/// that the transfers do not see) are dropped.
fn transfer(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    c: &DMatrix<f64>,
    d: &DMatrix<f64>,
    sample_time: Option<f64>,
) -> PolynomialModel {
    let n = a.nrows();
    let mut den = characteristic(a);
    let h = markov(a, b, c, d, n + 1);
    let mut num: Vec<Vec<f64>> = (0..b.ncols())
        .map(|i| {
            (0..=n)
                .map(|k| (0..=k).map(|j| den[j] * h[k - j][(0, i)]).sum())
                .collect()
        })
        .collect();
    let clean = |v: &mut Vec<f64>| {
        let top = v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        for x in v.iter_mut() {
            if x.abs() <= 1e-12 * top {
                *x = 0.0;
            }
        }
    };
    clean(&mut den);
    num.iter_mut().for_each(clean);
    while den.len() > 1 && den.last() == Some(&0.0) && num.iter().all(|b| b.last() == Some(&0.0)) {
        den.pop();
        num.iter_mut().for_each(|b| {
            b.pop();
        });
    }
    PolynomialModel {
        num,
        den,
        sample_time,
    }
}

/// The structures a declared location may be, with their G, in the order they are tried.
fn candidates(name: &str, l: &Lft) -> Vec<(LinearStructure, PolynomialModel)> {
    let m = l.matrices();
    let ts = l.sample_time();
    let g_yu = transfer(&m.a, &m.bu, &m.cy, &m.dyu, ts);
    let g_yw = transfer(&m.a, &m.bw, &m.cy, &m.dyw, ts);
    let g_zu = transfer(&m.a, &m.bu, &m.cz, &m.dzu, ts);
    let mut out = Vec::new();
    if g_yu.num.len() == 1 {
        out.push((LinearStructure::output_feedback(name), {
            let mut g = g_yu.clone();
            g.num.push(g_yu.num[0].iter().map(|x| -x).collect());
            g
        }));
    }
    out.push((
        LinearStructure::output_feedback(name).with_separate_numerator(true),
        {
            let mut g = g_yu.clone();
            g.num.push(g_yw.num[0].clone());
            g
        },
    ));
    if g_yu.num.len() == 1 {
        out.push((LinearStructure::rate_feedback(name), g_yu));
    }
    out.push((LinearStructure::input(name), g_yw));
    out.push((LinearStructure::output(name), g_zu));
    out
}

pub(super) fn from_lft(
    name: String,
    nominal: &Lft,
    z: usize,
    w: usize,
) -> Result<(LinearStructure, PolynomialModel)> {
    let l = Site::Declared { z, w }.insert(nominal)?;
    let dims = l.dims();
    if dims.y != 1 {
        return Err(Error::InvalidStructure(format!(
            "refinement re-estimates a linear part G with one output; this LFT has {} outputs",
            dims.y
        )));
    }
    let m = l.matrices();
    // White output noise: the noise reaches y without dynamics. Refinement estimates G by
    // output error, which has no noise model to re-estimate.
    let noise = markov(&m.a, &m.be, &m.cy, &m.dye, dims.states + 1);
    let noise_scale = noise
        .iter()
        .flat_map(|p| p.iter())
        .fold(0.0f64, |a, v| a.max(v.abs()));
    if noise
        .iter()
        .skip(1)
        .flat_map(|p| p.iter())
        .any(|v| v.abs() > 1e-9 * noise_scale.max(1e-300))
    {
        return Err(Error::InvalidStructure(format!(
            "the LFT at z row {z}, w column {w} has a noise path with dynamics (B_e ≠ 0); \
             refinement re-estimates G by output error under white output noise and would \
             drop that noise model; identify the map with this LFT fixed instead"
        )));
    }
    let reference = |count| lft_markov(&l, count);
    for (structure, g) in candidates(&name, &l) {
        let Ok(candidate) = structure.lft(&g) else {
            continue;
        };
        if candidate.dims().e != 1 || candidate.dims().u != dims.u {
            continue;
        }
        let count = dims.states + candidate.dims().states + 2;
        let want = reference(count);
        // The candidate has white unit output noise; the LFT's noise enters through D_ye.
        let got: Vec<DMatrix<f64>> = lft_markov(&candidate, count)
            .into_iter()
            .map(|p| {
                let nu = dims.u + 1;
                let mut full = DMatrix::zeros(p.nrows(), nu + dims.e);
                full.view_mut((0, 0), (p.nrows(), nu))
                    .copy_from(&p.columns(0, nu));
                full.view_mut((0, nu), (p.nrows(), dims.e))
                    .copy_from(&(p.columns(nu, 1) * &m.dye));
                full
            })
            .collect();
        let scale = want
            .iter()
            .flat_map(|p| p.iter())
            .fold(0.0f64, |a, v| a.max(v.abs()));
        let agrees = want
            .iter()
            .zip(&got)
            .all(|(a, b)| (a - b).iter().all(|v| v.abs() <= 1e-8 * scale.max(1e-300)));
        if agrees {
            return Ok((structure, g));
        }
    }
    Err(Error::InvalidStructure(format!(
        "the LFT at z row {z}, w column {w} is not one linear block G with the map at its \
         input, at its output, or in feedback from y or from its rate (its transfers from u \
         and w to y and z have none of those forms), so it does not say which of its \
         coefficients are G's to re-estimate; identify the map with this LFT fixed, or write \
         the model as [linear] with a structure"
    )))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::structure::realise;

    fn g() -> PolynomialModel {
        PolynomialModel {
            num: vec![vec![0.0, 0.3, 0.1]],
            den: vec![1.0, -1.4, 0.6],
            sample_time: Some(0.05),
        }
    }

    /// Property: every built-in site inserted into a realised G is recognised as that site,
    /// with G's coefficients back (its transfer is independent of the realisation).
    #[test]
    fn every_built_in_site_is_recognised_with_its_g() {
        let nominal = realise(&g()).unwrap();
        for site in Site::ALL {
            let lft = site.insert(&nominal).unwrap();
            let (s, found) = from_lft("N".into(), &lft, 0, 0).unwrap();
            assert_eq!(s.site(), site);
            assert!(!s.separate_numerator());
            for (a, b) in found.den.iter().zip(&g().den) {
                assert!((a - b).abs() < 1e-10, "{site:?}: {found:?}");
            }
            assert_eq!(found.den.len(), 3, "{site:?}: {found:?}");
            for (a, b) in found.num[0].iter().zip(&g().num[0]) {
                assert!((a - b).abs() < 1e-10, "{site:?}: {found:?}");
            }
            assert_eq!(found.sample_time, Some(0.05));
        }
    }

    /// A map that reads y but acts through a path of its own is output feedback with a
    /// separate numerator; a noise path with dynamics and an unrelated location are refused.
    #[test]
    fn separate_paths_noise_dynamics_and_other_forms() {
        let two = PolynomialModel {
            num: vec![vec![0.0, 0.3, 0.1], vec![0.0, -0.2, 0.05]],
            ..g()
        };
        let lft = crate::model::structure::polynomial_lft(&two, Some(Site::OutputFeedback), true)
            .unwrap();
        let (s, found) = from_lft("N".into(), &lft, 0, 0).unwrap();
        assert!(s.separate_numerator());
        assert!((found.num[1][1] + 0.2).abs() < 1e-10, "{found:?}");

        let mut mats = lft.matrices().clone();
        mats.be = DMatrix::from_element(2, 1, 0.5);
        let coloured = Lft::new(mats.clone()).unwrap();
        let e = from_lft("N".into(), &coloured, 0, 0)
            .unwrap_err()
            .to_string();
        assert!(e.contains("noise path with dynamics"), "{e}");

        // z reads the first state alone: not y, not its rate, not u, not G·u.
        mats.be = DMatrix::zeros(2, 1);
        mats.cz = DMatrix::from_row_slice(1, 2, &[0.0, 1.0]);
        mats.dze = DMatrix::zeros(1, 1);
        let other = Lft::new(mats).unwrap();
        let e = from_lft("N".into(), &other, 0, 0).unwrap_err().to_string();
        assert!(e.contains("does not say which"), "{e}");
    }
}
