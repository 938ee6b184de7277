//! ARX order selection over a grid by information criteria or validation simulation error.

use std::ops::RangeInclusive;

use structid_lti::Signal;

use crate::arx::{ArxSettings, fit_arx_records, prepare_data};
use crate::error::LinearError;
use crate::orders::Orders;
use crate::polynomial::PolynomialModel;
use structid_lti::filter_row;

/// How [`select_orders`] scores a fitted ARX model (`V` = mean squared equation error over
/// the `N` equations, `d` = number of parameters; smaller is better).
///
/// ```
/// use structid_linear::OrderCriterion;
/// let c = OrderCriterion::Bic;
/// assert_eq!(c.name(), "BIC");
/// ```
#[derive(Clone, Debug, PartialEq)]
pub enum OrderCriterion {
    /// Akaike: `ln V + 2d/N`.
    Aic,
    /// Bayesian (Schwarz): `ln V + d ln N / N`.
    Bic,
    /// Akaike's final prediction error: `V (N + d)/(N − d)`.
    Fpe,
    /// Simulation mean squared error on a separate record (zero initial conditions). Among
    /// the models whose error is within one standard error of the best (standard error of
    /// the mean of the squared errors), the one with the fewest parameters wins (the
    /// one-standard-error rule), so that statistical ties do not favour over-parameterised
    /// models.
    Validation {
        /// Validation input (same channels as the estimation input).
        u: Signal,
        /// Validation output (one channel).
        y: Signal,
    },
}

impl OrderCriterion {
    /// Short name for reports: `"AIC"`, `"BIC"`, `"FPE"`, `"validation"`.
    ///
    /// ```
    /// use structid_linear::OrderCriterion;
    /// assert_eq!(OrderCriterion::Fpe.name(), "FPE");
    /// ```
    pub fn name(&self) -> &'static str {
        match self {
            OrderCriterion::Aic => "AIC",
            OrderCriterion::Bic => "BIC",
            OrderCriterion::Fpe => "FPE",
            OrderCriterion::Validation { .. } => "validation",
        }
    }
}

/// A grid of orders; the same `nb` and `nk` are used for every input.
///
/// ```
/// use structid_linear::OrderGrid;
/// let g = OrderGrid { na: 1..=4, nb: 1..=4, nk: 0..=3 };
/// assert_eq!(g.len(), 64);
/// ```
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct OrderGrid {
    /// Denominator orders.
    pub na: RangeInclusive<usize>,
    /// Numerator coefficient counts.
    pub nb: RangeInclusive<usize>,
    /// Input delays.
    pub nk: RangeInclusive<usize>,
}

impl OrderGrid {
    /// Number of grid points.
    ///
    /// ```
    /// use structid_linear::OrderGrid;
    /// assert_eq!(OrderGrid { na: 0..=2, nb: 1..=1, nk: 0..=1 }.len(), 6);
    /// ```
    pub fn len(&self) -> usize {
        let n = |r: &RangeInclusive<usize>| {
            if r.is_empty() {
                0
            } else {
                (r.end() - r.start()).saturating_add(1)
            }
        };
        n(&self.na)
            .saturating_mul(n(&self.nb))
            .saturating_mul(n(&self.nk))
    }

    /// `true` when one of the ranges is empty.
    ///
    /// ```
    /// use structid_linear::OrderGrid;
    /// #[allow(clippy::reversed_empty_ranges)]
    /// let g = OrderGrid { na: 1..=0, nb: 1..=1, nk: 0..=1 };
    /// assert!(g.is_empty());
    /// ```
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// The largest NA and NB of a selection grid.
///
/// Chosen from the cost: every candidate is an ARX fit costing about L·(na + nb)²
/// operations, so a grid up to order M costs about L·M⁴ (times the number of delays). Up to
/// M = 30 a record of 10⁴ samples takes about 13 s with three delays (measured, release
/// build); M = 200 would take some 2 000 times longer. Orders that high are also beyond what
/// a polynomial in q⁻¹ represents in double precision: the roots of a degree-n polynomial
/// move by about ε^(1/n) under a relative change ε of its coefficients.
pub const MAX_ORDER: usize = 30;

/// The most candidates a selection grid may hold: 30 × 30 orders at three delays (see
/// [`MAX_ORDER`] for the cost of each).
pub const MAX_CANDIDATES: usize = MAX_ORDER * MAX_ORDER * 3;

/// Refuses a grid whose orders exceed [`MAX_ORDER`] or that holds more than
/// [`MAX_CANDIDATES`] candidates, before any fit.
///
/// ```
/// use structid_linear::{OrderGrid, selection::check_grid};
/// assert!(check_grid(&OrderGrid { na: 1..=6, nb: 1..=6, nk: 1..=3 }).is_ok());
/// let e = check_grid(&OrderGrid { na: 1..=200, nb: 1..=200, nk: 1..=3 }).unwrap_err();
/// assert!(e.to_string().contains("at most 30"), "{e}");
/// assert!(check_grid(&OrderGrid { na: 1..=6, nb: 1..=6, nk: 0..=usize::MAX }).is_err());
/// ```
pub fn check_grid(grid: &OrderGrid) -> Result<(), LinearError> {
    let (na, nb) = (*grid.na.end(), *grid.nb.end());
    if na > MAX_ORDER || nb > MAX_ORDER {
        return Err(LinearError::param(
            "grid",
            format!(
                "orders up to na = {na}, nb = {nb} were asked for; the selection grid goes up to at \
                 most {MAX_ORDER} (each candidate is a least-squares fit costing about L·(na + nb)² \
                 operations, and polynomials of higher order are numerically meaningless)"
            ),
        ));
    }
    if grid.len() > MAX_CANDIDATES {
        return Err(LinearError::param(
            "grid",
            format!(
                "the grid has {} candidates (orders × delays); at most {MAX_CANDIDATES} are fitted: \
                 narrow the delay range",
                grid.len()
            ),
        ));
    }
    Ok(())
}

/// Result of [`select_orders`].
///
/// ```
/// use structid_linear::{select_orders, ArxSettings, OrderCriterion, OrderGrid};
/// use structid_lti::{testing::SplitMix64, Signal};
/// let mut rng = SplitMix64::new(3);
/// let u = Signal::from_fn(300, 1, |_, _| rng.uniform_in(-1.0, 1.0));
/// let y = Signal::from_fn(300, 1, |k, _| if k > 0 { u.get(k - 1, 0) } else { 0.0 } + rng.uniform_in(-0.1, 0.1));
/// let grid = OrderGrid { na: 0..=1, nb: 1..=2, nk: 0..=1 };
/// let sel = select_orders(&u, &y, &grid, &OrderCriterion::Aic, &ArxSettings::default()).unwrap();
/// assert_eq!(sel.table.len(), 8);
/// assert_eq!(sel.model.orders(), sel.best);
/// ```
#[derive(Clone, Debug)]
pub struct OrderSelection {
    /// The selected orders.
    pub best: Orders,
    /// The ARX model fitted with the selected orders.
    pub model: PolynomialModel,
    /// Criterion value of every grid point that could be fitted, in grid order (`na`
    /// outermost, then `nb`, then `nk`). Grid points whose regression fails (singular, too
    /// few samples, no parameters) are left out; for [`OrderCriterion::Validation`], a model
    /// whose simulation diverges scores `+∞`.
    pub table: Vec<(Orders, f64)>,
}

/// Fits an ARX model at every point of `grid` and returns the best by `criterion`.
///
/// All fits use the same equations `k = K … L−1`, `K` the largest lag in the grid, so the
/// criteria compare like with like.
///
/// [`ArxSettings::integrators`] is not applied here: to select the free part of a model with
/// `N` known integrators, pass the differenced output
/// [`integrators::difference`](crate::integrators::difference)`(y, N)` (as `structid linear
/// --integrators` does).
///
/// ```
/// use structid_linear::{select_orders, ArxSettings, OrderCriterion, OrderGrid, Orders};
/// use structid_lti::{testing::SplitMix64, Signal};
/// let mut rng = SplitMix64::new(1);
/// let u = Signal::from_fn(400, 1, |_, _| rng.uniform_in(-1.0, 1.0));
/// // y_k = 0.5 y_{k-1} + u_{k-1} + e_k
/// let mut y = vec![0.0; 400];
/// for k in 1..400 {
///     y[k] = 0.5 * y[k - 1] + u.get(k - 1, 0) + rng.uniform_in(-0.05, 0.05);
/// }
/// let y = Signal::new(1, y).unwrap();
/// let grid = OrderGrid { na: 1..=3, nb: 1..=3, nk: 0..=2 };
/// let sel = select_orders(&u, &y, &grid, &OrderCriterion::Bic, &ArxSettings::default()).unwrap();
/// assert_eq!(sel.best, Orders::siso(1, 1, 1));
/// ```
pub fn select_orders(
    u: &Signal,
    y: &Signal,
    grid: &OrderGrid,
    criterion: &OrderCriterion,
    settings: &ArxSettings,
) -> Result<OrderSelection, LinearError> {
    select_orders_observed(u, y, grid, criterion, settings, &|_, _| {})
}

/// [`select_orders`], telling `progress(done, total)` as each point of the grid is fitted (a
/// grid holds up to 2700 fits; the command-line tool draws a progress bar from it).
///
/// ```
/// use structid_linear::{ArxSettings, OrderCriterion, OrderGrid, select_orders_observed};
/// use structid_lti::Signal;
/// let u = Signal::from_fn(200, 1, |k, _| ((k * 7919) % 17) as f64 - 8.0);
/// let y = Signal::from_fn(200, 1, |k, _| if k > 0 { u.get(k - 1, 0) } else { 0.0 });
/// let grid = OrderGrid { na: 1..=2, nb: 1..=2, nk: 1..=1 };
/// let last = std::sync::Mutex::new((0, 0));
/// let progress = |done, total| *last.lock().unwrap() = (done, total);
/// select_orders_observed(&u, &y, &grid, &OrderCriterion::Bic, &ArxSettings::default(), &progress)
///     .unwrap();
/// assert_eq!(*last.lock().unwrap(), (4, 4));
/// ```
pub fn select_orders_observed(
    u: &Signal,
    y: &Signal,
    grid: &OrderGrid,
    criterion: &OrderCriterion,
    settings: &ArxSettings,
    progress: &dyn Fn(u64, u64),
) -> Result<OrderSelection, LinearError> {
    select_orders_records(&[(u, y)], grid, criterion, settings, progress)
}

/// [`select_orders_observed`] over several records (experiments) of the same system, given as
/// `(u, y)` pairs: each candidate is one ARX fit over the equations of every record, each
/// record's equations starting after its own first samples (as
/// [`arx_records`](crate::arx_records)), and AIC, BIC and FPE count the equations of all
/// records. One record gives [`select_orders_observed`]'s selection.
///
/// ```
/// use structid_linear::{select_orders_records, ArxSettings, OrderCriterion, OrderGrid, Orders};
/// use structid_lti::{testing::SplitMix64, Signal};
/// let mut rng = SplitMix64::new(3);
/// let mut record = |len: usize| {
///     let u = Signal::from_fn(len, 1, |_, _| rng.uniform_in(-1.0, 1.0));
///     let mut y = vec![0.0; len];
///     for k in 1..len {
///         y[k] = 0.5 * y[k - 1] + u.get(k - 1, 0) + rng.uniform_in(-0.05, 0.05);
///     }
///     (u, Signal::new(1, y).unwrap())
/// };
/// let (a, b) = (record(200), record(150));
/// let grid = OrderGrid { na: 1..=3, nb: 1..=3, nk: 0..=2 };
/// let sel = select_orders_records(&[(&a.0, &a.1), (&b.0, &b.1)], &grid, &OrderCriterion::Bic,
///     &ArxSettings::default(), &|_, _| {})?;
/// assert_eq!(sel.best, Orders::siso(1, 1, 1));
/// # Ok::<(), structid_linear::LinearError>(())
/// ```
pub fn select_orders_records(
    records: &[(&Signal, &Signal)],
    grid: &OrderGrid,
    criterion: &OrderCriterion,
    settings: &ArxSettings,
    progress: &dyn Fn(u64, u64),
) -> Result<OrderSelection, LinearError> {
    let Some(&(u, _)) = records.first() else {
        return Err(LinearError::param("records", "no data record was given"));
    };
    if grid.is_empty() {
        return Err(LinearError::param(
            "grid",
            "every order range must be non-empty",
        ));
    }
    check_grid(grid)?;
    let inputs = u.channels();
    if inputs == 0 {
        return Err(LinearError::dims("input channels", "at least 1", 0));
    }
    let crate::output_error::Stacked {
        u: uc,
        y: yv,
        bounds,
    } = crate::output_error::Stacked::new(records, inputs)?;
    let validation = match criterion {
        OrderCriterion::Validation { u, y } => Some(prepare_data(u, y, inputs, "validation ")?),
        _ => None,
    };
    let (na_max, nb_max, nk_max) = (*grid.na.end(), *grid.nb.end(), *grid.nk.end());
    let start = na_max.max((nk_max + nb_max).saturating_sub(1));
    let mut rows: Vec<(Orders, f64, f64, PolynomialModel)> = Vec::new(); // orders, value, SE, model
    let mut last_error = None;
    let total =
        (grid.na.clone().count() * grid.nb.clone().count() * grid.nk.clone().count()) as u64;
    let mut done = 0u64;
    for na in grid.na.clone() {
        for nb in grid.nb.clone() {
            for nk in grid.nk.clone() {
                done += 1;
                progress(done, total);
                let orders = Orders {
                    na,
                    nb: vec![nb; inputs],
                    nk: vec![nk; inputs],
                };
                if orders.parameters() == 0 {
                    continue;
                }
                let fit = match fit_arx_records(&uc, &yv, &orders, settings, &bounds, start) {
                    Ok((f, _)) => f,
                    Err(e) => {
                        last_error = Some(e);
                        continue;
                    }
                };
                let n = fit.samples as f64;
                let d = orders.parameters() as f64;
                let v = fit.cost.max(f64::MIN_POSITIVE);
                let (value, se) = match criterion {
                    OrderCriterion::Aic => (v.ln() + 2.0 * d / n, 0.0),
                    OrderCriterion::Bic => (v.ln() + d * n.ln() / n, 0.0),
                    OrderCriterion::Fpe => (v * (n + d) / (n - d), 0.0),
                    OrderCriterion::Validation { .. } => {
                        let (vu, vy) = validation.as_ref().expect("validation data prepared");
                        validation_error(&fit.model, vu, vy)
                    }
                };
                rows.push((orders, value, se, fit.model));
            }
        }
    }
    if rows.is_empty() {
        return Err(last_error.unwrap_or_else(|| {
            LinearError::InvalidOrders("the grid has no point with parameters".into())
        }));
    }
    let best_idx = pick(
        &rows,
        matches!(criterion, OrderCriterion::Validation { .. }),
    );
    let (best, _, _, model) = rows[best_idx].clone();
    Ok(OrderSelection {
        best,
        model,
        table: rows.into_iter().map(|(o, v, _, _)| (o, v)).collect(),
    })
}

/// Index of the minimum; with `one_se`, the smallest model within one standard error of it.
fn pick(rows: &[(Orders, f64, f64, PolynomialModel)], one_se: bool) -> usize {
    let mut best = 0;
    for (i, r) in rows.iter().enumerate() {
        if r.1 < rows[best].1 || rows[best].1.is_nan() {
            best = i;
        }
    }
    if !one_se {
        return best;
    }
    let limit = rows[best].1 + rows[best].2;
    let mut chosen = best;
    for (i, r) in rows.iter().enumerate() {
        if r.1 <= limit {
            let (dp, dc) = (r.0.parameters(), rows[chosen].0.parameters());
            if dp < dc || (dp == dc && r.1 < rows[chosen].1) {
                chosen = i;
            }
        }
    }
    chosen
}

/// Simulation MSE of `model` on a validation record and the standard error of that mean;
/// `(+∞, 0)` when the simulation diverges.
fn validation_error(model: &PolynomialModel, u: &[Vec<f64>], y: &[f64]) -> (f64, f64) {
    let a0 = model.den[0];
    let den: Vec<f64> = model.den.iter().map(|v| v / a0).collect();
    let num: Vec<Vec<f64>> = model
        .num
        .iter()
        .map(|b| b.iter().map(|v| v / a0).collect())
        .collect();
    let mut yhat = vec![0.0; y.len()];
    filter_row(&num, &den, u, &mut yhat);
    let n = y.len() as f64;
    let sq: Vec<f64> = y.iter().zip(&yhat).map(|(a, b)| (a - b).powi(2)).collect();
    let mse = sq.iter().sum::<f64>() / n;
    if !mse.is_finite() {
        return (f64::INFINITY, 0.0);
    }
    let var = sq.iter().map(|s| (s - mse).powi(2)).sum::<f64>() / (n - 1.0).max(1.0);
    (mse, (var / n).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testutil::*;

    #[test]
    fn oversized_grids_are_refused_before_any_fit() {
        let (u, y) = record(1, 200, 0.1);
        let grid = |m: usize, nk: RangeInclusive<usize>| OrderGrid {
            na: 1..=m,
            nb: 1..=m,
            nk,
        };
        let t = std::time::Instant::now();
        for g in [grid(200, 1..=3), grid(31, 1..=1), grid(6, 0..=usize::MAX)] {
            let e = select_orders(&u, &y, &g, &OrderCriterion::Bic, &ArxSettings::default())
                .unwrap_err();
            assert!(matches!(e, LinearError::InvalidParameter { .. }), "{e}");
        }
        assert!(t.elapsed().as_secs_f64() < 1.0);
        assert_eq!(grid(6, 0..=usize::MAX).len(), usize::MAX);
        assert!(check_grid(&grid(MAX_ORDER, 1..=3)).is_ok());
        assert!(check_grid(&grid(MAX_ORDER, 0..=3)).is_err());
    }

    /// `A y = B u + e` with `A = 1 − 1.5q⁻¹ + 0.7q⁻²`, `B = q⁻¹(1 + 0.5q⁻¹)`.
    fn record(seed: u64, len: usize, noise: f64) -> (Signal, Signal) {
        let truth =
            PolynomialModel::new(vec![vec![0.0, 1.0, 0.5]], vec![1.0, -1.5, 0.7], None).unwrap();
        let u = white(seed, len, 1.0, 1);
        let e = white(seed + 1000, len, noise, 1);
        let two = PolynomialModel {
            num: vec![truth.num[0].clone(), vec![1.0]],
            ..truth
        };
        let ue = Signal::from_fn(
            len,
            2,
            |k, c| if c == 0 { u.get(k, 0) } else { e.get(k, 0) },
        );
        let y = Signal::new(1, two.simulate(&ue).unwrap()).unwrap();
        (u, y)
    }

    /// Over two records, BIC picks the true orders, and every candidate's value is the BIC of
    /// the ARX fit over both records computed here with `arx_records`; one record is
    /// `select_orders`.
    #[test]
    fn selection_over_records_scores_the_fit_over_every_record() {
        let (ua, ya) = record(61, 700, 0.5);
        let (ub, yb) = record(62, 500, 0.5);
        let grid = OrderGrid {
            na: 1..=3,
            nb: 1..=3,
            nk: 0..=2,
        };
        let s = ArxSettings::default();
        let pairs = [(&ua, &ya), (&ub, &yb)];
        let sel =
            select_orders_records(&pairs, &grid, &OrderCriterion::Bic, &s, &|_, _| {}).unwrap();
        assert_eq!(sel.best, Orders::siso(2, 2, 1));
        // The equations start after the largest lag of the grid in each record.
        // max(na_max, nk_max + nb_max − 1) = max(3, 2 + 3 − 1)
        let start = 4;
        for (orders, value) in &sel.table {
            let fit = crate::arx::fit_arx_records(
                &[[ua.channel(0), ub.channel(0)].concat()],
                &[ya.channel(0), yb.channel(0)].concat(),
                orders,
                &s,
                &[0, 700, 1200],
                start,
            )
            .unwrap()
            .0;
            assert_eq!(fit.samples, 700 + 500 - 2 * start);
            let (n, d) = (fit.samples as f64, orders.parameters() as f64);
            let bic = fit.cost.ln() + d * n.ln() / n;
            assert!((value - bic).abs() < 1e-12, "{orders}: {value} vs {bic}");
        }
        let one = select_orders_records(&pairs[..1], &grid, &OrderCriterion::Bic, &s, &|_, _| {})
            .unwrap();
        let direct = select_orders(&ua, &ya, &grid, &OrderCriterion::Bic, &s).unwrap();
        assert_eq!(one.table, direct.table);
        assert!(select_orders_records(&[], &grid, &OrderCriterion::Bic, &s, &|_, _| {}).is_err());
    }

    #[test]
    fn bic_aic_fpe_and_validation_pick_the_true_orders() {
        let (u, y) = record(51, 2000, 0.5);
        let (uv, yv) = record(52, 2000, 0.5);
        let grid = OrderGrid {
            na: 1..=4,
            nb: 1..=4,
            nk: 0..=3,
        };
        let s = ArxSettings::default();
        let truth = Orders::siso(2, 2, 1);
        for crit in [
            OrderCriterion::Bic,
            OrderCriterion::Validation { u: uv, y: yv },
        ] {
            let sel = select_orders(&u, &y, &grid, &crit, &s).unwrap();
            assert_eq!(sel.best, truth, "{}: {:?}", crit.name(), sel.table);
            assert_eq!(sel.table.len(), 64);
            assert_eq!(sel.model.orders(), truth);
        }
        // AIC and FPE at least find the right structure family (they may over-fit)
        for crit in [OrderCriterion::Aic, OrderCriterion::Fpe] {
            let sel = select_orders(&u, &y, &grid, &crit, &s).unwrap();
            assert!(sel.best.na >= 2 && sel.best.nk[0] <= 1, "{}", crit.name());
        }
    }

    #[test]
    fn errors() {
        let (u, y) = record(53, 100, 0.1);
        let s = ArxSettings::default();
        let (lo, hi) = (2, 1);
        let empty = OrderGrid {
            na: lo..=hi,
            nb: 1..=1,
            nk: 0..=0,
        };
        assert!(select_orders(&u, &y, &empty, &OrderCriterion::Aic, &s).is_err());
        let grid = OrderGrid {
            na: 1..=2,
            nb: 1..=2,
            nk: 0..=1,
        };
        let bad = OrderCriterion::Validation {
            u: u.clone(),
            y: y.slice(0..50),
        };
        assert!(matches!(
            select_orders(&u, &y, &grid, &bad, &s),
            Err(LinearError::LengthMismatch { .. })
        ));
        // every grid point needs more samples than available: the fit error is returned
        let big = OrderGrid {
            na: 30..=30,
            nb: 30..=30,
            nk: 0..=0,
        };
        let (u, y) = (u.slice(0..60), y.slice(0..60));
        assert!(matches!(
            select_orders(&u, &y, &big, &OrderCriterion::Bic, &s),
            Err(LinearError::TooFewSamples { .. })
        ));
    }
}
