//! Output-error fits of G alone: with a free initial state, integrators held at z = 1,
//! several records, and the best linear approximation built on them.

use super::*;

/// Output-error estimate of `g` from `inputs` to `y`, optionally with a free initial state.
///
/// The free response of a realisation of B/F with n states is any sequence C·Aᵏ·x₀, and these
/// are exactly the responses I(q)/F(q)·δ_k to a unit impulse at k = 0 of a numerator
/// I = i₀ + i₁q⁻¹ + … + i_{n−1}q^{−(n−1)}: both satisfy F(q)·y_k = 0 from k = n on and span n
/// dimensions. So the initial state is estimated by adding an impulse input with its own
/// numerator (sharing F) to the output-error fit, and dropping it afterwards. The criterion is
/// then the one [`identify()`] minimises with [`InitialState::Estimate`].
pub fn output_error_with_state(
    inputs: &Signal,
    y: &Signal,
    g: &PolynomialModel,
    settings: &OeSettings,
    free_initial_state: bool,
) -> Result<OeFit> {
    output_error_records_with_state(&[(inputs, y)], g, settings, free_initial_state, 0)
}

/// The best linear approximation of order n from `data` (one input, one output): na = nb = n
/// with one sample of delay, fitted by ARX and then by output error with a free initial state
/// ([`output_error_with_state`]), so that the criterion is the simulation error.
///
/// ```
/// use structid_core::{Data, refine::best_linear_approximation};
/// use structid_linear::PolynomialModel;
/// use structid_lti::Signal;
/// let g = PolynomialModel { num: vec![vec![0.0, 0.5, 0.2]], den: vec![1.0, -1.2, 0.5], sample_time: None };
/// let u = Signal::from_fn(400, 1, |k, _| ((k * k) as f64 * 0.37).sin());
/// let y = Signal::new(1, g.simulate(&u)?)?;
/// let bla = best_linear_approximation(&Data::new(u, y)?, 2, 1.0)?;
/// assert!((bla.den[1] + 1.2).abs() < 1e-6 && (bla.num[0][1] - 0.5).abs() < 1e-6);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn best_linear_approximation(
    data: &Data,
    order: usize,
    sample_time: f64,
) -> Result<PolynomialModel> {
    data.require_single_record("the best linear approximation")?;
    let arx_settings = structid_linear::ArxSettings::builder()
        .sample_time(sample_time)
        .build()
        .map_err(linear_error)?;
    let orders = structid_linear::Orders::siso(order, order, 1);
    let start = structid_linear::arx(data.u(), data.y(), &orders, &arx_settings)
        .map_err(linear_error)?
        .model;
    let oe = OeSettings::builder()
        .sample_time(sample_time)
        .build()
        .map_err(linear_error)?;
    Ok(output_error_with_state(data.u(), data.y(), &start, &oe, true)?.model)
}

/// [`output_error_with_state`] with `integrators` poles of `g` held at z = 1.
///
/// G = B/(F′·(1 − q⁻¹)ⁿ) applied to v is B/F′ applied to ṽ = v/(1 − q⁻¹)ⁿ (v summed n times
/// from zero), so the fit is an ordinary output-error fit of the stable B/F′ from ṽ to y with
/// the same cost. Filtering y by (1 − q⁻¹)ⁿ instead would colour the noise and change the
/// criterion. With a free initial state the impulse input is summed too: I/F′ on the summed
/// impulse is I/F on the impulse, the free response of all n + deg F′ states.
pub fn output_error_with_integrators(
    inputs: &Signal,
    y: &Signal,
    g: &PolynomialModel,
    settings: &OeSettings,
    free_initial_state: bool,
    integrators: usize,
) -> Result<OeFit> {
    output_error_records_with_state(&[(inputs, y)], g, settings, free_initial_state, integrators)
}

/// [`output_error_with_integrators`] over several records (experiments) of the same system,
/// given as `(inputs, y)` pairs: one fit of G to the stacked simulation errors, each record
/// simulated from rest ([`structid_linear::output_error_records`]) or, with
/// `free_initial_state`, from an initial state of its own (one impulse input per record, each
/// with its own numerator, as in [`output_error_with_state`]). The cost is the mean over all
/// samples of all records, the criterion [`identify()`] minimises on a [`Data`] of several
/// records. `integrators` poles of `g` stay at z = 1 (0 for none), the inputs being summed
/// record by record from zero. One record gives [`output_error_with_integrators`]'s fit.
///
/// ```
/// use structid_core::refine::output_error_records_with_state;
/// use structid_linear::PolynomialModel;
/// use structid_lti::Signal;
/// let g = PolynomialModel { num: vec![vec![0.0, 0.5]], den: vec![1.0, -0.8], sample_time: None };
/// // Two records, each started from its own state x₀ (free response 2·0.8ᵏ and −1·0.8ᵏ).
/// let rec = |len: usize, shift: usize, x0: f64| {
///     let u = Signal::from_fn(len, 1, |k, _| (((k + shift) * (k + shift)) as f64 * 0.37).sin());
///     let sim = g.simulate(&u).unwrap();
///     let y: Vec<f64> = (0..len).map(|k| sim[k] + x0 * 0.8f64.powi(k as i32)).collect();
///     (u, Signal::new(1, y).unwrap())
/// };
/// let (a, b) = (rec(150, 0, 2.0), rec(100, 5, -1.0));
/// let start = PolynomialModel { num: vec![vec![0.0, 0.4]], den: vec![1.0, -0.6], sample_time: None };
/// let s = structid_linear::OeSettings::default();
/// let fit = output_error_records_with_state(&[(&a.0, &a.1), (&b.0, &b.1)], &start, &s, true, 0)?;
/// assert!((fit.model.den[1] + 0.8).abs() < 1e-8 && fit.cost < 1e-20);
/// assert_eq!(fit.model.num.len(), 1); // the impulse inputs are dropped
/// # Ok::<(), structid_core::Error>(())
/// ```
pub fn output_error_records_with_state(
    records: &[(&Signal, &Signal)],
    g: &PolynomialModel,
    settings: &OeSettings,
    free_initial_state: bool,
    integrators: usize,
) -> Result<OeFit> {
    // The output-error orders are read from the numerators (nk = leading zeros): an all-zero
    // numerator would have no free coefficient and its path would silently stay at zero.
    if let Some(i) = g
        .num
        .iter()
        .position(|b| !b.is_empty() && b.iter().all(|&v| v == 0.0))
    {
        return Err(Error::InvalidStructure(format!(
            "numerator {i} of the linear part is all zeros, so output error cannot tell its \
             delay and would keep that path at zero; start it from small nonzero coefficients \
             after the delay (e.g. [0.0, 1e-6, 1e-6] for a delay of one sample)"
        )));
    }
    let Some(first) = records.first() else {
        return Err(Error::InvalidStructure("no data record was given".into()));
    };
    let order = state_order(g);
    let m = first.0.channels();
    let count = records.len();
    let mut start = g.clone();
    let mut columns: Vec<Signal> = records.iter().map(|(u, _)| (*u).clone()).collect();
    if free_initial_state && order > 0 {
        // One impulse input per record, at that record's first sample (zero in the others).
        for (r, (inputs, _)) in records.iter().enumerate() {
            if inputs.channels() != m {
                // output_error_records() reports the mismatch.
                continue;
            }
            columns[r] = Signal::from_fn(inputs.len(), m + count, |k, c| {
                if c < m {
                    inputs.get(k, c)
                } else if c - m == r && k == 0 {
                    1.0
                } else {
                    0.0
                }
            });
        }
        // Start each impulse numerator at the best initial state of its record for `g` (a
        // linear least-squares problem once F is fixed), so that the fit begins at the cost
        // identify() reaches with InitialState::Estimate and can only go below it, however
        // early the iteration stops.
        for (inputs, y) in records {
            start.num.push(best_impulse_numerator(inputs, y, g, order)?);
        }
    }
    if integrators > 0 {
        start.den = integrators::deflate(&g.den, integrators)?;
        for c in &mut columns {
            *c = integrators::sum(c, integrators)?;
        }
    }
    let pairs: Vec<(&Signal, &Signal)> = columns
        .iter()
        .zip(records)
        .map(|(u, (_, y))| (u, *y))
        .collect();
    // The numerator coefficients of the inputs, then those of the impulse inputs (θ = (b…, f…)).
    let nb = start.orders().nb;
    let (nb_inputs, nb_impulses) = (
        nb.iter().take(m).sum::<usize>(),
        nb.iter().skip(m).sum::<usize>(),
    );
    let mut fit = output_error_records(&pairs, &start, settings).map_err(linear_error)?;
    fit.model.num.truncate(m);
    if nb_impulses > 0 {
        // The initial states are nuisance parameters: G's uncertainty is theirs marginalised,
        // the rows and columns of G's parameters in the joint covariance.
        let keep: Vec<usize> = (0..fit.parameter_std.len())
            .filter(|&i| i < nb_inputs || i >= nb_inputs + nb_impulses)
            .collect();
        fit.parameter_std = keep.iter().map(|&i| fit.parameter_std[i]).collect();
        fit.parameter_covariance = fit.parameter_covariance.map(|c| {
            nalgebra::DMatrix::from_fn(keep.len(), keep.len(), |i, j| c[(keep[i], keep[j])])
        });
    }
    if integrators > 0 {
        fit.model.den = integrators::inflate(&fit.model.den, integrators);
    }
    Ok(fit)
}

/// [`output_error_records_with_state`] on stacked signals with record bounds `[0, L₁, …, L]`.
pub(super) fn oe_fit_stacked(
    inputs: &Signal,
    y: &Signal,
    bounds: &[usize],
    g: &PolynomialModel,
    settings: &OeSettings,
    free_initial_state: bool,
    integrators: usize,
) -> Result<OeFit> {
    if bounds.len() <= 2 {
        return output_error_records_with_state(
            &[(inputs, y)],
            g,
            settings,
            free_initial_state,
            integrators,
        );
    }
    let parts: Vec<(Signal, Signal)> = bounds
        .windows(2)
        .map(|w| (inputs.slice(w[0]..w[1]), y.slice(w[0]..w[1])))
        .collect();
    let pairs: Vec<(&Signal, &Signal)> = parts.iter().map(|(u, y)| (u, y)).collect();
    output_error_records_with_state(&pairs, g, settings, free_initial_state, integrators)
}

/// The number of states of a realisation of `g`: its longest numerator's or its denominator's
/// degree, whichever is larger (the length of an initial state's free response).
pub(super) fn state_order(g: &PolynomialModel) -> usize {
    g.num
        .iter()
        .map(|b| b.len().saturating_sub(1))
        .chain([g.den.len().saturating_sub(1)])
        .max()
        .unwrap_or(0)
}

/// The numerator I (`order` coefficients) whose impulse response I/F·δ best fits the
/// residual y − G·inputs in least squares: the free response of the best initial state for G.
/// Coefficients that come out exactly zero are replaced by a tiny value so that every one
/// stays a free parameter of the output-error fit (the orders are read from the numerators).
pub(super) fn best_impulse_numerator(
    inputs: &Signal,
    y: &Signal,
    g: &PolynomialModel,
    order: usize,
) -> Result<Vec<f64>> {
    let len = y.len();
    let tiny = |v: Vec<f64>| -> Vec<f64> {
        v.into_iter()
            .map(|c| if c == 0.0 || !c.is_finite() { 1e-12 } else { c })
            .collect()
    };
    if len == 0 || y.channels() != 1 || inputs.len() != len {
        // output_error() reports the mismatch.
        return Ok(vec![1e-12; order]);
    }
    let sim = g.simulate(inputs).map_err(linear_error)?;
    // The impulse response h of 1/F; column j of the regressors is h delayed by j.
    let a0 = g.den[0];
    let den: Vec<f64> = g.den.iter().map(|a| a / a0).collect();
    let mut h = vec![0.0; len];
    structid_lti::filter_row(&[[1.0 / a0]], &den, &[[1.0]], &mut h);
    let phi = faer::Mat::from_fn(len, order, |k, j| if k >= j { h[k - j] } else { 0.0 });
    let r: Vec<f64> = (0..len).map(|k| y.get(k, 0) - sim[k]).collect();
    // The plain least-squares x₀ of validation: a non-finite or failed problem starts the
    // impulse numerator from the tiny default instead of failing the fit.
    let c = estimate_initial_state(phi.as_ref(), &r, None).unwrap_or_else(|_| vec![0.0; order]);
    Ok(tiny(c))
}

pub(super) fn one_channel(data: &Data, what: &str) -> Result<()> {
    if data.y().channels() != 1 {
        return Err(Error::DimensionMismatch {
            what: format!("{what}: measured outputs"),
            expected: "1".into(),
            found: data.y().channels().to_string(),
        });
    }
    Ok(())
}
