//! The candidate table and its one selection rule.
//!
//! Every model the workflow weighs is a row ([`Candidate`]): its form (a named family, a
//! nonparametric map, …), its number of parameters, its fit on the estimation record, and its
//! errors e_r(k) on the validation record, all scored the same way (free run or windows,
//! chosen once per run). [`select`] decides among the rows by one rule with a statistical
//! meaning:
//!
//! 1. The best row b has the smallest mean squared validation error among the rows that may
//!    be chosen (a family with an unidentifiable parameter or a refit that did not converge is
//!    shown, but is not a candidate: its fit is not a model the data determine).
//! 2. Row r is *as good as the best* unless a paired test over blocks of the validation record
//!    says that r is worse at the level α ([`compare_blocks`]): the record's scored samples
//!    are cut into B contiguous blocks, and the log ratios ℓ_j = ln(MSE_r,j / MSE_b,j) of the
//!    two rows' mean squared errors in each block are tested for a positive mean (one-sided,
//!    S = mean(ℓ)/(sd(ℓ)/√B), P(Z ≥ S) < α). Blocks allow for the serial correlation of
//!    simulation errors; the log ratio weighs every block alike, so that a few blocks where a
//!    simulation nearly diverges neither hide a row that is worse everywhere else nor condemn
//!    one that is as good everywhere else (a paired test of the squared errors themselves,
//!    Diebold–Mariano's, is dominated by such blocks).
//! 3. Among the rows as good as the best, the simplest in
//!    [`Candidate::complexity`] order is chosen: a named family before a nonparametric map, fewer
//!    parameters first, the exact forms before the approximate ones.
//!
//! A caller that also gives the errors of a reference (the model without the block) learns
//! whether the chosen row beats it at the same α ([`Selection::beats_reference`]).
//!
//! α is the level of each row's comparison with the best: the chance of dismissing one row
//! that is in truth as good as the best. Each row is compared with the best of the table, not
//! with a fixed model, and no correction is made for the number of rows, so a row as good as
//! the best is dismissed somewhat more often than α. The smaller α, the more rows count as
//! equally good and the simpler the choice.
//!
//! ```
//! use structid_discover::table::{Candidate, Form, select};
//! // Two rows whose errors are different series of the same size, and a much worse one.
//! let a: Vec<f64> = (0..400).map(|k| ((k * 7919) % 101) as f64 / 50.0 - 1.0).collect();
//! let b: Vec<f64> = (0..400).map(|k| ((k * 104_729 + 13) % 101) as f64 / 50.0 - 1.0).collect();
//! let rich = Candidate::new("rich", Form::Nonparametric { estimator: "quadratic".into() }, 0)
//!     .with_errors(a.clone());
//! let simple = Candidate::new("simple", Form::Family { approximate: false }, 2)
//!     .with_errors(b);
//! let poor = Candidate::new("poor", Form::Family { approximate: false }, 1)
//!     .with_errors(a.iter().map(|e| 3.0 * e).collect());
//! let s = select(&[rich, simple, poor], None, 0.05);
//! assert!(s.as_good[0] && s.as_good[1]);
//! assert_eq!(s.chosen, Some(1)); // as good as the best, and simpler than a nonparametric map
//! assert!(!s.as_good[2]);
//! ```

use structid_core::validation::comparison::mean_statistic;
use structid_core::validation::distributions::upper_normal_tail;

use crate::hypotheses::Site;

/// The significance level of the selection rule when none is given: a row is dismissed as
/// worse than the best only when the paired test says so with at most a 5 % chance of error.
pub const DEFAULT_SIGNIFICANCE: f64 = 0.05;

/// What kind of model a row is, for the complexity order.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
#[serde(rename_all = "kebab-case", tag = "kind")]
pub enum Form {
    /// The model without any new block (the reference).
    Nominal,
    /// A parametric family of the effects library; `approximate` for forms that bend to
    /// another family's shape (a tanh saturation, a power law without a linear term).
    Family {
        /// Whether the form approximates others.
        approximate: bool,
    },
    /// A nonparametric map (`quadratic` or `total variation`).
    Nonparametric {
        /// The estimator.
        estimator: String,
    },
}

impl Form {
    /// The form's rank in the complexity order: a family before a nonparametric map.
    fn rank(&self) -> u8 {
        match self {
            Form::Nominal => 0,
            Form::Family { .. } => 1,
            Form::Nonparametric { .. } => 2,
        }
    }
}

/// One row of the table.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Candidate {
    /// What the row is, e.g. `saturation` or `nonparametric (quadratic)`.
    pub label: String,
    /// Where its block sits, if it has one.
    pub location: Option<Site>,
    /// Its form.
    pub form: Form,
    /// Its number of parameters (for a nonparametric map, the points it was estimated on are
    /// not counted: its rank in the order places it after every family).
    pub parameters: usize,
    /// Whether G was refitted with the block.
    pub g_refitted: bool,
    /// Its simulation RMS on the estimation record, when known.
    pub estimation_rms: Option<f64>,
    /// Its simulation RMS on the validation record (infinite when it failed or diverged).
    pub validation_rms: f64,
    /// Whether the row may be chosen (a family with identifiable parameters and a refit that
    /// converged; a nonparametric map always may).
    pub eligible: bool,
    /// The validation errors at the scored samples (empty when the simulation failed).
    #[serde(skip)]
    pub errors: Vec<f64>,
}

impl Candidate {
    /// A row without errors yet (see [`Candidate::with_errors`]).
    pub fn new(label: impl Into<String>, form: Form, parameters: usize) -> Self {
        Candidate {
            label: label.into(),
            location: None,
            form,
            parameters,
            g_refitted: false,
            estimation_rms: None,
            validation_rms: f64::INFINITY,
            eligible: true,
            errors: Vec::new(),
        }
    }

    /// The row with validation errors `errors` (and their RMS as its validation RMS).
    pub fn with_errors(mut self, errors: Vec<f64>) -> Self {
        self.validation_rms = rms(&errors);
        self.errors = if self.validation_rms.is_finite() {
            errors
        } else {
            Vec::new()
        };
        self
    }

    /// The row's key in the complexity order (smaller is simpler): its form's rank, its
    /// number of parameters, then exact before approximate.
    pub fn complexity(&self) -> (u8, usize, bool) {
        let approximate = matches!(self.form, Form::Family { approximate: true });
        (self.form.rank(), self.parameters, approximate)
    }

    fn scored(&self) -> bool {
        !self.errors.is_empty() && self.validation_rms.is_finite()
    }
}

/// The RMS of `errors`; infinite when there are none or one is not finite (a simulation that
/// failed or diverged).
pub(crate) fn rms(errors: &[f64]) -> f64 {
    if errors.is_empty() || errors.iter().any(|e| !e.is_finite()) {
        return f64::INFINITY;
    }
    (errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt()
}

/// How many contiguous blocks of the validation record [`compare_blocks`] uses (fewer when
/// the record is short: at least [`MIN_BLOCK`] samples a block).
pub const BLOCKS: usize = 20;

/// The fewest samples a block of [`compare_blocks`] holds.
pub const MIN_BLOCK: usize = 10;

/// The outcome of [`compare_blocks`].
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct BlockComparison {
    /// The mean over blocks of ln(MSE_a / MSE_b): positive when a's errors are larger.
    pub mean_log_ratio: f64,
    /// S = mean / (sd/√B).
    pub statistic: f64,
    /// P(Z ≥ S) for a standard normal Z: small when a is worse than b.
    pub p_worse: f64,
    /// The number of blocks B.
    pub blocks: usize,
}

impl BlockComparison {
    /// Whether a is better than b at level α (one-sided).
    pub fn better_at(&self, alpha: f64) -> bool {
        1.0 - self.p_worse < alpha
    }
}

/// The paired test of two models' errors `a` and `b` on the same samples over contiguous
/// blocks (see the [module documentation](self)); `None` for unequal lengths, fewer than
/// three blocks of [`MIN_BLOCK`] samples, or a block where either MSE is not positive and
/// finite.
///
/// ```
/// use structid_discover::table::compare_blocks;
/// let b: Vec<f64> = (0..400).map(|k| (0.7 * k as f64).sin()).collect();
/// let a: Vec<f64> = b.iter().map(|v| 1.5 * v).collect();
/// let c = compare_blocks(&a, &b).unwrap();
/// assert!((c.mean_log_ratio - (2.25f64).ln()).abs() < 1e-12 && c.p_worse < 1e-6);
/// ```
pub fn compare_blocks(a: &[f64], b: &[f64]) -> Option<BlockComparison> {
    let n = a.len();
    if n != b.len() {
        return None;
    }
    let blocks = BLOCKS.min(n / MIN_BLOCK);
    if blocks < 3 {
        return None;
    }
    let mse = |e: &[f64]| e.iter().map(|v| v * v).sum::<f64>() / e.len() as f64;
    let ratios: Vec<f64> = (0..blocks)
        .map(|j| {
            let r = j * n / blocks..(j + 1) * n / blocks;
            (mse(&a[r.clone()]) / mse(&b[r])).ln()
        })
        .collect();
    if ratios.iter().any(|l| !l.is_finite()) {
        return None;
    }
    let m = blocks as f64;
    let mean = ratios.iter().sum::<f64>() / m;
    let var = ratios.iter().map(|l| (l - mean).powi(2)).sum::<f64>() / (m - 1.0);
    let statistic = mean_statistic(mean, var, blocks);
    Some(BlockComparison {
        mean_log_ratio: mean,
        statistic,
        p_worse: upper_normal_tail(statistic),
        blocks,
    })
}

/// What [`select`] decided, row by row.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Selection {
    /// The significance level α used.
    pub alpha: f64,
    /// The eligible row with the smallest validation RMS.
    pub best: usize,
    /// For every row, the one-sided p-value of "worse than the best" (`None` for the best
    /// row itself and for rows that could not be compared).
    pub p_worse_than_best: Vec<Option<f64>>,
    /// For every row, whether it is eligible and as good as the best at α.
    pub as_good: Vec<bool>,
    /// The chosen row: the simplest eligible row as good as the best (`None` when no row
    /// is eligible and as good).
    pub chosen: Option<usize>,
    /// The chosen row against the reference, when a reference was given.
    #[serde(skip)]
    pub against_reference: Option<BlockComparison>,
    /// Whether a reference was given and a row chosen.
    reference_given: bool,
}

impl Selection {
    /// Whether the chosen row beats the reference at α: `None` when no reference was given
    /// or nothing was chosen, `Some(false)` when the comparison could not be made.
    pub fn beats_reference(&self) -> Option<bool> {
        self.reference_given.then(|| {
            self.against_reference
                .as_ref()
                .is_some_and(|c| c.better_at(self.alpha))
        })
    }
}

/// Applies the selection rule (see the [module documentation](self)) to `rows`, against the
/// errors of `reference` (the model without the block) when given, at significance `alpha`.
///
/// Rows whose simulation failed (no errors) and rows that are not eligible are never as good
/// (their p-values are still given). When no eligible row was scored, `best` is 0 and nothing
/// is chosen.
pub fn select(rows: &[Candidate], reference: Option<&[f64]>, alpha: f64) -> Selection {
    let best = (0..rows.len())
        .filter(|&i| rows[i].scored() && rows[i].eligible)
        .min_by(|&a, &b| rows[a].validation_rms.total_cmp(&rows[b].validation_rms));
    let Some(best) = best else {
        return Selection {
            alpha,
            best: 0,
            p_worse_than_best: vec![None; rows.len()],
            as_good: vec![false; rows.len()],
            chosen: None,
            against_reference: None,
            reference_given: false,
        };
    };
    let p: Vec<Option<f64>> = rows
        .iter()
        .enumerate()
        .map(|(i, r)| {
            (i != best && r.scored())
                .then(|| compare_blocks(&r.errors, &rows[best].errors))
                .flatten()
                .map(|c| c.p_worse)
        })
        .collect();
    let as_good: Vec<bool> = (0..rows.len())
        .map(|i| i == best || (rows[i].eligible && p[i].is_some_and(|p| p >= alpha)))
        .collect();
    let chosen = (0..rows.len()).filter(|&i| as_good[i]).min_by(|&a, &b| {
        rows[a]
            .complexity()
            .cmp(&rows[b].complexity())
            .then(rows[a].validation_rms.total_cmp(&rows[b].validation_rms))
    });
    let against_reference = match (chosen, reference) {
        (Some(c), Some(reference)) => compare_blocks(&rows[c].errors, reference),
        _ => None,
    };
    Selection {
        alpha,
        best,
        p_worse_than_best: p,
        as_good,
        chosen,
        against_reference,
        reference_given: reference.is_some() && chosen.is_some(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use rand::{RngExt, SeedableRng, rngs::StdRng};

    fn white(n: usize, scale: f64, seed: u64) -> Vec<f64> {
        let mut rng = StdRng::seed_from_u64(seed);
        (0..n)
            .map(|_| scale * (rng.random::<f64>() - 0.5))
            .collect()
    }

    fn family(label: &str, k: usize, errors: Vec<f64>) -> Candidate {
        Candidate::new(label, Form::Family { approximate: false }, k).with_errors(errors)
    }

    #[test]
    fn a_clearly_better_rich_row_beats_a_simple_one() {
        // The simple row's errors carry a systematic component larger than the noise's RMS.
        let e = white(2000, 1.0, 1);
        let biased = e
            .iter()
            .enumerate()
            .map(|(k, e)| e + if k % 2 == 0 { 0.6 } else { -0.6 });
        let simple = family("simple", 1, biased.collect());
        let rich = family("rich", 4, e.clone());
        let s = select(&[simple, rich], None, 0.05);
        assert_eq!(s.best, 1);
        assert!(!s.as_good[0], "{:?}", s.p_worse_than_best);
        assert_eq!(s.chosen, Some(1));
    }

    #[test]
    fn failed_and_ineligible_rows_are_never_chosen_nor_the_bar() {
        let e = white(500, 1.0, 2);
        let failed = Candidate::new("failed", Form::Family { approximate: false }, 1);
        let mut flagged = family("flagged", 2, e.iter().map(|v| 0.9 * v).collect());
        flagged.eligible = false;
        let table = Candidate::new(
            "table",
            Form::Nonparametric {
                estimator: "tv".into(),
            },
            0,
        )
        .with_errors(e.clone());
        let s = select(&[failed, flagged, table], None, 0.05);
        // The flagged row validates best but is not a candidate: the table is the best
        // eligible row and is chosen, and the flagged row's p-value is still reported.
        assert_eq!(s.best, 2);
        assert!(!s.as_good[0] && !s.as_good[1]);
        assert_eq!(s.chosen, Some(2));
        assert!(s.p_worse_than_best[1].is_some_and(|p| p > 0.5));
        let only_flagged = select(&rows_without_table(), None, 0.05);
        assert_eq!(only_flagged.chosen, None);
    }

    fn rows_without_table() -> Vec<Candidate> {
        let mut flagged = family("flagged", 2, white(500, 1.0, 2));
        flagged.eligible = false;
        vec![flagged]
    }

    #[test]
    fn nothing_scored_chooses_nothing() {
        let rows = [Candidate::new("a", Form::Nominal, 0)];
        let s = select(&rows, None, 0.05);
        assert_eq!(s.chosen, None);
        assert!(!s.as_good[0]);
    }

    #[test]
    fn the_reference_must_be_beaten() {
        let e = white(1000, 1.0, 3);
        let row = family("row", 1, e.iter().map(|v| 0.98 * v).collect());
        let s = select(std::slice::from_ref(&row), Some(&e), 0.05);
        assert_eq!(s.chosen, Some(0));
        // A 2 % gain on a deterministic scaling is significant: d_k = (0.98² − 1)·e_k² < 0.
        assert_eq!(s.beats_reference(), Some(true));
        let same = select(std::slice::from_ref(&row), Some(&row.errors), 0.05);
        assert_eq!(same.beats_reference(), Some(false));
        // A reference of another length cannot be compared: not beaten.
        let short = select(std::slice::from_ref(&row), Some(&e[..10]), 0.05);
        assert_eq!(short.beats_reference(), Some(false));
        assert_eq!(
            select(std::slice::from_ref(&row), None, 0.05).beats_reference(),
            None
        );
    }

    proptest! {
        // The chosen row is as good as the best, eligible, and no eligible row as good as the
        // best is simpler (checked by brute force over the rows).
        #[test]
        fn the_choice_is_the_simplest_row_as_good_as_the_best(
            scales in proptest::collection::vec(0.5f64..2.0, 1..6),
            sizes in proptest::collection::vec(0usize..6, 6),
            seed in 0u64..1000,
        ) {
            let base = white(300, 1.0, seed);
            let rows: Vec<Candidate> = scales
                .iter()
                .enumerate()
                .map(|(i, s)| {
                    let noise = white(300, 0.2, seed + 1 + i as u64);
                    family(&format!("r{i}"), sizes[i], base.iter().zip(&noise).map(|(b, n)| s * b + n).collect())
                })
                .collect();
            let s = select(&rows, None, 0.05);
            let min = rows.iter().map(|r| r.validation_rms).fold(f64::INFINITY, f64::min);
            prop_assert_eq!(rows[s.best].validation_rms, min);
            let c = s.chosen.expect("the best row is always as good as itself");
            prop_assert!(s.as_good[c]);
            for (i, r) in rows.iter().enumerate() {
                if s.as_good[i] {
                    prop_assert!(r.complexity() >= rows[c].complexity());
                }
                // As good means not significantly worse: p ≥ α.
                if let Some(p) = s.p_worse_than_best[i] {
                    prop_assert_eq!(s.as_good[i], p >= 0.05);
                }
            }
        }
    }
}
