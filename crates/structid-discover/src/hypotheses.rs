//! Candidate places for a missing static effect in a nominal linear model.
//!
//! The nominal model is a polynomial G (one output): y = Σ_i B_i/F·u_i + e. Each
//! [`Location`] inserts one unknown static block N and gives the LFT of the augmented model:
//!
//! | location | model | z (measurable because) |
//! |---|---|---|
//! | [`Location::Input`] | y = G·N(u) + e | z = u |
//! | [`Location::Output`] | y = N(G·u) + e (a sensor map) | z = G·u depends on u only |
//! | [`Location::OutputFeedback`] | y = G·(u − N(y)) + e | z = y is measured |
//! | [`Location::RateFeedback`] | y = G·(u − N(ẏ)) + e, ẏ_k = (y_k − y_(k−1))/T_s | z = Ψ(q)·y with the LTI Ψ = (1 − q⁻¹)/T_s |
//!
//! For the rate, z is a *dynamic* function of the measured output (the paper's Definition 1
//! with an LTI Ψ_M): the LFT carries Ψ's state (the previous output), and the record gets z
//! computed from the measured y ([`Hypothesis::data`]) so that identification sees the
//! measured rate. Every location but the input needs one sample of delay in G (nk ≥ 1).

use std::sync::Arc;

use structid_core::refine::{
    InputNonlinearity, LinearStructure, OutputFeedback, output_sensor_lft, rate_feedback_lft,
};
use structid_core::{Data, Dispersion, Error, Model, NonlinearBlock, Result, Signal};
use structid_linear::PolynomialModel;

/// Where the unknown block is inserted.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub enum Location {
    /// An actuator map ahead of G: y = G·N(u) + e.
    Input,
    /// A sensor map of the linear output: y = N(G·u) + e.
    Output,
    /// Stiffness-like feedback from the output: y = G·(u − N(y)) + e.
    OutputFeedback,
    /// Friction-like feedback from the output's rate: y = G·(u − N(ẏ)) + e.
    RateFeedback,
}

impl Location {
    /// Every location, in the order of the table above.
    pub const ALL: [Location; 4] = [
        Location::Input,
        Location::Output,
        Location::OutputFeedback,
        Location::RateFeedback,
    ];

    /// A short description for reports.
    pub fn describe(self) -> &'static str {
        match self {
            Location::Input => "at the input: y = G·N(u) + e",
            Location::Output => "at the output (sensor): y = N(G·u) + e",
            Location::OutputFeedback => "in feedback from the output: y = G·(u − N(y)) + e",
            Location::RateFeedback => "in feedback from the output rate: y = G·(u − N(ẏ)) + e",
        }
    }
}

/// An augmented model: the nominal G with one unknown block at a location.
#[derive(Clone, Debug)]
pub struct Hypothesis {
    /// Where the block is.
    pub location: Location,
    /// The LFT and its block `N`.
    pub model: Model,
    /// The sample time used for rates (1 when G has none).
    pub sample_time: f64,
}

impl Hypothesis {
    /// The record as identification needs it: for the rate, with the measured z = Ψ(q)·y
    /// attached; otherwise unchanged.
    pub fn data(&self, data: &Data) -> Result<Data> {
        match self.location {
            Location::RateFeedback => {
                let y = data.y();
                let ts = self.sample_time;
                let z = Signal::from_fn(y.len(), 1, |k, _| {
                    let prev = if k > 0 { y.get(k - 1, 0) } else { 0.0 };
                    (y.get(k, 0) - prev) / ts
                });
                data.clone().with_z(z)
            }
            _ => Ok(data.clone()),
        }
    }
}

fn siso(g: &PolynomialModel) -> Result<()> {
    if g.num.len() != 1 {
        return Err(Error::InvalidStructure(format!(
            "hypotheses are built for a nominal model with one input; this one has {}",
            g.num.len()
        )));
    }
    Ok(())
}

fn delayed(g: &PolynomialModel, location: Location) -> Result<()> {
    if g.num[0].first().is_some_and(|b| *b != 0.0) {
        return Err(Error::InvalidStructure(format!(
            "a block {} needs G to have an input delay (nk ≥ 1); otherwise the loop is algebraic",
            location.describe()
        )));
    }
    Ok(())
}

/// Builds the hypothesis that a static block with `dispersion` sits at `location` of the
/// nominal single-input model `g`.
///
/// ```
/// use std::sync::Arc;
/// use structid_core::KernelDispersion;
/// use structid_discover::hypotheses::{Location, hypothesis};
/// use structid_linear::PolynomialModel;
/// let g = PolynomialModel { den: vec![1.0, -0.8], num: vec![vec![0.0, 0.5]], sample_time: Some(0.1) };
/// for loc in Location::ALL {
///     let h = hypothesis(&g, loc, Arc::new(KernelDispersion::gaussian(0.3).unwrap())).unwrap();
///     assert_eq!(h.model.blocks().len(), 1);
/// }
/// ```
pub fn hypothesis(
    g: &PolynomialModel,
    location: Location,
    dispersion: Arc<dyn Dispersion>,
) -> Result<Hypothesis> {
    siso(g)?;
    let ts = g.sample_time.unwrap_or(1.0);
    let block = || NonlinearBlock::new("N", vec![0], 0, Arc::clone(&dispersion));
    let lft = match location {
        Location::Input => InputNonlinearity::new("N").lft(g)?,
        Location::OutputFeedback => {
            delayed(g, location)?;
            let s = OutputFeedback::new("N");
            s.lft(&s.initial_from_bla(g)?)?
        }
        Location::Output => output_sensor_lft(g)?,
        Location::RateFeedback => {
            delayed(g, location)?;
            rate_feedback_lft(g)?
        }
    };
    Ok(Hypothesis {
        location,
        model: Model::new(lft, vec![block()])?,
        sample_time: ts,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand::rngs::StdRng;
    use rand_distr::{Distribution, Normal};
    use structid_core::{
        IdentifySettings, InitialState, MapBinding, PolynomialDispersion, identify,
    };

    fn nominal() -> PolynomialModel {
        PolynomialModel {
            den: vec![1.0, -1.2, 0.5],
            num: vec![vec![0.0, 0.3, 0.2]],
            sample_time: Some(0.1),
        }
    }

    /// Simulates the hypothesis with `truth` in the loop and identifies its map again: the
    /// estimate must match the truth, which checks the LFT against its own simulation and
    /// the measured z of the rate.
    fn round_trip(location: Location, truth: fn(f64) -> f64, amplitude: f64) -> f64 {
        let h = hypothesis(
            &nominal(),
            location,
            Arc::new(
                PolynomialDispersion::new(3)
                    .unwrap()
                    .with_scale(100.0)
                    .unwrap(),
            ),
        )
        .unwrap();
        let mut rng = StdRng::seed_from_u64(3);
        let n = Normal::new(0.0, 1.0).unwrap();
        let mut s = 0.0;
        let u = Signal::from_fn(1500, 1, |_, _| {
            s = 0.5 * s + amplitude * n.sample(&mut rng);
            s
        });
        let f = |z: &[f64]| truth(z[0]);
        let noise = Normal::new(0.0, 1e-3).unwrap();
        let e = Signal::from_fn(u.len(), 1, |_, _| noise.sample(&mut rng));
        let sim = h
            .model
            .lft()
            .simulate(
                &[MapBinding {
                    inputs: &[0],
                    output: 0,
                    map: &f,
                }],
                &u,
                Some(&e),
                None,
            )
            .unwrap();
        let data = h.data(&Data::new(u, sim.y.clone()).unwrap()).unwrap();
        // The measured z of the record is the z of the simulation.
        if let Some(z) = data.z() {
            let d: f64 = (0..z.len())
                .map(|k| (z.get(k, 0) - sim.z.get(k, 0)).abs())
                .fold(0.0, f64::max);
            assert!(
                d < 1e-9,
                "{location:?}: measured z differs from the LFT's by {d}"
            );
        }
        let id = identify(
            &h.model,
            &data,
            &IdentifySettings::builder()
                .beta(1e-9)
                .initial_state(InitialState::Zero)
                .build()
                .unwrap(),
        )
        .unwrap();
        let map = &id.blocks[0];
        let zs = map.z.channel(0);
        let (lo, hi) = zs
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| {
                (l.min(*v), h.max(*v))
            });
        let worst = (0..=20)
            .map(|i| lo + (hi - lo) * (0.1 + 0.8 * i as f64 / 20.0))
            .map(|z| (map.predict(&[z]) - truth(z)).abs())
            .fold(0.0, f64::max);
        let scale = (0..=20)
            .map(|i| truth(lo + (hi - lo) * i as f64 / 20.0).abs())
            .fold(0.0, f64::max);
        worst / scale
    }

    #[test]
    fn every_location_identifies_the_map_it_was_simulated_with() {
        let cubic: fn(f64) -> f64 = |z| 0.5 * z + 0.3 * z.powi(3);
        // Rate feedback: ẏ = Δy/T_s is ten times y, so a gentler friction keeps the loop stable.
        let friction: fn(f64) -> f64 = |z| 0.02 * z + 0.002 * z.powi(3);
        for (loc, truth, amp) in [
            (Location::Input, cubic, 1.0),
            (Location::Output, cubic, 1.0),
            (Location::OutputFeedback, cubic, 0.5),
            (Location::RateFeedback, friction, 0.3),
        ] {
            let err = round_trip(loc, truth, amp);
            assert!(err < 0.02, "{loc:?}: relative map error {err}");
        }
    }

    #[test]
    fn feedback_locations_need_a_delay_and_one_input() {
        let direct = PolynomialModel {
            den: vec![1.0, -0.5],
            num: vec![vec![1.0, 0.2]],
            sample_time: None,
        };
        let d: Arc<dyn Dispersion> = Arc::new(PolynomialDispersion::new(3).unwrap());
        for loc in [Location::OutputFeedback, Location::RateFeedback] {
            let e = hypothesis(&direct, loc, Arc::clone(&d))
                .unwrap_err()
                .to_string();
            assert!(e.contains("delay"), "{e}");
        }
        assert!(hypothesis(&direct, Location::Input, Arc::clone(&d)).is_ok());
        let two = PolynomialModel {
            den: vec![1.0, -0.5],
            num: vec![vec![0.0, 1.0], vec![0.0, 2.0]],
            sample_time: None,
        };
        assert!(hypothesis(&two, Location::Input, d).is_err());
    }
}
