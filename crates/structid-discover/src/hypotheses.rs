//! Candidate places for a missing static effect in a nominal linear model.
//!
//! A [`Nominal`] model is an LFT without maps, y = G·u + H·e (one input, one output, any noise
//! path H), possibly with *declared* injection points and signals: w columns and z rows of its
//! LFT that the model file names, unused until a block is put there. Each [`Location`] inserts
//! one unknown static block N (the LFTs are built by [`Site::insert`]):
//!
//! | location | model | z (measurable because) |
//! |---|---|---|
//! | [`Location::Input`] | y = G·N(u) + H·e | z = u |
//! | [`Location::Output`] | y = N(G·u) + H·e (a sensor map) | z = G·u depends on u only |
//! | [`Location::OutputFeedback`] | y = G·(u − N(y)) + H·e | z = y is measured |
//! | [`Location::RateFeedback`] | y = G·(u − N(ẏ)) + H·e, ẏ_k = (y_k − y_(k−1))/T_s | z = Ψ(q)·y with the LTI Ψ = (1 − q⁻¹)/T_s |
//! | [`Location::Declared`] | the nominal LFT's declared w column and z row | checked by measurability |
//!
//! For the rate, z is a *dynamic* function of the measured output (the paper's Definition 1
//! with an LTI Ψ_M): the LFT carries Ψ's state (the previous output), and
//! [`Hypothesis::data`] attaches the measured z to the record. The feedback locations need one
//! sample of delay in G (D_yu = 0).

use std::sync::Arc;

use structid_core::structure::{realise, without_blocks};
use structid_core::{
    Data, Dispersion, Error, Interpolant, Lft, MapBinding, Model, Result, Signal, Simulation, Site,
    Structure,
};
use structid_linear::PolynomialModel;

/// Where the unknown block is inserted: structid-core's [`Site`], under the name this crate
/// has always used.
pub use structid_core::Site as Location;

/// A location the nominal model declares: the block reads z row `z` and writes w column `w`
/// of the nominal LFT.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize)]
pub struct DeclaredLocation {
    /// Its name, e.g. `spring`.
    pub name: String,
    /// The z row the block reads.
    pub z: usize,
    /// The w column the block writes.
    pub w: usize,
}

/// A state of the nominal model named for localisation (e.g. `position`).
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize)]
pub struct NamedState {
    /// The name.
    pub name: String,
    /// The state's index in the nominal LFT.
    pub state: usize,
}

/// A nominal model: an LFT without maps, with its declared locations and named states.
#[derive(Clone, Debug)]
pub struct Nominal {
    lft: Lft,
    declared: Vec<DeclaredLocation>,
    states: Vec<NamedState>,
    polynomial: Option<PolynomialModel>,
}

impl Nominal {
    /// A nominal model from an LFT with one input and one output. Its w columns and z rows,
    /// if any, are only used by locations declared with [`Nominal::with_location`].
    pub fn new(lft: Lft) -> Result<Self> {
        let d = lft.dims();
        if d.u != 1 || d.y != 1 {
            return Err(Error::InvalidStructure(format!(
                "discovery needs a nominal model with one input and one output; this one has {} \
                 input(s) and {} output(s)",
                d.u, d.y
            )));
        }
        if lft.matrices().dye.iter().all(|v| *v == 0.0) {
            return Err(Error::InvalidStructure(
                "the nominal model has no noise on y (D_ye = 0): identification and the \
                 residual tests need the output's noise path; give [lft] a Dye (e.g. \
                 Dye = [[1.0]] for white output noise)"
                    .into(),
            ));
        }
        Ok(Self {
            lft,
            declared: Vec::new(),
            states: Vec::new(),
            polynomial: None,
        })
    }

    /// The nominal model y = G·u + e of a polynomial G (white output noise).
    ///
    /// ```
    /// use structid_discover::hypotheses::{Location, Nominal};
    /// use structid_linear::PolynomialModel;
    /// let g = PolynomialModel { den: vec![1.0, -0.8], num: vec![vec![0.0, 0.5]], sample_time: Some(0.1) };
    /// let nominal = Nominal::from_polynomial(&g).unwrap();
    /// assert_eq!(nominal.locations(), Location::ALL.to_vec());
    /// ```
    pub fn from_polynomial(g: &PolynomialModel) -> Result<Self> {
        let mut n = Self::new(realise(g)?)?;
        n.polynomial = Some(g.clone());
        Ok(n)
    }

    /// G as a polynomial model when the nominal model was given as one
    /// ([`Nominal::from_polynomial`]): what a re-estimation of G starts from.
    pub fn polynomial(&self) -> Option<&PolynomialModel> {
        self.polynomial.as_ref()
    }

    /// The nominal model with a second noise source acting where u acts: y = G·(u + λ·v) + H·e
    /// with v white and independent of e (a force disturbance, in the units of u per unit of
    /// the output noise). For a plant with integrators this is the physical noise model:
    /// unmodelled forces make the position wander, and without it identification would have to
    /// explain that wander by the map. The new noise channel is appended after the existing ones.
    ///
    /// ```
    /// use structid_discover::hypotheses::Nominal;
    /// use structid_linear::PolynomialModel;
    /// let g = PolynomialModel { den: vec![1.0, -1.0], num: vec![vec![0.0, 0.1]], sample_time: Some(0.1) };
    /// let n = Nominal::from_polynomial(&g).unwrap().with_input_noise(50.0).unwrap();
    /// assert_eq!(n.lft().dims().e, 2);
    /// assert!(Nominal::from_polynomial(&g).unwrap().with_input_noise(-1.0).is_err());
    /// ```
    pub fn with_input_noise(mut self, ratio: f64) -> Result<Self> {
        if !(ratio.is_finite() && ratio > 0.0) {
            return Err(Error::InvalidParameter {
                name: "input noise ratio".into(),
                value: ratio,
                reason: "must be positive and finite".into(),
            });
        }
        let m = self.lft.matrices();
        let append = |a: &nalgebra::DMatrix<f64>, b: &nalgebra::DMatrix<f64>| {
            let mut out = nalgebra::DMatrix::zeros(a.nrows(), a.ncols() + 1);
            out.columns_mut(0, a.ncols()).copy_from(a);
            out.column_mut(a.ncols()).copy_from(&(b.column(0) * ratio));
            out
        };
        let mut next = m.clone();
        next.be = append(&m.be, &m.bu);
        next.dye = append(&m.dye, &m.dyu);
        next.dze = append(&m.dze, &m.dzu);
        let mut lft = Lft::new(next)?;
        if let Some(ts) = self.lft.sample_time() {
            lft = lft.with_sample_time(ts)?;
        }
        self.lft = lft;
        Ok(self)
    }

    /// Declares a location: a block reading z row `z` and writing w column `w` of the LFT.
    pub fn with_location(mut self, name: &str, z: usize, w: usize) -> Result<Self> {
        // Fails early when the channels do not exist.
        Site::Declared { z, w }.insert(&self.lft)?;
        self.declared.push(DeclaredLocation {
            name: name.to_string(),
            z,
            w,
        });
        Ok(self)
    }

    /// Names a state of the LFT for localisation.
    pub fn with_state(mut self, name: &str, state: usize) -> Result<Self> {
        if state >= self.lft.dims().states {
            return Err(Error::InvalidStructure(format!(
                "named state `{name}` is state {state}, but the nominal model has {} state(s)",
                self.lft.dims().states
            )));
        }
        self.states.push(NamedState {
            name: name.to_string(),
            state,
        });
        Ok(self)
    }

    /// The nominal LFT (with its declared channels).
    pub fn lft(&self) -> &Lft {
        &self.lft
    }

    /// The declared locations.
    pub fn declared(&self) -> &[DeclaredLocation] {
        &self.declared
    }

    /// The named states.
    pub fn states(&self) -> &[NamedState] {
        &self.states
    }

    /// The nominal model without any block (its declared channels dropped).
    pub fn model(&self) -> Result<Model> {
        Model::new(without_blocks(&self.lft)?, Vec::new())
    }

    /// Every candidate location: the four built-in ones, then the declared ones.
    pub fn locations(&self) -> Vec<Location> {
        Location::ALL
            .into_iter()
            .chain(
                self.declared
                    .iter()
                    .map(|d| Location::Declared { z: d.z, w: d.w }),
            )
            .collect()
    }

    /// The index of the declared location a [`Location::Declared`] reads and writes.
    fn declared_index(&self, location: Location) -> Option<usize> {
        match location {
            Location::Declared { z, w } => self.declared.iter().position(|d| d.z == z && d.w == w),
            _ => None,
        }
    }

    /// A short identifier of `location`: its [`Site::name`] for the built-in ones, `declared-i`
    /// for the i-th declared one (the names of `--locations` and the reports).
    pub fn key(&self, location: Location) -> String {
        match location {
            Location::Declared { z, w } => match self.declared_index(location) {
                Some(i) => format!("declared-{i}"),
                None => format!("declared-z{z}-w{w}"),
            },
            other => other.name().to_string(),
        }
    }

    /// A description of `location` for reports.
    pub fn describe(&self, location: Location) -> String {
        match location {
            Location::Declared { z, w } => match self.declared_index(location) {
                Some(i) => format!(
                    "at the declared location `{}` (z row {z}, w column {w})",
                    self.declared[i].name
                ),
                None => format!("at z row {z}, w column {w} (not declared)"),
            },
            other => other.describe().to_string(),
        }
    }

    /// The named states simulated from u (nominal model, zero initial state), by name.
    pub fn state_signals(&self, data: &Data) -> Result<Vec<(String, Vec<f64>)>> {
        if self.states.is_empty() {
            return Ok(Vec::new());
        }
        let n = self.lft.dims().states;
        let (_, x) = self.lft.t_yu().simulate_states(&vec![0.0; n], data.u())?;
        Ok(self
            .states
            .iter()
            .map(|s| (s.name.clone(), x.channel(s.state)))
            .collect())
    }

    /// Builds the hypothesis that a static block with `dispersion` sits at `location`.
    ///
    /// ```
    /// use std::sync::Arc;
    /// use structid_core::KernelDispersion;
    /// use structid_discover::hypotheses::Nominal;
    /// use structid_linear::PolynomialModel;
    /// let g = PolynomialModel { den: vec![1.0, -0.8], num: vec![vec![0.0, 0.5]], sample_time: Some(0.1) };
    /// let nominal = Nominal::from_polynomial(&g).unwrap();
    /// for loc in nominal.locations() {
    ///     let h = nominal.hypothesis(loc, Arc::new(KernelDispersion::gaussian(0.3).unwrap())).unwrap();
    ///     assert_eq!(h.model.blocks().len(), 1);
    /// }
    /// ```
    pub fn hypothesis(
        &self,
        location: Location,
        dispersion: Arc<dyn Dispersion>,
    ) -> Result<Hypothesis> {
        if let Location::Declared { z, w } = location
            && self.declared_index(location).is_none()
        {
            return Err(Error::InvalidStructure(format!(
                "z row {z} and w column {w} are not a declared location (the nominal model \
                 declares {})",
                self.declared.len()
            )));
        }
        Ok(Hypothesis {
            location,
            model: Structure::new(&self.lft, location, dispersion).model()?,
            sample_time: self.lft.sample_time().unwrap_or(1.0),
        })
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
    /// Simulates the augmented model with `map` in its block N from `u`, with the noise `e`
    /// (zero when `None`) and a zero initial state.
    ///
    /// ```
    /// use std::sync::Arc;
    /// use structid_core::{PolynomialDispersion, Signal};
    /// use structid_discover::hypotheses::{Location, hypothesis};
    /// use structid_linear::PolynomialModel;
    /// let g = PolynomialModel { den: vec![1.0, -0.5], num: vec![vec![0.0, 1.0]], sample_time: None };
    /// let h = hypothesis(&g, Location::Input, Arc::new(PolynomialDispersion::new(1).unwrap())).unwrap();
    /// let square = |z: &[f64]| z[0] * z[0];
    /// let sim = h.simulate(&square, &Signal::from_fn(3, 1, |_, _| 2.0), None).unwrap();
    /// assert_eq!(sim.y.channel(0), vec![0.0, 4.0, 6.0]); // y_k = 0.5·y_(k−1) + u²_(k−1)
    /// ```
    pub fn simulate(
        &self,
        map: &dyn Interpolant,
        u: &Signal,
        e: Option<&Signal>,
    ) -> Result<Simulation> {
        let f = |z: &[f64]| map.eval(z);
        self.model.lft().simulate(
            &[MapBinding {
                inputs: &[0],
                output: 0,
                map: &f,
            }],
            u,
            e,
            None,
        )
    }

    /// The record as identification needs it: for the rate, with the measured z = Ψ(q)·y
    /// attached (measurability would compute the same z, through the inverted noise path,
    /// except at the first sample, whose rate is taken as 0 here); otherwise unchanged.
    pub fn data(&self, data: &Data) -> Result<Data> {
        match self.location {
            Location::RateFeedback => {
                let y = data.y();
                let ts = self.sample_time;
                // The first sample has no predecessor in the record: its rate is taken as 0
                // rather than y₀/T_s (a record rarely starts at y = 0, and one spurious rate
                // of y₀/T_s would set the map's range and kernel width).
                let z = Signal::from_fn(y.len(), 1, |k, _| {
                    let prev = if k > 0 { y.get(k - 1, 0) } else { y.get(0, 0) };
                    (y.get(k, 0) - prev) / ts
                });
                data.clone().with_z(z)
            }
            _ => Ok(data.clone()),
        }
    }
}

/// Builds the hypothesis that a static block with `dispersion` sits at `location` of the
/// nominal single-input model `g` (shorthand for [`Nominal::from_polynomial`] then
/// [`Nominal::hypothesis`]).
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
    Nominal::from_polynomial(g)?.hypothesis(location, dispersion)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand::rngs::StdRng;
    use rand_distr::{Distribution, Normal};
    use structid_core::{IdentifySettings, InitialState, PolynomialDispersion, identify};

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
        let sim = h.simulate(&f, &u, Some(&e)).unwrap();
        let data = h.data(&Data::new(u, sim.y.clone()).unwrap()).unwrap();
        // The measured z of the record is the z of the simulation (after the first sample,
        // whose rate the record sets to 0 and the LFT, starting from m = 0, to y₀/T_s).
        if let Some(z) = data.z() {
            let d: f64 = (1..z.len())
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
