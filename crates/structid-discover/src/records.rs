//! Several records (experiments) in discovery: every step runs on each record on its own and
//! pools what it found, so that no simulation, filter, difference or lag pairs samples across
//! a record boundary.
//!
//! [`Data`] stacks its records one after the other ([`Data::record_bounds`]). The helpers here
//! apply a one-record computation record by record: [`restack`] for a computation that returns
//! a record, [`stacked`] for one that returns a signal, [`parts`] to cut a stacked signal
//! back into its records, and [`simulate`] for the simulation with the maps in the loop that
//! scores every model of the workflow, pooled over the records' scored samples. With one
//! record each is the one-record computation itself.

use std::ops::Range;

use structid_core::validation::records::pool_record;
use structid_core::validation::windows::simulate_scored;
use structid_core::validation::{ValidationSettings, validate_records};
use structid_core::{Data, Error, Interpolant, Model, Result};

/// `data`'s records, each passed through `f`, stacked again into one [`Data`] with the same
/// record bounds (`f` itself for one record).
pub fn restack(data: &Data, f: impl Fn(&Data) -> Result<Data>) -> Result<Data> {
    if data.record_count() == 1 {
        return f(data);
    }
    Data::from_records(data.records().iter().map(f).collect::<Result<Vec<_>>>()?)
}

/// `f` of each record of `data`, the outputs stacked one after the other (`f` itself for one
/// record). Each output must have its record's length.
pub fn stacked(data: &Data, f: impl Fn(&Data) -> Result<Vec<f64>>) -> Result<Vec<f64>> {
    if data.record_count() == 1 {
        return f(data);
    }
    let mut out = Vec::with_capacity(data.len());
    for (i, r) in data.records().iter().enumerate() {
        let part = f(r)?;
        if part.len() != r.len() {
            return Err(Error::DimensionMismatch {
                what: format!("samples computed for record {}", i + 1),
                expected: r.len().to_string(),
                found: part.len().to_string(),
            });
        }
        out.extend(part);
    }
    Ok(out)
}

/// The length of the shortest record of `data` (every step that sizes lags or windows sizes
/// them for it).
pub fn shortest(data: &Data) -> usize {
    data.record_bounds()
        .windows(2)
        .map(|w| w[1] - w[0])
        .min()
        .unwrap_or(data.len())
}

/// `signal` (stacked like `data`'s records) cut into its records.
pub fn parts<'a, T>(signal: &'a [T], bounds: &[usize]) -> Vec<&'a [T]> {
    bounds
        .windows(2)
        .map(|w| &signal[w[0].min(signal.len())..w[1].min(signal.len())])
        .collect()
}

/// The simulation of a model with its maps in the loop on every record of a [`Data`], each
/// record scored as [`validate`](structid_core::validation::validate) scores it (its own initial state, its own windows), pooled.
#[derive(Clone, Debug)]
pub struct Simulated {
    /// The simulated output (first output), records stacked.
    pub simulated: Vec<f64>,
    /// The measured output (first output), records stacked.
    pub measured: Vec<f64>,
    /// The scored samples of every record, as indices into the stacked records.
    pub scored: Vec<Range<usize>>,
    /// The simulation RMS over every scored sample of every record.
    pub rms: f64,
    /// The fit in percent over every scored sample (about the mean of those samples).
    pub fit_percent: f64,
    /// Each record's simulation RMS and number of scored samples.
    pub records: Vec<(f64, usize)>,
}

impl Simulated {
    /// Nothing simulated yet of `data`: its measured output, no scored sample.
    fn of(data: &Data) -> Self {
        Self {
            simulated: Vec::with_capacity(data.len()),
            measured: data.y().channel(0),
            scored: Vec::new(),
            rms: f64::NAN,
            fit_percent: f64::NAN,
            records: Vec::new(),
        }
    }

    /// The residual y − ŷ at the scored samples, record after record.
    pub fn scored_residual(&self) -> Vec<f64> {
        self.scored
            .iter()
            .flat_map(|r| r.clone())
            .map(|k| self.measured[k] - self.simulated[k])
            .collect()
    }

    /// The residual y − ŷ at the scored samples, one vector per record.
    pub fn scored_residual_parts(&self, bounds: &[usize]) -> Vec<Vec<f64>> {
        bounds
            .windows(2)
            .map(|w| {
                self.scored
                    .iter()
                    .flat_map(|r| r.start.max(w[0])..r.end.min(w[1]))
                    .map(|k| self.measured[k] - self.simulated[k])
                    .collect()
            })
            .collect()
    }
}

/// Simulates `model` with `maps` on every record of `data` ([`validate`](structid_core::validation::validate) record by record,
/// with `settings`) and pools the simulation RMS and fit over the records' scored samples.
///
/// A model beyond measurability (maps in series, a map of a latent signal) has no one-step
/// predictor, which [`validate`](structid_core::validation::validate) fits the initial state with; it is scored by
/// [`simulate_scored`] alone instead: under free-run scoring simulated from rest, as the
/// sensor site always is; under windowed scoring each window from its own state, fitted to z
/// as [`Model::compute_z_with_maps`] gives it (the noise-free simulation's for an
/// output-error model) or, where the record gives no z, to y through the simulation.
pub fn simulate(
    model: &Model,
    maps: &[&dyn Interpolant],
    data: &Data,
    settings: &ValidationSettings,
) -> Result<Simulated> {
    let bounds = data.record_bounds();
    let mut out = Simulated::of(data);
    let all = match validate_records(model, maps, data, settings) {
        Err(e) if e.beyond_measurability() => {
            return without_prediction(model, maps, data, settings);
        }
        other => other.map_err(|e| match e {
            Error::InRecord { record, source } => in_record(*source, record - 1, data),
            other => other,
        })?,
    };
    for (v, start) in all.records.iter().zip(bounds) {
        let count = v.scored.iter().map(|s| s.len()).sum::<usize>();
        out.scored
            .extend(v.scored.iter().map(|s| s.start + start..s.end + start));
        out.records.push((v.rms[0], count));
        out.simulated.extend(v.simulated.channel(0));
    }
    // One record keeps its validation's own figures; several are pooled over their scored
    // samples.
    (out.rms, out.fit_percent) = match all.records.as_slice() {
        [one] => (one.rms[0], one.fit_percent[0]),
        _ => (all.pooled[0].rms(), all.pooled[0].fit_percent()),
    };
    Ok(out)
}

/// [`simulate`] by [`simulate_scored`] on each record with the scoring and settling samples
/// of `settings`: a free run from rest, or windows.
fn without_prediction(
    model: &Model,
    maps: &[&dyn Interpolant],
    data: &Data,
    settings: &ValidationSettings,
) -> Result<Simulated> {
    let (scoring, settle) = (settings.scoring(), settings.settle());
    let mut out = Simulated::of(data);
    let mut pooled = Vec::new();
    for (r, (record, start)) in data.records().iter().zip(data.record_bounds()).enumerate() {
        let sim = simulate_scored(model, maps, record, scoring, None, settle)
            .map_err(|e| in_record(e, r, data))?;
        pool_record(&mut pooled, record.y(), &sim.simulated, &sim.scored);
        let count = sim.scored.iter().map(|s| s.len()).sum::<usize>();
        out.records.push((sim.rms(record.y(), 0), count));
        out.scored
            .extend(sim.scored.iter().map(|s| s.start + start..s.end + start));
        out.simulated.extend(sim.simulated.channel(0));
    }
    let fit = &pooled[0];
    (out.rms, out.fit_percent) = (fit.rms(), fit.fit_percent());
    Ok(out)
}

/// An error of record `r` (0-based) of `data`, naming the record when there are several.
pub fn in_record(e: Error, r: usize, data: &Data) -> Error {
    if data.record_count() == 1 {
        return e;
    }
    match e {
        Error::InvalidParameter {
            name,
            value,
            reason,
        } => Error::InvalidParameter {
            name: format!("{name} (record {} of {})", r + 1, data.record_count()),
            value,
            reason,
        },
        Error::InvalidStructure(s) => {
            Error::InvalidStructure(format!("record {} of {}: {s}", r + 1, data.record_count()))
        }
        Error::Numerical(s) => {
            Error::Numerical(format!("record {} of {}: {s}", r + 1, data.record_count()))
        }
        other => other,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use structid_core::Signal;
    use structid_core::validation::Scoring;
    use structid_core::validation::Windows;

    /// y = N₂(G·N₁(u)) + e with an integrating G with a direct term (maps in series), the
    /// noise reaching the state: the record gives no z.
    fn series_model() -> Model {
        structid_core::scenarios::actuator_sensor_series([-1.8, 0.8], [0.01, 0.015, 0.005]).unwrap()
    }

    /// A model beyond measurability is scored in windows on every record, each record and
    /// window from its own state: the exact model at round-off, where a free run from rest
    /// misses each record's integrated initial state.
    #[test]
    fn a_model_beyond_measurability_is_scored_in_windows() {
        let model = series_model();
        let act = |z: &[f64]| (1.5 * z[0]).tanh();
        let sen = |z: &[f64]| z[0] + 0.1 * z[0].powi(3);
        let maps: [&dyn Interpolant; 2] = [&act, &sen];
        let record = |len: usize, x0: [f64; 2], f: f64| {
            let u = Signal::from_fn(len, 1, |k, _| {
                (f * k as f64).sin() + 0.4 * (0.37 * k as f64).cos()
            });
            let y = model.simulate(&maps, &u, None, Some(&x0)).unwrap().y;
            Data::new(u, y).unwrap()
        };
        let data = Data::from_records(vec![
            record(1200, [3.0, 2.9], 0.05),
            record(900, [-2.0, -2.0], 0.03),
        ])
        .unwrap();
        let windowed = ValidationSettings::builder()
            .scoring(Scoring::Windowed(Windows::new(150, 20).unwrap()))
            .build()
            .unwrap();
        assert!(
            validate_records(&model, &maps, &data, &windowed)
                .unwrap_err()
                .beyond_measurability()
        );
        let win = simulate(&model, &maps, &data, &windowed).unwrap();
        let scale = structid_core::validation::metrics::rms(&win.measured);
        assert!(win.rms < 1e-8 * scale, "{} of {scale}", win.rms);
        assert_eq!(win.simulated.len(), 2100);
        // 8 + 6 windows, each scored after its first 20 samples.
        assert_eq!(win.scored.len(), 14);
        assert_eq!(
            win.records.iter().map(|r| r.1).sum::<usize>(),
            2100 - 14 * 20
        );
        let free = ValidationSettings::builder()
            .scoring(Scoring::Free)
            .build()
            .unwrap();
        let from_rest = simulate(&model, &maps, &data, &free).unwrap();
        assert!(from_rest.rms > 0.1, "{}", from_rest.rms);
    }

    fn rec(len: usize, offset: f64) -> Data {
        let u = Signal::from_fn(len, 1, |k, _| offset + k as f64);
        Data::new(u.clone(), u).unwrap()
    }

    #[test]
    fn restack_and_stacked_run_each_record_alone() {
        let data = Data::from_records(vec![rec(5, 0.0), rec(3, 100.0)]).unwrap();
        // The first difference of each record, 0 at its start: no difference across the seam.
        let diff = |d: &Data| -> Result<Vec<f64>> {
            let u = d.u().channel(0);
            Ok((0..u.len())
                .map(|k| if k == 0 { 0.0 } else { u[k] - u[k - 1] })
                .collect())
        };
        assert_eq!(
            stacked(&data, diff).unwrap(),
            vec![0.0, 1.0, 1.0, 1.0, 1.0, 0.0, 1.0, 1.0]
        );
        let again = restack(&data, |d| Ok(d.clone())).unwrap();
        assert_eq!(again, data);
        let cut = parts(data.u().as_slice(), data.record_bounds());
        assert_eq!(cut[1], &[100.0, 101.0, 102.0]);
    }
}
