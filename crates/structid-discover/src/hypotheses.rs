//! Candidate places for a missing static effect in a nominal linear model.
//!
//! A [`Nominal`] model is an LFT without maps, y = G·u + H·e (one input, one output, any noise
//! path H), possibly with *declared* injection points and signals: w columns and z rows of its
//! LFT that the model file names, unused until a block is put there. Each [`Site`] inserts
//! one unknown static block N (the LFTs are built by [`Site::insert`]):
//!
//! | location | model | z (measurable because) |
//! |---|---|---|
//! | [`Site::Input`] | y = G·N(u) + H·e | z = u |
//! | [`Site::Output`] | y = N(G·u) + H·e (a sensor map) | z = G·u depends on u only |
//! | [`Site::OutputFeedback`] | y = G·(u − N(y)) + H·e | z = y is measured |
//! | [`Site::RateFeedback`] | y = G·(u − N(ẏ)) + H·e, ẏ_k = (y_k − y_(k−1))/T_s | z = Ψ(q)·y with the LTI Ψ = (1 − q⁻¹)/T_s |
//! | [`Site::Declared`] | the nominal LFT's declared w column and z row | checked by measurability |
//!
//! For the rate, z is a *dynamic* function of the measured output (the paper's Definition 1
//! with an LTI Ψ_M): the LFT carries Ψ's state (the previous output), and
//! [`Hypothesis::data`] attaches the measured z to the record. The feedback locations need one
//! sample of delay in G (D_yu = 0).
//!
//! **A nominal model with maps.** A nominal model may already carry static maps, e.g. the
//! augmented model of an earlier discovery ([`Nominal::with_known_map`],
//! [`Nominal::from_model`]): they stay fixed while the next block is identified. The new block
//! is then put *around* the whole nominal model, its maps kept inside (the input location
//! drives the nominal model, maps included, through N(u); feedback locations subtract N(y) or
//! N(ẏ) from its input; the output location maps its noise-free output), see
//! [`crate::known`]. Every simulation of a [`Hypothesis`] binds its known maps
//! ([`Hypothesis::maps`]); identification sees them as known inputs, w_k = N_k(z_k) at the
//! record's z ([`Hypothesis::identification`]).

use std::sync::Arc;

use structid_core::model::structure::{realise, without_blocks};
use structid_core::{
    Data, Dispersion, Error, Interpolant, Lft, MapBinding, Model, NonlinearBlock,
    PolynomialDispersion, Result, Signal, Simulation, Structure,
};
use structid_linear::PolynomialModel;
use structid_lti::LinearSystem as _;

/// Where the unknown block is inserted: structid-core's [`Site`],
/// re-exported beside the hypotheses built on it.
pub use structid_core::Site;

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

/// A static map that a nominal model already carries: fixed while the next block is
/// identified.
#[derive(Clone)]
pub struct KnownMap {
    /// The block's name (unique in the model).
    pub name: String,
    /// The map.
    pub map: Arc<dyn Interpolant>,
    /// The named family it is, when it was found by discovery in this process: its parameters
    /// are refitted jointly with the next effect's (a map found first carries the bias of the
    /// effects not yet modelled).
    pub fit: Option<crate::effects::EffectFit>,
}

impl std::fmt::Debug for KnownMap {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("KnownMap")
            .field("name", &self.name)
            .finish_non_exhaustive()
    }
}

/// A known map of a nominal model with the channels of its LFT it reads and writes.
#[derive(Clone, Debug)]
struct KnownBlock {
    known: KnownMap,
    z: usize,
    w: usize,
}

/// A nominal model: an LFT, with its declared locations, named states and the known maps it
/// already carries (none for a linear nominal model).
#[derive(Clone, Debug)]
pub struct Nominal {
    lft: Lft,
    declared: Vec<DeclaredLocation>,
    states: Vec<NamedState>,
    polynomial: Option<PolynomialModel>,
    known: Vec<KnownBlock>,
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
            known: Vec::new(),
        })
    }

    /// A nominal model that already carries maps: `model`'s LFT with every block's map fixed to
    /// `maps` (one per block, in block order, each reading one z channel). The next block is
    /// found around it, with these maps in the loop (see the [module documentation](self)).
    ///
    /// ```
    /// use std::sync::Arc;
    /// use structid_core::{Interpolant, PolynomialDispersion};
    /// use structid_discover::hypotheses::{Site, Nominal, hypothesis};
    /// use structid_linear::PolynomialModel;
    /// let g = PolynomialModel { den: vec![1.0, -0.8], num: vec![vec![0.0, 0.5]], sample_time: Some(0.1) };
    /// // The augmented model of a first discovery: a saturation at the input.
    /// let first = hypothesis(&g, Site::Input, Arc::new(PolynomialDispersion::new(1).unwrap())).unwrap();
    /// let sat: Arc<dyn Interpolant> = Arc::new(|z: &[f64]| z[0].clamp(-1.0, 1.0));
    /// let nominal = Nominal::from_model(&first.model, vec![sat]).unwrap();
    /// assert_eq!(nominal.known_maps().len(), 1);
    /// // A cubic spring in feedback from y, with the saturation kept in the loop.
    /// let h = nominal.hypothesis(Site::OutputFeedback, Arc::new(PolynomialDispersion::new(3).unwrap())).unwrap();
    /// assert_eq!(h.model.blocks().len(), 2);
    /// ```
    ///
    /// # Errors
    /// As [`Nominal::new`]; a number of maps other than the number of blocks; a block reading
    /// several z channels.
    pub fn from_model(model: &Model, maps: Vec<Arc<dyn Interpolant>>) -> Result<Self> {
        if maps.len() != model.blocks().len() {
            return Err(Error::DimensionMismatch {
                what: "known maps of the nominal model (one per block)".into(),
                expected: model.blocks().len().to_string(),
                found: maps.len().to_string(),
            });
        }
        let mut n = Self::new(model.lft().clone())?;
        for (b, map) in model.blocks().iter().zip(maps) {
            let [z] = b.inputs[..] else {
                return Err(Error::InvalidStructure(format!(
                    "block `{}` reads {} z channels; a known map of a nominal model reads one",
                    b.name,
                    b.inputs.len()
                )));
            };
            n = n.with_known_map(&b.name, z, b.output, map)?;
        }
        Ok(n)
    }

    /// Declares that w column `w` of the LFT is the output of the fixed map `map` of its z row
    /// `z` (a block called `name`).
    ///
    /// # Errors
    /// A channel that does not exist, a channel already used by another known map, a name
    /// already used.
    pub fn with_known_map(
        self,
        name: &str,
        z: usize,
        w: usize,
        map: Arc<dyn Interpolant>,
    ) -> Result<Self> {
        self.with_known(
            z,
            w,
            KnownMap {
                name: name.to_string(),
                map,
                fit: None,
            },
        )
    }

    /// [`Nominal::with_known_map`] with the map as a [`KnownMap`] (which may carry its named
    /// family).
    pub fn with_known(mut self, z: usize, w: usize, known: KnownMap) -> Result<Self> {
        let name = known.name.as_str();
        let d = self.lft.dims();
        if z >= d.z || w >= d.w {
            return Err(Error::InvalidStructure(format!(
                "known map `{name}` reads z row {z} and writes w column {w}, but the nominal \
                 model has {} z row(s) and {} w column(s)",
                d.z, d.w
            )));
        }
        if let Some(other) = self.known.iter().find(|k| k.w == w || k.known.name == name) {
            return Err(Error::InvalidStructure(format!(
                "known map `{name}` (w column {w}) clashes with `{}` (w column {})",
                other.known.name, other.w
            )));
        }
        self.known.push(KnownBlock { known, z, w });
        // Maps in series are simulated in order (and fitted by simulation error); a cycle of
        // maps has no order and fails here, early.
        self.model()?.evaluation_order()?;
        Ok(self)
    }

    /// The nominal model with the known maps' named families set to `fits` (one per known
    /// map, in their order; `None` leaves a map as it is).
    pub fn with_known_fits(mut self, fits: Vec<Option<crate::effects::EffectFit>>) -> Self {
        for (k, fit) in self.known.iter_mut().zip(fits) {
            if fit.is_some() {
                k.known.fit = fit;
            }
        }
        self
    }

    /// The known maps, in the order of their blocks.
    pub fn known_maps(&self) -> Vec<KnownMap> {
        self.known.iter().map(|k| k.known.clone()).collect()
    }

    /// The nominal LFT with only the known maps' channels, in their order.
    fn known_lft(&self) -> Result<Lft> {
        let z: Vec<usize> = self.known.iter().map(|k| k.z).collect();
        let w: Vec<usize> = self.known.iter().map(|k| k.w).collect();
        crate::known::select_channels(&self.lft, &z, &w)
    }

    /// A name for the next block, unused by the known maps: `N`, else `N2`, `N3`, ….
    pub fn next_block_name(&self) -> String {
        let used = |n: &str| self.known.iter().any(|k| k.known.name == n);
        if !used("N") {
            return "N".into();
        }
        (2..)
            .map(|i| format!("N{i}"))
            .find(|n| !used(n))
            .unwrap_or_else(|| "N".into())
    }

    /// The nominal model y = G·u + e of a polynomial G (white output noise).
    ///
    /// ```
    /// use structid_discover::hypotheses::{Site, Nominal};
    /// use structid_linear::PolynomialModel;
    /// let g = PolynomialModel { den: vec![1.0, -0.8], num: vec![vec![0.0, 0.5]], sample_time: Some(0.1) };
    /// let nominal = Nominal::from_polynomial(&g).unwrap();
    /// assert_eq!(nominal.locations(), Site::ALL.to_vec());
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

    /// The nominal model: without any block for a linear nominal model (its declared channels
    /// dropped), else with its known blocks (simulate it with [`Nominal::maps`]; their
    /// dispersions are placeholders).
    pub fn model(&self) -> Result<Model> {
        if self.known.is_empty() {
            return Model::new(without_blocks(&self.lft)?, Vec::new());
        }
        let placeholder: Arc<dyn Dispersion> = Arc::new(PolynomialDispersion::new(1)?);
        let blocks = self
            .known
            .iter()
            .enumerate()
            .map(|(i, k)| NonlinearBlock::new(&k.known.name, vec![i], i, Arc::clone(&placeholder)))
            .collect();
        Model::new(self.known_lft()?, blocks)
    }

    /// The known maps as [`Nominal::model`]'s blocks take them (empty for a linear nominal).
    pub fn maps(&self) -> Vec<&dyn Interpolant> {
        self.known
            .iter()
            .map(|k| k.known.map.as_ref() as &dyn Interpolant)
            .collect()
    }

    /// The output of the nominal model simulated from u at rest, without noise (G·u for a
    /// linear nominal model).
    pub fn simulate_output(&self, u: &Signal) -> Result<Vec<f64>> {
        if self.known.is_empty() {
            return Ok(without_blocks(&self.lft)?.t_yu().simulate(u)?.channel(0));
        }
        Ok(self
            .model()?
            .simulate(&self.maps(), u, None, None)?
            .y
            .channel(0))
    }

    /// Every candidate location: the four built-in ones, then the declared ones.
    pub fn locations(&self) -> Vec<Site> {
        Site::ALL
            .into_iter()
            .chain(
                self.declared
                    .iter()
                    .map(|d| Site::Declared { z: d.z, w: d.w }),
            )
            .collect()
    }

    /// The index of the declared location a [`Site::Declared`] reads and writes.
    fn declared_index(&self, location: Site) -> Option<usize> {
        match location {
            Site::Declared { z, w } => self.declared.iter().position(|d| d.z == z && d.w == w),
            _ => None,
        }
    }

    /// A short identifier of `location`: its [`Site::name`] for the built-in ones, `declared-i`
    /// for the i-th declared one (the names of `--locations` and the reports).
    pub fn key(&self, location: Site) -> String {
        match location {
            Site::Declared { z, w } => match self.declared_index(location) {
                Some(i) => format!("declared-{i}"),
                None => format!("declared-z{z}-w{w}"),
            },
            other => other.name().to_string(),
        }
    }

    /// A description of `location` for reports.
    pub fn describe(&self, location: Site) -> String {
        match location {
            Site::Declared { z, w } => match self.declared_index(location) {
                Some(i) => format!(
                    "at the declared location `{}` (z row {z}, w column {w})",
                    self.declared[i].name
                ),
                None => format!("at z row {z}, w column {w} (not declared)"),
            },
            other => other.describe().to_string(),
        }
    }

    /// The named states simulated from u (nominal model with its known maps, zero initial
    /// state, no noise), by name.
    /// With several records, each record's states start at zero.
    pub fn state_signals(&self, data: &Data) -> Result<Vec<(String, Vec<f64>)>> {
        if self.states.is_empty() {
            return Ok(Vec::new());
        }
        if data.record_count() > 1 {
            let mut out: Vec<(String, Vec<f64>)> = Vec::new();
            for record in data.records() {
                let part = self.state_signals(&record)?;
                if out.is_empty() {
                    out = part;
                } else {
                    for (o, (_, p)) in out.iter_mut().zip(part) {
                        o.1.extend(p);
                    }
                }
            }
            return Ok(out);
        }
        let n = self.lft.dims().states;
        if !self.known.is_empty() {
            // The maps' outputs of the noise-free simulation drive the states with u:
            // x⁺ = A·x + B_u·u + B_w·w.
            let model = self.model()?;
            let w = model.simulate(&self.maps(), data.u(), None, None)?.w;
            let m = model.lft().matrices();
            let mut x = nalgebra::DVector::zeros(n);
            let mut out: Vec<Vec<f64>> = vec![Vec::with_capacity(data.len()); self.states.len()];
            for k in 0..data.len() {
                for (o, s) in out.iter_mut().zip(&self.states) {
                    o.push(x[s.state]);
                }
                let u = nalgebra::DVector::from_column_slice(data.u().sample(k));
                let wk = nalgebra::DVector::from_column_slice(w.sample(k));
                x = &m.a * &x + &m.bu * u + &m.bw * wk;
            }
            return Ok(self
                .states
                .iter()
                .map(|s| s.name.clone())
                .zip(out)
                .collect());
        }
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
        location: Site,
        dispersion: Arc<dyn Dispersion>,
    ) -> Result<Hypothesis> {
        if let Site::Declared { z, w } = location
            && self.declared_index(location).is_none()
        {
            return Err(Error::InvalidStructure(format!(
                "z row {z} and w column {w} are not a declared location (the nominal model \
                 declares {})",
                self.declared.len()
            )));
        }
        if self.known.is_empty() {
            return Ok(Hypothesis {
                location,
                model: Structure::new(&self.lft, location, dispersion).model()?,
                sample_time: self.lft.sample_time().unwrap_or(1.0),
                known: Vec::new(),
            });
        }
        let lft = match location {
            Site::Declared { z, w } => {
                let zs: Vec<usize> = std::iter::once(z)
                    .chain(self.known.iter().map(|k| k.z))
                    .collect();
                let ws: Vec<usize> = std::iter::once(w)
                    .chain(self.known.iter().map(|k| k.w))
                    .collect();
                crate::known::select_channels(&self.lft, &zs, &ws)?
            }
            site => crate::known::wrap(&self.known_lft()?, site)?,
        };
        let mut blocks = vec![NonlinearBlock::new(
            self.next_block_name(),
            vec![0],
            0,
            dispersion,
        )];
        let placeholder: Arc<dyn Dispersion> = Arc::new(PolynomialDispersion::new(1)?);
        blocks.extend(self.known.iter().enumerate().map(|(i, k)| {
            NonlinearBlock::new(&k.known.name, vec![i + 1], i + 1, Arc::clone(&placeholder))
        }));
        let model = Model::new(lft, blocks)?;
        // Maps in series are evaluated in order; a cycle of maps has no order.
        model.evaluation_order()?;
        Ok(Hypothesis {
            location,
            model,
            sample_time: self.lft.sample_time().unwrap_or(1.0),
            known: self.known_maps(),
        })
    }
}

/// An augmented model: the nominal model with one unknown block at a location.
#[derive(Clone, Debug)]
pub struct Hypothesis {
    /// Where the block is.
    pub location: Site,
    /// The LFT and its blocks: the unknown one first (z row 0, w column 0), then the nominal
    /// model's known maps.
    pub model: Model,
    /// The sample time used for rates (1 when G has none).
    pub sample_time: f64,
    /// The nominal model's known maps: blocks `1..` of `model` (empty for a linear nominal).
    pub known: Vec<KnownMap>,
}

impl Hypothesis {
    /// The maps of every block of [`Hypothesis::model`]: `map` in the unknown block, then the
    /// known maps (what every simulation of the hypothesis binds).
    pub fn maps<'a>(&'a self, map: &'a dyn Interpolant) -> Vec<&'a dyn Interpolant> {
        std::iter::once(map)
            .chain(
                self.known
                    .iter()
                    .map(|k| k.map.as_ref() as &dyn Interpolant),
            )
            .collect()
    }

    /// The hypothesis with the unknown block's dispersion replaced.
    pub fn with_dispersion(&self, dispersion: Arc<dyn Dispersion>) -> Self {
        let mut first = Some(dispersion);
        Hypothesis {
            model: self.model.with_dispersions(|b| match first.take() {
                Some(d) => d,
                None => Arc::clone(&b.dispersion),
            }),
            ..self.clone()
        }
    }

    /// The LFT from the unknown block's output to y with the known maps' outputs as inputs
    /// after u ([`crate::known`]): the linear path identification and deconvolution see.
    /// [`Hypothesis::model`]'s LFT itself without known maps.
    pub fn block_lft(&self) -> Result<Lft> {
        if self.known.is_empty() {
            return Ok(self.model.lft().clone());
        }
        crate::known::with_known_inputs(self.model.lft())
    }

    /// The model and record that identify the unknown block: without known maps, the
    /// hypothesis' model and [`Hypothesis::data`]; with them, the LFT of
    /// [`Hypothesis::block_lft`] and the record with the inputs u' = [u; N_1(z_1); …], each
    /// known map at its z computed from the record (measured, or through the inverted noise
    /// path). That is exact for identification's one-step criterion; `data` is the record as
    /// given (not yet passed through [`Hypothesis::data`]).
    ///
    /// With several records, each record's z and known maps' outputs are computed from that
    /// record alone.
    pub fn identification(&self, data: &Data) -> Result<(Model, Data)> {
        let full = self.data(data)?;
        if self.known.is_empty() {
            return Ok((self.model.clone(), full));
        }
        if data.record_count() > 1 {
            let model = self.identification(&data.records()[0])?.0;
            let id_data = crate::records::restack(data, |r| Ok(self.identification(r)?.1))?;
            return Ok((model, id_data));
        }
        let z = match full.z() {
            Some(z) => z.clone(),
            None => match self.model.lft().compute_z(data.u(), data.y()) {
                Ok((z, _)) => z,
                // The unknown block's own z may need the known maps' outputs (a sensor map
                // behind a known actuator map): only the known maps' z must come from the
                // record.
                Err(e) => self.known_z(data).map_err(|_| e)?,
            },
        };
        let len = data.len();
        let mut columns = vec![data.u().channel(0)];
        for (i, k) in self.known.iter().enumerate() {
            let zi = z.channel(i + 1);
            let w: Vec<f64> = zi.iter().map(|v| k.map.eval(&[*v])).collect();
            if let Some(at) = w.iter().position(|v| !v.is_finite()) {
                return Err(Error::Numerical(format!(
                    "the known map `{}` is not finite at sample {at} (z = {})",
                    k.name, zi[at]
                )));
            }
            columns.push(w);
        }
        let u = Signal::from_fn(len, columns.len(), |t, c| columns[c][t]);
        let mut id_data = Data::new(u, data.y().clone())?;
        if self.location == Site::RateFeedback {
            id_data = id_data.with_z(Signal::from_fn(len, 1, |t, _| z.get(t, 0)))?;
        }
        let block = NonlinearBlock::new(
            self.model.blocks()[0].name.clone(),
            vec![0],
            0,
            Arc::clone(&self.model.blocks()[0].dispersion),
        );
        Ok((Model::new(self.block_lft()?, vec![block])?, id_data))
    }

    /// The z rows of the known maps computed from the record, after a zero row in place of
    /// the unknown block's: what [`Hypothesis::identification`] needs when the unknown
    /// block's z is not itself computable from u and y. Every map output is kept in the LFT,
    /// so that the known maps' z are refused when the unknown block's output reaches them.
    fn known_z(&self, data: &Data) -> Result<Signal> {
        let lft = self.model.lft();
        let d = lft.dims();
        let rows: Vec<usize> = (1..d.z).collect();
        let cols: Vec<usize> = (0..d.w).collect();
        let known = crate::known::select_channels(lft, &rows, &cols)?
            .compute_z(data.u(), data.y())?
            .0;
        Ok(Signal::from_fn(data.len(), d.z, |k, c| {
            if c == 0 { 0.0 } else { known.get(k, c - 1) }
        }))
    }

    /// Simulates the augmented model with `map` in its block N from `u`, with the noise `e`
    /// (zero when `None`) and a zero initial state.
    ///
    /// ```
    /// use std::sync::Arc;
    /// use structid_core::{PolynomialDispersion, Signal};
    /// use structid_discover::hypotheses::{Site, hypothesis};
    /// use structid_linear::PolynomialModel;
    /// let g = PolynomialModel { den: vec![1.0, -0.5], num: vec![vec![0.0, 1.0]], sample_time: None };
    /// let h = hypothesis(&g, Site::Input, Arc::new(PolynomialDispersion::new(1).unwrap())).unwrap();
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
        if !self.known.is_empty() {
            return self.model.simulate(&self.maps(map), u, e, None);
        }
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
    ///
    /// With several records, each record's rate starts at 0 (see [`crate::records`]).
    pub fn data(&self, data: &Data) -> Result<Data> {
        if data.record_count() > 1 {
            return crate::records::restack(data, |r| self.data(r));
        }
        match self.location {
            Site::RateFeedback => {
                let y = data.y();
                let ts = self.sample_time;
                // The first sample has no predecessor in the record: its rate is taken as 0
                // rather than y₀/T_s (a record rarely starts at y = 0, and one spurious rate
                // of y₀/T_s would set the map's range and kernel width).
                let rate = |k: usize| {
                    let prev = if k > 0 { y.get(k - 1, 0) } else { y.get(0, 0) };
                    (y.get(k, 0) - prev) / ts
                };
                if self.known.is_empty() {
                    return data
                        .clone()
                        .with_z(Signal::from_fn(y.len(), 1, |k, _| rate(k)));
                }
                // Every z row is attached: the known maps' as the LFT computes them from the
                // record, the new block's as the measured rate.
                let all = self.model.lft().compute_z(data.u(), y)?.0;
                let z = Signal::from_fn(y.len(), all.channels(), |k, c| {
                    if c == 0 { rate(k) } else { all.get(k, c) }
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
/// use structid_discover::hypotheses::{Site, hypothesis};
/// use structid_linear::PolynomialModel;
/// let g = PolynomialModel { den: vec![1.0, -0.8], num: vec![vec![0.0, 0.5]], sample_time: Some(0.1) };
/// for loc in Site::ALL {
///     let h = hypothesis(&g, loc, Arc::new(KernelDispersion::gaussian(0.3).unwrap())).unwrap();
///     assert_eq!(h.model.blocks().len(), 1);
/// }
/// ```
pub fn hypothesis(
    g: &PolynomialModel,
    location: Site,
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
    fn round_trip(location: Site, truth: fn(f64) -> f64, amplitude: f64) -> f64 {
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
            (Site::Input, cubic, 1.0),
            (Site::Output, cubic, 1.0),
            (Site::OutputFeedback, cubic, 0.5),
            (Site::RateFeedback, friction, 0.3),
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
        for loc in [Site::OutputFeedback, Site::RateFeedback] {
            let e = hypothesis(&direct, loc, Arc::clone(&d))
                .unwrap_err()
                .to_string();
            assert!(e.contains("delay"), "{e}");
        }
        assert!(hypothesis(&direct, Site::Input, Arc::clone(&d)).is_ok());
        let two = PolynomialModel {
            den: vec![1.0, -0.5],
            num: vec![vec![0.0, 1.0], vec![0.0, 2.0]],
            sample_time: None,
        };
        assert!(hypothesis(&two, Site::Input, d).is_err());
    }
}
