//! The linear step of a sensor map, y = N̂(G·u) + e with N̂ fixed: output error through the
//! map.
//!
//! The map's input z = G·u moves with G, so its sample values ŵ cannot be held fixed as in
//! the other structures. With N̂ held as a function, the step minimises
//!
//! ```text
//!   V(θ) = (1/L)·Σ_k (y_k − N̂(z_k(θ)))²,   z = Σ_i B_i/F·u_i,
//! ```
//!
//! by Levenberg–Marquardt. The residual's Jacobian is −N̂′(z_k)·∂z_k/∂θ, where ∂z/∂b_(i,j) is
//! u_i filtered by q^(−(nk_i+j))/F and ∂z/∂f_j is −z filtered by q^(−j)/F (the output-error
//! sensitivities), and N̂′ a central difference of the map. Where the map is flat (a
//! saturated sensor) the samples carry no information about G, as they should. Data of
//! several records are simulated record by record from rest (or each from an initial state of
//! its own, an impulse input per record), and so are the sensitivities.

use nalgebra::{DMatrix, DVector};
use structid_linear::levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt, LmSettings};
use structid_linear::{OeFit, OeSettings, Orders, PolynomialModel};
use structid_lti::Signal;

use super::{integrators, linear_error};
use crate::error::{Error, Result};
use crate::model::Data;
use crate::model::interpolant::Interpolant;

struct Problem<'a> {
    u: Signal,
    y: Vec<f64>,
    /// Where each record starts, then the total length: each is simulated from rest.
    bounds: Vec<usize>,
    orders: Orders,
    sample_time: Option<f64>,
    map: &'a dyn Interpolant,
}

impl Problem<'_> {
    fn model(&self, theta: &[f64]) -> Option<PolynomialModel> {
        let m = PolynomialModel::from_parameters(&self.orders, theta, self.sample_time).ok()?;
        m.is_stable().then_some(m)
    }

    fn z(&self, m: &PolynomialModel) -> Option<Vec<f64>> {
        let mut z = Vec::with_capacity(self.y.len());
        for w in self.bounds.windows(2) {
            z.extend(m.simulate(&self.u.slice(w[0]..w[1])).ok()?);
        }
        z.iter().all(|v| v.is_finite()).then_some(z)
    }

    /// `x` filtered by 1/F, each record from rest.
    fn through_den(&self, den: &[f64], x: &[f64]) -> Vec<f64> {
        self.bounds
            .windows(2)
            .flat_map(|w| through_den(den, &x[w[0]..w[1]]))
            .collect()
    }

    /// The first sample of the record of every sample.
    fn record_starts(&self) -> Vec<usize> {
        self.bounds
            .windows(2)
            .flat_map(|w| std::iter::repeat_n(w[0], w[1] - w[0]))
            .collect()
    }
}

/// `x` filtered by 1/F.
fn through_den(den: &[f64], x: &[f64]) -> Vec<f64> {
    let mut out = vec![0.0; x.len()];
    for k in 0..x.len() {
        let mut v = x[k];
        for (j, a) in den.iter().enumerate().skip(1) {
            if k >= j {
                v -= a * out[k - j];
            }
        }
        out[k] = v / den[0];
    }
    out
}

impl LeastSquaresProblem for Problem<'_> {
    fn residuals(&mut self, theta: &[f64]) -> Option<DVector<f64>> {
        let m = self.model(theta)?;
        let z = self.z(&m)?;
        let r: Vec<f64> = z
            .iter()
            .zip(&self.y)
            .map(|(z, y)| y - self.map.eval(&[*z]))
            .collect();
        r.iter()
            .all(|v| v.is_finite())
            .then(|| DVector::from_vec(r))
    }

    fn jacobian(&mut self, theta: &[f64], _: &DVector<f64>) -> Option<DMatrix<f64>> {
        let m = self.model(theta)?;
        let z = self.z(&m)?;
        let len = z.len();
        let top = z.iter().fold(0.0f64, |a, v| a.max(v.abs()));
        let h = 1e-6 * top.max(1e-9);
        let slope: Vec<f64> = z
            .iter()
            .map(|&v| (self.map.eval(&[v + h]) - self.map.eval(&[v - h])) / (2.0 * h))
            .collect();
        let mut columns: Vec<(Vec<f64>, usize, f64)> = Vec::with_capacity(theta.len());
        for (i, (&nb, &nk)) in self.orders.nb.iter().zip(&self.orders.nk).enumerate() {
            let x = self.through_den(&m.den, &self.u.channel(i));
            for j in 0..nb {
                columns.push((x.clone(), nk + j, 1.0));
            }
        }
        let zf = self.through_den(&m.den, &z);
        for j in 1..=self.orders.na {
            columns.push((zf.clone(), j, -1.0));
        }
        let starts = self.record_starts();
        Some(DMatrix::from_fn(len, theta.len(), |k, p| {
            let (x, lag, sign) = &columns[p];
            let dz = if k >= starts[k] + *lag {
                sign * x[k - lag]
            } else {
                0.0
            };
            -slope[k] * dz
        }))
    }
}

/// The linear step of a sensor map; see the [module documentation](self).
pub(super) fn fit(
    data: &Data,
    map: &dyn Interpolant,
    g: &PolynomialModel,
    settings: &OeSettings,
    free_initial_state: bool,
    n_integrators: usize,
) -> Result<OeFit> {
    let u = data.u();
    let m = u.channels();
    if g.num.len() != m {
        return Err(Error::DimensionMismatch {
            what: "output (sensor) map: numerators of the linear part".into(),
            expected: m.to_string(),
            found: g.num.len().to_string(),
        });
    }
    if let Some(i) = g.num.iter().position(|b| b.iter().all(|&v| v == 0.0)) {
        return Err(Error::InvalidStructure(format!(
            "numerator {i} of the linear part is all zeros, so its delay is unknown and the \
             path would stay at zero; start it from small nonzero coefficients after the delay"
        )));
    }
    let order = super::state_order(g);
    let a0 = g.den[0];
    let mut start = PolynomialModel {
        num: g
            .num
            .iter()
            .map(|b| b.iter().map(|v| v / a0).collect())
            .collect(),
        den: g.den.iter().map(|v| v / a0).collect(),
        sample_time: g.sample_time,
    };
    let bounds = data.record_bounds().to_vec();
    let count = data.record_count();
    let mut columns = u.clone();
    let free = free_initial_state && order > 0;
    if free {
        // One impulse input per record, at its first sample.
        columns = Signal::from_fn(u.len(), m + count, |k, c| {
            if c < m {
                u.get(k, c)
            } else if k == bounds[c - m] {
                1.0
            } else {
                0.0
            }
        });
        // The free responses start at zero (a tiny value keeps every coefficient free: the
        // orders are read from the leading zeros).
        for _ in 0..count {
            start.num.push(vec![1e-12; order]);
        }
    }
    if n_integrators > 0 {
        start.den = integrators::deflate(&start.den, n_integrators)?;
        // Summed record by record from zero.
        let parts: Vec<Signal> = bounds
            .windows(2)
            .map(|w| integrators::sum(&columns.slice(w[0]..w[1]), n_integrators))
            .collect::<Result<_>>()?;
        let ch = columns.channels();
        columns = Signal::new(
            ch,
            parts.iter().flat_map(|p| p.as_slice().to_vec()).collect(),
        )?;
    }
    if !start.is_stable() {
        return Err(Error::InvalidStructure(format!(
            "the linear part's denominator (without the {n_integrators} integrator(s) held \
             fixed) is not stable, spectral radius {:.6}; a sensor map's linear step starts \
             from a stable G",
            start.spectral_radius()
        )));
    }
    let orders = start.orders();
    let theta0 = start.parameters();
    let mut problem = Problem {
        u: columns,
        y: data.y().channel(0),
        bounds,
        orders,
        sample_time: g.sample_time,
        map,
    };
    let lm = LmSettings::builder()
        .max_iterations(settings.max_iterations())
        .tolerance(settings.tolerance())
        .initial_damping(settings.initial_damping())
        .damping_increase(10.0)
        .damping_decrease(10.0)
        .min_damping(1e-15)
        .max_damping(1e20)
        .build()
        .map_err(linear_error)?;
    let fit = LevenbergMarquardt::new(lm)
        .minimize(&mut problem, &theta0)
        .map_err(linear_error)?;
    let mut model = PolynomialModel::from_parameters(&problem.orders, &fit.theta, g.sample_time)
        .map_err(linear_error)?;
    model.num.truncate(m);
    if n_integrators > 0 {
        model.den = integrators::inflate(&model.den, n_integrators);
    }
    // The fit is through the map (y ≈ N̂(G·u)), not G's own simulation: no linear fit
    // percentage or degeneracy warning applies, and no parameter uncertainty is computed.
    Ok(OeFit::from_lm(
        model,
        &fit,
        data.len().max(1),
        n_integrators,
    ))
}
