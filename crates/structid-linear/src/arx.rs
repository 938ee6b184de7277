//! ARX estimation by linear least squares (column-scaled QR with faer).

use faer::Mat;
use nalgebra::DMatrix;
use structid_lti::Signal;

use crate::error::{LinearError, check_finite, check_non_negative, check_sample_time};
use crate::integrators::{
    MAX_INTEGRATORS, convolve, difference, full_covariance, integrator_polynomial,
};
use crate::orders::Orders;
use crate::polynomial::PolynomialModel;

/// Default limit on the condition number of the column-scaled regressor matrix.
///
/// ```
/// assert_eq!(structid_linear::ArxSettings::default().max_condition(), structid_linear::arx::DEFAULT_MAX_CONDITION);
/// ```
pub const DEFAULT_MAX_CONDITION: f64 = 1e12;

/// Settings of [`arx`] (build with [`ArxSettings::builder`]; [`Default`] is valid).
///
/// ```
/// use structid_linear::ArxSettings;
/// let s = ArxSettings::builder().sample_time(0.01).ridge(1e-6).build().unwrap();
/// assert_eq!((s.sample_time(), s.ridge()), (Some(0.01), 1e-6));
/// assert!(ArxSettings::builder().ridge(-1.0).build().is_err());
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct ArxSettings {
    pub(crate) sample_time: Option<f64>,
    ridge: f64,
    max_condition: f64,
    integrators: usize,
}

impl Default for ArxSettings {
    /// No sample time, no ridge, maximum condition number 1e12, no fixed integrator.
    fn default() -> Self {
        ArxSettings {
            sample_time: None,
            ridge: 0.0,
            max_condition: DEFAULT_MAX_CONDITION,
            integrators: 0,
        }
    }
}

impl ArxSettings {
    /// A builder from the defaults.
    ///
    /// ```
    /// use structid_linear::ArxSettings;
    /// assert_eq!(ArxSettings::builder().build().unwrap(), ArxSettings::default());
    /// ```
    pub fn builder() -> ArxSettingsBuilder {
        ArxSettingsBuilder(Self::default())
    }
    /// Sample time attached to the fitted model (`None` by default).
    ///
    /// ```
    /// use structid_linear::ArxSettings;
    /// assert_eq!(ArxSettings::default().sample_time(), None);
    /// ```
    pub fn sample_time(&self) -> Option<f64> {
        self.sample_time
    }
    /// Ridge weight λ ≥ 0: the fit minimises `‖Y − Φθ‖² + λ‖θ‖²` (0 by default).
    ///
    /// ```
    /// use structid_linear::ArxSettings;
    /// assert_eq!(ArxSettings::default().ridge(), 0.0);
    /// ```
    pub fn ridge(&self) -> f64 {
        self.ridge
    }
    /// Largest admissible condition number of the column-scaled regressor matrix before
    /// [`LinearError::SingularRegression`] is reported (1e12 by default).
    ///
    /// ```
    /// use structid_linear::ArxSettings;
    /// assert_eq!(ArxSettings::default().max_condition(), 1e12);
    /// ```
    pub fn max_condition(&self) -> f64 {
        self.max_condition
    }
    /// Number `N` of integrators fixed at `z = 1` (0 by default): the fit regresses
    /// `(1 − q⁻¹)ᴺ y` on the input with the given orders (`na` counts the free poles) and
    /// returns `A = A'(1 − q⁻¹)ᴺ`, of order `na + N` (see [`crate::integrators`]).
    ///
    /// ```
    /// use structid_linear::ArxSettings;
    /// assert_eq!(ArxSettings::default().integrators(), 0);
    /// ```
    pub fn integrators(&self) -> usize {
        self.integrators
    }
}

/// Builder for [`ArxSettings`].
///
/// ```
/// use structid_linear::ArxSettings;
/// let s = ArxSettings::builder().max_condition(1e8).build().unwrap();
/// assert_eq!(s.max_condition(), 1e8);
/// ```
#[derive(Clone, Debug)]
pub struct ArxSettingsBuilder(ArxSettings);

impl ArxSettingsBuilder {
    /// Sample time in seconds (positive, finite).
    ///
    /// ```
    /// use structid_linear::ArxSettings;
    /// assert!(ArxSettings::builder().sample_time(0.0).build().is_err());
    /// ```
    pub fn sample_time(mut self, ts: f64) -> Self {
        self.0.sample_time = Some(ts);
        self
    }
    /// Ridge weight λ (≥ 0, finite).
    ///
    /// ```
    /// use structid_linear::ArxSettings;
    /// assert!(ArxSettings::builder().ridge(f64::NAN).build().is_err());
    /// ```
    pub fn ridge(mut self, ridge: f64) -> Self {
        self.0.ridge = ridge;
        self
    }
    /// Condition-number limit (> 1).
    ///
    /// ```
    /// use structid_linear::ArxSettings;
    /// assert!(ArxSettings::builder().max_condition(0.5).build().is_err());
    /// ```
    pub fn max_condition(mut self, limit: f64) -> Self {
        self.0.max_condition = limit;
        self
    }
    /// Integrators fixed at `z = 1` (at most [`MAX_INTEGRATORS`]).
    ///
    /// ```
    /// use structid_linear::ArxSettings;
    /// assert_eq!(ArxSettings::builder().integrators(1).build().unwrap().integrators(), 1);
    /// assert!(ArxSettings::builder().integrators(3).build().is_err());
    /// ```
    pub fn integrators(mut self, n: usize) -> Self {
        self.0.integrators = n;
        self
    }
    /// Validates.
    ///
    /// ```
    /// use structid_linear::ArxSettings;
    /// assert!(ArxSettings::builder().ridge(1.0).build().is_ok());
    /// ```
    pub fn build(self) -> Result<ArxSettings, LinearError> {
        check_sample_time(self.0.sample_time)?;
        check_non_negative("ridge", self.0.ridge)?;
        let c = self.0.max_condition;
        if c.is_nan() || c <= 1.0 {
            return Err(LinearError::param(
                "max_condition",
                format!("must exceed 1, got {c}"),
            ));
        }
        check_integrators(self.0.integrators)?;
        Ok(self.0)
    }
}

/// Result of [`arx()`].
///
/// ```
/// use structid_linear::{arx, ArxSettings, Orders};
/// use structid_lti::Signal;
/// let u = Signal::from_fn(100, 1, |k, _| ((k * k) as f64 * 0.37).sin());
/// let y = Signal::from_fn(100, 1, |k, _| if k > 0 { 2.0 * u.get(k - 1, 0) } else { 0.0 });
/// let fit = arx(&u, &y, &Orders::siso(0, 1, 1), &ArxSettings::default()).unwrap();
/// assert!((fit.model.num[0][1] - 2.0).abs() < 1e-12 && fit.cost < 1e-20);
/// assert_eq!((fit.samples, fit.parameter_std.len()), (99, 1));
/// ```
#[derive(Clone, Debug)]
pub struct ArxFit {
    /// The fitted model (`den` = `A`).
    pub model: PolynomialModel,
    /// Mean squared equation error `RSS / samples`.
    pub cost: f64,
    /// Standard deviations of the parameters, in the order `θ = (b…, a…)` of
    /// [`PolynomialModel::parameters`]: `sqrt(σ̂² diag((ΦᵀΦ)⁻¹))` with `σ̂² = RSS/(samples − d)`
    /// (with a ridge, the sandwich `(ΦᵀΦ+λI)⁻¹ΦᵀΦ(ΦᵀΦ+λI)⁻¹`).
    pub parameter_std: Vec<f64>,
    /// The covariance of the same parameters (whose diagonal gives
    /// [`parameter_std`](Self::parameter_std)), for the uncertainty of what depends on
    /// several of them, such as the frequency response ([`crate::response`]).
    pub parameter_covariance: Option<DMatrix<f64>>,
    /// 2-norm condition number of the column-scaled regressor matrix (with the ridge rows).
    pub condition: f64,
    /// Number of equations (samples after the first `max_lag`, and after the `N` samples
    /// the differencing needs when integrators are fixed).
    pub samples: usize,
    /// Integrators fixed at `z = 1` ([`ArxSettings::integrators`]); the denominator
    /// contains `(1 − q⁻¹)ᴺ` exactly and those coefficients have no uncertainty of their own.
    pub integrators: usize,
}

/// Fits an ARX model `A(q) y_k = Σ_i B_i(q) u_{i,k} + e_k` by least squares.
///
/// `u` has one channel per input (`orders.inputs()`), `y` one channel, both of the same
/// length `L`. The equations run over `k = max_lag … L−1` (no assumption about the data before
/// the record); at least `max_lag + d + 1` samples are needed (`d = orders.parameters()`).
///
/// ```
/// use structid_linear::{arx, ArxSettings, Orders, PolynomialModel};
/// use structid_lti::Signal;
/// let truth = PolynomialModel::new(vec![vec![0.0, 1.0, 0.5]], vec![1.0, -1.5, 0.7], None).unwrap();
/// let u = Signal::from_fn(200, 1, |k, _| ((k * k) as f64 * 0.37).sin());
/// let y = Signal::new(1, truth.simulate(&u).unwrap()).unwrap();
/// let fit = arx(&u, &y, &Orders::siso(2, 2, 1), &ArxSettings::default()).unwrap();
/// assert!((fit.model.den[1] + 1.5).abs() < 1e-9);
/// assert_eq!(fit.samples, 198);
/// ```
pub fn arx(
    u: &Signal,
    y: &Signal,
    orders: &Orders,
    settings: &ArxSettings,
) -> Result<ArxFit, LinearError> {
    orders.validate()?;
    let (uc, yv) = prepare_data(u, y, orders.inputs(), "")?;
    let n = settings.integrators;
    if n == 0 {
        return fit_arx(&uc, &yv, orders, settings, orders.max_lag()).map(|(fit, _)| fit);
    }
    // A'(q) (1 − q⁻¹)ᴺ y = B u + e is an ARX model of the differenced output.
    let yd = difference(&yv, n);
    let (free, cov) = fit_arx(&uc, &yd, orders, settings, orders.max_lag() + n)?;
    with_integrators(free, &cov, orders, n)
}

/// [`arx`] over several records (experiments) of the same system, given as `(u, y)` pairs:
/// one least-squares fit over the equations of every record, each record's equations
/// starting `max_lag` (+ N with integrators) samples after its own start, so that no
/// regressor mixes two records. One record gives [`arx`]'s fit.
///
/// ```
/// use structid_linear::{arx, arx_records, ArxSettings, Orders, PolynomialModel};
/// use structid_lti::Signal;
/// let truth = PolynomialModel::new(vec![vec![0.0, 1.0]], vec![1.0, -0.5], None).unwrap();
/// let rec = |len: usize, shift: usize| {
///     let u = Signal::from_fn(len, 1, |k, _| (((k + shift) * (k + shift)) as f64 * 0.37).sin());
///     let y = Signal::new(1, truth.simulate(&u).unwrap()).unwrap();
///     (u, y)
/// };
/// let (a, b) = (rec(60, 0), rec(40, 7));
/// let s = ArxSettings::default();
/// let fit = arx_records(&[(&a.0, &a.1), (&b.0, &b.1)], &Orders::siso(1, 1, 1), &s).unwrap();
/// assert!((fit.model.den[1] + 0.5).abs() < 1e-9);
/// assert_eq!(fit.samples, 59 + 39);
/// ```
pub fn arx_records(
    records: &[(&Signal, &Signal)],
    orders: &Orders,
    settings: &ArxSettings,
) -> Result<ArxFit, LinearError> {
    orders.validate()?;
    let Some(first) = records.first() else {
        return Err(LinearError::param("records", "no data record was given"));
    };
    if records.len() == 1 {
        return arx(first.0, first.1, orders, settings);
    }
    let mut uc: Vec<Vec<f64>> = vec![Vec::new(); orders.inputs()];
    let mut yv = Vec::new();
    let mut bounds = vec![0];
    let n = settings.integrators;
    for (i, (u, y)) in records.iter().enumerate() {
        let (ui, yi) = prepare_data(u, y, orders.inputs(), &format!("record {}: ", i + 1))?;
        for (c, col) in uc.iter_mut().zip(ui) {
            c.extend(col);
        }
        // Differenced record by record: the first N samples of each are not equations.
        yv.extend(if n == 0 { yi } else { difference(&yi, n) });
        bounds.push(yv.len());
    }
    let start = orders.max_lag() + n;
    let (free, cov) = fit_arx_records(&uc, &yv, orders, settings, &bounds, start)?;
    if n == 0 {
        return Ok(free);
    }
    with_integrators(free, &cov, orders, n)
}

/// The fit `free` of the differenced output (free parameter covariance `cov`) as the fit
/// of the model with its `n` integrators at `z = 1` put back into the denominator.
fn with_integrators(
    free: ArxFit,
    cov: &DMatrix<f64>,
    orders: &Orders,
    n: usize,
) -> Result<ArxFit, LinearError> {
    let den = convolve(&free.model.den, &integrator_polynomial(n));
    let model = PolynomialModel::new(free.model.num, den, free.model.sample_time)?;
    let cov = full_covariance(cov, orders.nb.iter().sum(), orders.na, n);
    let parameter_std = std_from(&cov);
    Ok(ArxFit {
        model,
        parameter_std,
        parameter_covariance: Some(cov),
        integrators: n,
        ..free
    })
}

/// Checks a number of fixed integrators.
pub(crate) fn check_integrators(n: usize) -> Result<(), LinearError> {
    if n > MAX_INTEGRATORS {
        return Err(LinearError::param(
            "integrators",
            format!("at most {MAX_INTEGRATORS} integrators can be fixed, got {n}"),
        ));
    }
    Ok(())
}

/// Square roots of the diagonal (negative rounding clipped to 0).
pub(crate) fn std_from(cov: &DMatrix<f64>) -> Vec<f64> {
    (0..cov.nrows())
        .map(|i| cov[(i, i)].max(0.0).sqrt())
        .collect()
}

/// Checks an input/output record and returns the input channels and the output.
pub(crate) fn prepare_data(
    u: &Signal,
    y: &Signal,
    inputs: usize,
    prefix: &str,
) -> Result<(Vec<Vec<f64>>, Vec<f64>), LinearError> {
    if y.channels() != 1 {
        return Err(LinearError::dims(
            format!("{prefix}output channels"),
            "1 (MISO models)",
            y.channels(),
        ));
    }
    if u.channels() != inputs {
        return Err(LinearError::dims(
            format!("{prefix}input channels"),
            format!("{inputs} (one per model input)"),
            u.channels(),
        ));
    }
    if u.len() != y.len() {
        return Err(LinearError::LengthMismatch {
            input: u.len(),
            output: y.len(),
        });
    }
    check_finite(&format!("{prefix}input"), u.as_slice(), u.channels())?;
    check_finite(&format!("{prefix}output"), y.as_slice(), 1)?;
    let uc = (0..inputs).map(|c| u.channel(c)).collect();
    Ok((uc, y.as_slice().to_vec()))
}

/// Regressor value of parameter `p` at time `k` (`θ = (b…, a…)`); `lags[p]` is the lag
/// and `src[p]` the source (`Some(i)`: input `i`, `None`: minus the output).
struct Regressors<'a> {
    u: &'a [Vec<f64>],
    y: &'a [f64],
    lag: Vec<usize>,
    src: Vec<Option<usize>>,
}

impl<'a> Regressors<'a> {
    fn new(u: &'a [Vec<f64>], y: &'a [f64], orders: &Orders) -> Self {
        let mut lag = Vec::new();
        let mut src = Vec::new();
        for (i, (&nb, &nk)) in orders.nb.iter().zip(&orders.nk).enumerate() {
            for j in 0..nb {
                lag.push(nk + j);
                src.push(Some(i));
            }
        }
        for j in 1..=orders.na {
            lag.push(j);
            src.push(None);
        }
        Regressors { u, y, lag, src }
    }

    #[inline]
    fn at(&self, k: usize, p: usize) -> f64 {
        let t = k - self.lag[p];
        match self.src[p] {
            Some(i) => self.u[i][t],
            None => -self.y[t],
        }
    }
}

/// ARX least squares over the equations `k = start … L−1` (`start ≥ orders.max_lag()`),
/// with no integrator (`settings.integrators` is ignored: callers difference the output
/// themselves), and the covariance of `θ`.
pub(crate) fn fit_arx(
    u: &[Vec<f64>],
    y: &[f64],
    orders: &Orders,
    settings: &ArxSettings,
    start: usize,
) -> Result<(ArxFit, DMatrix<f64>), LinearError> {
    fit_arx_records(u, y, orders, settings, &[0, y.len()], start)
}

/// [`fit_arx`] over several records stacked in `u` and `y`, record i being samples
/// `bounds[i]..bounds[i + 1]`: the equations of each record start `start` samples after its
/// own first sample, so no regressor reaches into the previous record.
pub(crate) fn fit_arx_records(
    u: &[Vec<f64>],
    y: &[f64],
    orders: &Orders,
    settings: &ArxSettings,
    bounds: &[usize],
    start: usize,
) -> Result<(ArxFit, DMatrix<f64>), LinearError> {
    let d = orders.parameters();
    let rows: Vec<usize> = bounds
        .windows(2)
        .flat_map(|w| (w[0] + start).min(w[1])..w[1])
        .collect();
    if rows.len() < d + 1 {
        let records = bounds.len().saturating_sub(1);
        return Err(LinearError::TooFewSamples {
            what: format!("ARX with orders {orders} ({d} parameters, first usable sample {start})"),
            needed: start + d + 1,
            available: if records > 1 {
                rows.len() + start
            } else {
                y.len()
            },
        });
    }
    let n = rows.len();
    let reg = Regressors::new(u, y, orders);
    // column scaling
    let mut scale = vec![0.0; d];
    for (p, s) in scale.iter_mut().enumerate() {
        let ss: f64 = rows.iter().map(|&k| reg.at(k, p).powi(2)).sum();
        *s = if ss > 0.0 { ss.sqrt() } else { 1.0 };
    }
    let ridge = settings.ridge();
    let extra = if ridge > 0.0 { d } else { 0 };
    let m = Mat::<f64>::from_fn(n + extra, d + 1, |r, c| {
        if r < n {
            let k = rows[r];
            if c < d { reg.at(k, c) / scale[c] } else { y[k] }
        } else if c == r - n {
            ridge.sqrt() / scale[c]
        } else {
            0.0
        }
    });
    let qr = m.qr();
    let rf = qr.thin_R();
    let r11 = DMatrix::from_fn(d, d, |i, j| if j >= i { rf[(i, j)] } else { 0.0 });
    let z = nalgebra::DVector::from_fn(d, |i, _| rf[(i, d)]);
    let sv = r11.singular_values();
    let smax = sv.max();
    let smin = sv.min();
    let condition = if smin > 0.0 {
        smax / smin
    } else {
        f64::INFINITY
    };
    if condition.is_nan() || condition > settings.max_condition() {
        return Err(LinearError::SingularRegression {
            condition,
            limit: settings.max_condition(),
        });
    }
    let Some(theta_s) = r11.solve_upper_triangular(&z) else {
        return Err(LinearError::SingularRegression {
            condition: f64::INFINITY,
            limit: settings.max_condition(),
        });
    };
    let theta: Vec<f64> = (0..d).map(|p| theta_s[p] / scale[p]).collect();
    let mut rss = 0.0;
    for &k in &rows {
        let pred: f64 = (0..d).map(|p| reg.at(k, p) * theta[p]).sum();
        rss += (y[k] - pred).powi(2);
    }
    let sigma2 = rss / (n - d) as f64;
    let g = r11
        .solve_upper_triangular(&DMatrix::identity(d, d))
        .expect("R11 checked non-singular");
    let cov_s = if ridge > 0.0 {
        let w = g.transpose()
            * DMatrix::from_diagonal(&nalgebra::DVector::from_fn(d, |i, _| {
                1.0 / (scale[i] * scale[i])
            }))
            * &g;
        let middle = DMatrix::identity(d, d) - w * ridge;
        &g * middle * g.transpose()
    } else {
        &g * g.transpose()
    };
    let cov = DMatrix::from_fn(d, d, |p, q| sigma2 * cov_s[(p, q)] / (scale[p] * scale[q]));
    let parameter_std = std_from(&cov);
    let model = PolynomialModel::from_parameters(orders, &theta, settings.sample_time())?;
    Ok((
        ArxFit {
            model,
            cost: rss / n as f64,
            parameter_std,
            parameter_covariance: Some(cov.clone()),
            condition,
            samples: n,
            integrators: 0,
        },
        cov,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testutil::*;

    #[test]
    fn records_are_fitted_exactly_where_their_concatenation_is_not() {
        let truth =
            PolynomialModel::new(vec![vec![0.0, 1.0, 0.5]], vec![1.0, -1.5, 0.7], None).unwrap();
        let (ua, ub) = (white(3, 80, 1.0, 1), white(4, 50, 1.0, 1));
        let ya = Signal::new(1, truth.simulate(&ua).unwrap()).unwrap();
        let yb = Signal::new(1, truth.simulate(&ub).unwrap()).unwrap();
        let orders = Orders::siso(2, 2, 1);
        let s = ArxSettings::default();
        let fit = arx_records(&[(&ua, &ya), (&ub, &yb)], &orders, &s).unwrap();
        assert_close(&fit.model.parameters(), &truth.parameters(), 1e-9);
        assert_eq!(fit.samples, 78 + 48);
        // Record b started at rest; glued after a, the equations at the seam see a's end.
        let cat =
            |a: &Signal, b: &Signal| Signal::new(1, [a.as_slice(), b.as_slice()].concat()).unwrap();
        let glued = arx(&cat(&ua, &ub), &cat(&ya, &yb), &orders, &s).unwrap();
        assert!(glued.cost > 1e-6, "{}", glued.cost);
        // One record is arx itself; a record too short for any equation adds none.
        let one = arx_records(&[(&ua, &ya)], &orders, &s).unwrap();
        assert_eq!(one.model, arx(&ua, &ya, &orders, &s).unwrap().model);
        let (us, ys) = (white(5, 2, 1.0, 1), Signal::zeros(2, 1));
        let with_short = arx_records(&[(&ua, &ya), (&us, &ys)], &orders, &s).unwrap();
        assert_eq!(with_short.samples, 78);
        assert!(arx_records(&[], &orders, &s).is_err());
    }

    #[test]
    fn recovers_second_order_exactly() {
        let truth =
            PolynomialModel::new(vec![vec![0.0, 1.0, 0.5]], vec![1.0, -1.5, 0.7], Some(0.1))
                .unwrap();
        let u = white(1, 500, 1.0, 1);
        let y = Signal::new(1, truth.simulate(&u).unwrap()).unwrap();
        let s = ArxSettings::builder().sample_time(0.1).build().unwrap();
        let fit = arx(&u, &y, &Orders::siso(2, 2, 1), &s).unwrap();
        assert_close(&fit.model.parameters(), &truth.parameters(), 1e-9);
        assert_eq!(fit.model.sample_time, Some(0.1));
        assert!(fit.cost < 1e-20);
        assert!(fit.condition.is_finite() && fit.condition > 1.0);
        assert_eq!(fit.samples, 498);
    }

    #[test]
    fn recovers_delays() {
        for nk in [2usize, 3] {
            let mut num = vec![0.0; nk];
            num.extend([1.0, 0.5]);
            let truth = PolynomialModel::new(vec![num], vec![1.0, -1.5, 0.7], None).unwrap();
            let u = white(2 + nk as u64, 400, 1.0, 1);
            let y = Signal::new(1, truth.simulate(&u).unwrap()).unwrap();
            let fit = arx(&u, &y, &Orders::siso(2, 2, nk), &ArxSettings::default()).unwrap();
            assert_close(&fit.model.parameters(), &truth.parameters(), 1e-9);
            assert_eq!(fit.model.orders(), Orders::siso(2, 2, nk));
        }
    }

    #[test]
    fn equation_error_noise_within_a_few_std() {
        let truth =
            PolynomialModel::new(vec![vec![0.0, 1.0, 0.5]], vec![1.0, -1.5, 0.7], None).unwrap();
        let u = white(11, 3000, 1.0, 1);
        let e = white(12, 3000, 0.3, 1);
        // A y = B u + e  <=>  y = B/A u + 1/A e
        let noise = PolynomialModel::new(vec![vec![1.0]], truth.den.clone(), None).unwrap();
        let y0 = truth.simulate(&u).unwrap();
        let v = noise.simulate(&e).unwrap();
        let y = Signal::new(1, y0.iter().zip(&v).map(|(a, b)| a + b).collect()).unwrap();
        let fit = arx(&u, &y, &Orders::siso(2, 2, 1), &ArxSettings::default()).unwrap();
        let est = fit.model.parameters();
        for (p, ((a, b), s)) in est
            .iter()
            .zip(truth.parameters())
            .zip(&fit.parameter_std)
            .enumerate()
        {
            assert!(s.is_finite() && *s > 0.0);
            assert!(
                (a - b).abs() < 4.0 * s,
                "parameter {p}: {a} vs {b}, std {s}"
            );
        }
        assert!((fit.cost - 0.09).abs() < 0.01, "cost {}", fit.cost);
    }

    #[test]
    fn miso_and_ridge() {
        let truth = PolynomialModel::new(
            vec![vec![0.5, 0.2], vec![0.0, 0.0, -1.0]],
            vec![1.0, -0.6],
            None,
        )
        .unwrap();
        let u = white(5, 300, 1.0, 2);
        let y = Signal::new(1, truth.simulate(&u).unwrap()).unwrap();
        let o = Orders::new(1, vec![2, 1], vec![0, 2]).unwrap();
        let fit = arx(&u, &y, &o, &ArxSettings::default()).unwrap();
        assert_close(&fit.model.parameters(), &truth.parameters(), 1e-9);
        // a ridge shrinks the parameters a little and keeps the std finite
        let s = ArxSettings::builder().ridge(10.0).build().unwrap();
        let fr = arx(&u, &y, &o, &s).unwrap();
        let norm = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>();
        assert!(norm(&fr.model.parameters()) < norm(&truth.parameters()));
        assert!(fr.parameter_std.iter().all(|s| s.is_finite()));
    }

    #[test]
    fn errors() {
        let o = Orders::siso(2, 2, 1);
        let s = ArxSettings::default();
        let u = white(1, 100, 1.0, 1);
        let y = white(2, 100, 1.0, 1);
        // NaN in the output, named with its sample
        let mut yb = y.clone();
        yb.as_mut_slice()[17] = f64::NAN;
        let e = arx(&u, &yb, &o, &s).unwrap_err();
        assert!(
            matches!(&e, LinearError::NonFinite { signal, sample: 17, .. } if signal == "output")
        );
        assert!(e.to_string().contains("sample 17"));
        let mut ub = u.clone();
        ub.as_mut_slice()[3] = f64::INFINITY;
        assert!(matches!(
            arx(&ub, &y, &o, &s),
            Err(LinearError::NonFinite { sample: 3, .. })
        ));
        // length mismatch
        assert!(matches!(
            arx(&u.slice(0..99), &y, &o, &s),
            Err(LinearError::LengthMismatch {
                input: 99,
                output: 100
            })
        ));
        // too few samples: max_lag 2 + 4 parameters + 1
        let e = arx(&u.slice(0..6), &y.slice(0..6), &o, &s).unwrap_err();
        assert!(matches!(
            e,
            LinearError::TooFewSamples {
                needed: 7,
                available: 6,
                ..
            }
        ));
        let ok = arx(&u.slice(0..7), &y.slice(0..7), &o, &s);
        assert!(ok.is_ok(), "{ok:?}");
        // wrong channel count
        assert!(matches!(
            arx(&Signal::zeros(100, 2), &y, &o, &s),
            Err(LinearError::DimensionMismatch { .. })
        ));
        // zero input: singular
        let e = arx(&Signal::zeros(100, 1), &y, &o, &s).unwrap_err();
        assert!(matches!(e, LinearError::SingularRegression { .. }));
        assert!(e.to_string().contains("condition"));
        // invalid orders
        let bad = Orders {
            na: 2,
            nb: vec![1],
            nk: vec![0, 1],
        };
        assert!(matches!(
            arx(&u, &y, &bad, &s),
            Err(LinearError::InvalidOrders(_))
        ));
    }
}
