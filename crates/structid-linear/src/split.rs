//! Dividing one transfer function between two blocks in series.
//!
//! A Wiener–Hammerstein system `y = G₂·N(G₁·u)` has, for Gaussian inputs, a best linear
//! approximation proportional to `G₂·G₁` (Bussgang): its poles and zeros are those of the two
//! blocks together, and which belongs to which is what the data must decide. A
//! [`BlockSplit`] is one allocation:
//!
//! ```text
//!   B(q)/F(q) = b_nk·q^{−nk}·Π_i(1 − ζ_i q⁻¹) / Π_j(1 − π_j q⁻¹)
//!             = G₂(q)·G₁(q),
//!   G₁ = c·q^{−nk}·Π_{i∈Z₁}(1 − ζ_i q⁻¹) / Π_{j∈P₁}(1 − π_j q⁻¹),    G₂ = (b_nk/c)·(the rest)
//! ```
//!
//! with complex-conjugate pairs kept together so that both blocks have real coefficients, the
//! delay given to the front block, and `c` chosen so that G₁ has unit gain at DC (the signal
//! between the blocks then has the input's scale). When G₁'s DC gain is zero, infinite or below
//! 10⁻⁸ in size (a zero or a pole at z = 1), `c = 1` instead.
//! [`block_splits`] lists every allocation: 2^g of them for g groups (a real root or a
//! conjugate pair), the two extremes being the Wiener (`G₂ = gain`) and Hammerstein
//! (`G₁ = q^{−nk}`) structures.

use crate::{LinearError, PolynomialModel, response::roots};

/// The largest number of root groups [`block_splits`] enumerates (2^16 = 65 536 splits).
pub const MAX_ROOT_GROUPS: usize = 16;

/// One allocation of a SISO model's poles and zeros to a front block G₁ and a back block G₂,
/// with `G₂·G₁` equal to the model.
#[derive(Clone, Debug, PartialEq)]
pub struct BlockSplit {
    /// G₁, the block that reads the input (it carries the delay).
    pub front: PolynomialModel,
    /// G₂, the block that writes the output.
    pub back: PolynomialModel,
}

/// A real root, or a complex pair given by its member with positive imaginary part.
#[derive(Clone, Copy, Debug)]
struct RootGroup {
    re: f64,
    im: f64,
}

impl RootGroup {
    /// The group's factor in q⁻¹: `1 − r q⁻¹`, or `1 − 2·Re r q⁻¹ + |r|² q⁻²`.
    fn factor(&self) -> Vec<f64> {
        if self.im == 0.0 {
            vec![1.0, -self.re]
        } else {
            vec![1.0, -2.0 * self.re, self.re * self.re + self.im * self.im]
        }
    }
}

/// Groups roots into real roots and conjugate pairs; a root whose imaginary part is below
/// `1e-9·(1 + |r|)` counts as real.
fn groups(rs: &[(f64, f64)]) -> Vec<RootGroup> {
    rs.iter()
        .filter_map(|&(re, im)| {
            let tol = 1e-9 * (1.0 + re.hypot(im));
            if im.abs() <= tol {
                Some(RootGroup { re, im: 0.0 })
            } else if im > 0.0 {
                Some(RootGroup { re, im })
            } else {
                None
            }
        })
        .collect()
}

fn product(factors: impl Iterator<Item = Vec<f64>>) -> Vec<f64> {
    factors.fold(vec![1.0], |acc, f| crate::integrators::convolve(&acc, &f))
}

fn at_one(p: &[f64]) -> f64 {
    p.iter().sum()
}

/// Every allocation of `model`'s poles and zeros to two blocks in series (see the
/// [module docs](self)), in the order of a binary count over the root groups (poles first);
/// the first split is the Hammerstein one (everything in G₂), the last the Wiener one.
///
/// ```
/// use structid_linear::{PolynomialModel, split::block_splits};
/// use structid_lti::Signal;
/// // Two real poles and one zero: 2³ = 8 splits, each the same system in two pieces.
/// let m = PolynomialModel::new(vec![vec![0.0, 1.0, -0.5]], vec![1.0, -1.1, 0.28], None).unwrap();
/// let splits = block_splits(&m).unwrap();
/// assert_eq!(splits.len(), 8);
/// let u = Signal::from_fn(30, 1, |k, _| (k as f64 * 0.7).sin());
/// let whole = m.simulate(&u).unwrap();
/// for s in &splits {
///     let mid = s.front.simulate(&u).unwrap();
///     let y = s.back.simulate(&Signal::new(1, mid).unwrap()).unwrap();
///     assert!(y.iter().zip(&whole).all(|(a, b)| (a - b).abs() < 1e-9));
/// }
/// ```
///
/// # Errors
/// A model with more than one input, a zero numerator, or more than [`MAX_ROOT_GROUPS`] root
/// groups (the enumeration would be too large).
pub fn block_splits(model: &PolynomialModel) -> Result<Vec<BlockSplit>, LinearError> {
    model.validate()?;
    if model.inputs() != 1 {
        return Err(LinearError::dims(
            "inputs of a model split into two blocks",
            1,
            model.inputs(),
        ));
    }
    let a0 = model.den[0];
    let den: Vec<f64> = model.den.iter().map(|v| v / a0).collect();
    let num = &model.num[0];
    let Some(nk) = num.iter().position(|v| *v != 0.0) else {
        return Err(LinearError::InvalidModel(
            "a zero numerator has no blocks to split".into(),
        ));
    };
    let gain = num[nk] / a0;
    let poles = groups(&roots(&den));
    let zeros = groups(&roots(&num[nk..]));
    let g = poles.len() + zeros.len();
    if g > MAX_ROOT_GROUPS {
        return Err(LinearError::InvalidParameter {
            name: "model order".into(),
            reason: format!(
                "{g} real roots and conjugate pairs give 2^{g} splits; at most {MAX_ROOT_GROUPS} \
                 groups are enumerated (estimate a lower-order best linear approximation)"
            ),
        });
    }
    let all: Vec<(bool, RootGroup)> = poles
        .iter()
        .map(|r| (true, *r))
        .chain(zeros.iter().map(|r| (false, *r)))
        .collect();
    let ts = model.sample_time;
    (0u64..1 << g)
        .map(|mask| {
            let in_front = |i: usize| mask >> i & 1 == 1;
            let pick = |pole: bool, front: bool| {
                product(
                    all.iter()
                        .enumerate()
                        .filter(|(i, (p, _))| *p == pole && in_front(*i) == front)
                        .map(|(_, (_, r))| r.factor()),
                )
            };
            let (f1, f2) = (pick(true, true), pick(true, false));
            let (z1, z2) = (pick(false, true), pick(false, false));
            let dc = at_one(&z1) / at_one(&f1);
            let c = if dc.is_finite() && dc.abs() > 1e-8 {
                1.0 / dc
            } else {
                1.0
            };
            let mut b1 = vec![0.0; nk];
            b1.extend(z1.iter().map(|v| v * c));
            let b2: Vec<f64> = z2.iter().map(|v| v * gain / c).collect();
            Ok(BlockSplit {
                front: PolynomialModel::new(vec![b1], f1, ts)?,
                back: PolynomialModel::new(vec![b2], f2, ts)?,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use structid_lti::Signal;

    fn impulse(m: &PolynomialModel, len: usize) -> Vec<f64> {
        m.simulate(&Signal::from_fn(
            len,
            1,
            |k, _| if k == 0 { 1.0 } else { 0.0 },
        ))
        .unwrap()
    }

    proptest! {
        /// Every split's blocks in series give the model's impulse response back, every split
        /// is distinct, and conjugate pairs stay whole (the blocks have real coefficients by
        /// construction, so a broken pair would change the product).
        #[test]
        fn the_blocks_of_every_split_compose_to_the_model(
            p1 in 0.1f64..0.9, r in 0.2f64..0.9, angle in 0.2f64..2.5, z1 in -0.9f64..0.9,
            b0 in 0.2f64..3.0, nk in 0usize..3,
        ) {
            // Poles p1 and r·e^{±i·angle}, a zero z1: groups = 3, splits = 8.
            let den = crate::integrators::convolve(
                &[1.0, -p1],
                &[1.0, -2.0 * r * angle.cos(), r * r],
            );
            let mut num = vec![0.0; nk];
            num.extend([b0, -b0 * z1]);
            let m = PolynomialModel::new(vec![num], den, None).unwrap();
            let splits = block_splits(&m).unwrap();
            prop_assert_eq!(splits.len(), 8);
            let whole = impulse(&m, 40);
            for s in &splits {
                let h1 = impulse(&s.front, 40);
                let h2 = impulse(&s.back, 40);
                let composed: Vec<f64> = (0..40)
                    .map(|k| (0..=k).map(|j| h1[j] * h2[k - j]).sum())
                    .collect();
                for (a, b) in composed.iter().zip(&whole) {
                    prop_assert!((a - b).abs() < 1e-9 * (1.0 + b.abs()));
                }
                // The front block has the delay and, away from a DC zero, unit DC gain.
                prop_assert!(s.front.num[0][..nk].iter().all(|v| *v == 0.0));
                let dc = at_one(&s.front.num[0]) / at_one(&s.front.den);
                prop_assert!((dc - 1.0).abs() < 1e-9);
            }
            for i in 0..splits.len() {
                for j in 0..i {
                    prop_assert!(splits[i] != splits[j]);
                }
            }
        }
    }

    #[test]
    fn a_two_input_model_and_a_zero_numerator_are_refused() {
        let two = PolynomialModel::new(vec![vec![1.0], vec![1.0]], vec![1.0, -0.5], None).unwrap();
        assert!(block_splits(&two).is_err());
        let zero = PolynomialModel::new(vec![vec![0.0, 0.0]], vec![1.0, -0.5], None).unwrap();
        assert!(block_splits(&zero).is_err());
    }
}
