//! Where an unknown static block sits in a structure, and the LFT that puts it there.
//!
//! A nominal model is an LFT without maps (its w and z channels, if any, are *declared*
//! injection points and signals, unused until a block is put there): with state x,
//!
//! ```text
//!   x⁺ = A·x + B_u·u + B_e·e,    y = C_y·x + D_yu·u + D_ye·e
//! ```
//!
//! so y = G·u + H·e with G the deterministic and H the noise path. A [`Site`] says where one
//! block N is inserted, and [`Site::insert`] returns the LFT of the nominal model with N there;
//! the noise path H is kept as it is. This is the one place where these LFTs are built.
//!
//! | site | model | z (measurable because) |
//! |---|---|---|
//! | [`Site::Input`] | y = G·N(u) + H·e (Hammerstein) | z = u |
//! | [`Site::Output`] | y = N(G·u) + H·e (a sensor map, Wiener) | z = G·u depends on u only |
//! | [`Site::OutputFeedback`] | y = G·(u − N(y)) + H·e | z = y is measured |
//! | [`Site::RateFeedback`] | y = G·(u − N(ẏ)) + H·e, ẏ_k = (y_k − y_(k−1))/T_s | z = Ψ(q)·y with Ψ = (1 − q⁻¹)/T_s (dynamic) |
//! | [`Site::Declared`] | the nominal LFT's own w column and z row | checked by [`Lft::measurability`] |
//!
//! The sensor map needs G·u without the noise: when the noise path has dynamics of its own
//! (B_e ≠ 0), the state is doubled into a deterministic copy driven by u (read by z) and a
//! stochastic copy driven by e (read by y). The rate needs the previous output, carried as an
//! extra state m_k = y_(k−1). The feedback sites need one sample of delay in G (D_yu = 0).
//!
//! A [`Structure`] is a linear part (an [`Lft`] or a [`PolynomialModel`], realised with white
//! output noise) plus the block at its site and its dispersion, and any further blocks wrapped
//! around it ([`Structure::then`], [`chain`]); [`Structure::model`] gives the
//! [`Model`] to identify.

use std::sync::Arc;

use nalgebra::DMatrix;
use structid_linear::PolynomialModel;

use crate::dispersion::Dispersion;
use crate::error::{Error, Result};
use crate::model::lft::{Lft, LftMatrices};
use crate::model::{Model, NonlinearBlock};

/// Where an unknown static block sits in a structure.
///
/// Serialised in kebab case, as model files name the structures of `[linear]`: `"input"`,
/// `"output"`, `"output-feedback"`, `"rate-feedback"` (and `{ "declared": { "z": 0, "w": 0 } }`).
///
/// ```
/// use structid_core::Site;
/// assert_eq!(Site::parse("rate-feedback"), Some(Site::RateFeedback));
/// assert_eq!(Site::OutputFeedback.name(), "output-feedback");
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Site {
    /// An actuator map ahead of G: y = G·N(u) + H·e, z = u.
    Input,
    /// A sensor map of the noise-free linear output: y = N(G·u) + H·e, z = G·u.
    Output,
    /// Stiffness-like feedback from the measured output: y = G·(u − N(y)) + H·e, z = y.
    OutputFeedback,
    /// Friction-like feedback from the output's rate: y = G·(u − N(ẏ)) + H·e with
    /// ẏ_k = (y_k − y_(k−1))/T_s (T_s the nominal model's sample time, 1 when it has none,
    /// y_(−1) = 0).
    RateFeedback,
    /// A place the nominal LFT declares itself: the block reads its z row `z` and writes its
    /// w column `w`.
    Declared {
        /// The z row the block reads.
        z: usize,
        /// The w column the block writes.
        w: usize,
    },
}

impl Site {
    /// The four built-in sites, in the order of the module's table.
    pub const ALL: [Site; 4] = [
        Site::Input,
        Site::Output,
        Site::OutputFeedback,
        Site::RateFeedback,
    ];

    /// The name used in model files (`input`, `output`, `output-feedback`, `rate-feedback`),
    /// `declared` for a declared site.
    pub fn name(self) -> &'static str {
        match self {
            Site::Input => "input",
            Site::Output => "output",
            Site::OutputFeedback => "output-feedback",
            Site::RateFeedback => "rate-feedback",
            Site::Declared { .. } => "declared",
        }
    }

    /// The built-in site called `name` (see [`Site::name`]), if any.
    pub fn parse(name: &str) -> Option<Site> {
        Site::ALL.into_iter().find(|s| s.name() == name)
    }

    /// A short description for reports.
    pub fn describe(self) -> &'static str {
        match self {
            Site::Input => "at the input: y = G·N(u) + e",
            Site::Output => "at the output (sensor): y = N(G·u) + e",
            Site::OutputFeedback => "in feedback from the output: y = G·(u − N(y)) + e",
            Site::RateFeedback => "in feedback from the output rate: y = G·(u − N(ẏ)) + e",
            Site::Declared { .. } => "at a location declared with the nominal model",
        }
    }

    /// The LFT of `nominal` with one block (z row 0, w column 0) at this site; the noise path
    /// is kept. The built-in sites ignore the nominal LFT's declared channels.
    ///
    /// ```
    /// use nalgebra::{DMatrix, dmatrix};
    /// use structid_core::{Lft, LftMatrices, Site};
    /// // y = 0.5/(q − 0.8)·u + e
    /// let nominal = Lft::new(LftMatrices {
    ///     a: dmatrix![0.8], bu: dmatrix![0.5], be: dmatrix![0.0], bw: DMatrix::zeros(1, 0),
    ///     cy: dmatrix![1.0], dyu: dmatrix![0.0], dye: dmatrix![1.0], dyw: DMatrix::zeros(1, 0),
    ///     cz: DMatrix::zeros(0, 1), dzu: DMatrix::zeros(0, 1), dze: DMatrix::zeros(0, 1),
    ///     dzw: DMatrix::zeros(0, 0),
    /// }).unwrap();
    /// let lft = Site::Input.insert(&nominal).unwrap();
    /// assert_eq!((lft.dims().w, lft.dims().z), (1, 1));
    /// ```
    pub fn insert(self, nominal: &Lft) -> Result<Lft> {
        match self {
            Site::Input => at_input(nominal),
            Site::Output => at_output(nominal),
            Site::OutputFeedback => {
                single_input(nominal, "in feedback from the output")?;
                let m = nominal.matrices();
                feedback_from_output(nominal, m.bu.clone(), m.dyu.clone(), -&m.bu, -&m.dyu)
            }
            Site::RateFeedback => rate_feedback(nominal),
            Site::Declared { z, w } => declared(nominal, z, w),
        }
    }
}

/// The LFT of a linear model without maps, y = Σ_i B_i/F·u_i + e (white output noise): the
/// nominal model of a polynomial G. The sample time of `g` is kept.
///
/// ```
/// use structid_core::model::structure::realise;
/// use structid_linear::PolynomialModel;
/// let g = PolynomialModel { num: vec![vec![0.0, 1.0]], den: vec![1.0, -0.5], sample_time: Some(0.1) };
/// let lft = realise(&g).unwrap();
/// assert_eq!((lft.dims().w, lft.dims().z), (0, 0));
/// ```
pub fn realise(g: &PolynomialModel) -> Result<Lft> {
    let ss = g
        .to_state_space()
        .map_err(|e| Error::InvalidStructure(format!("linear estimation: {e}")))?;
    let n = ss.order();
    let nu = ss.inputs();
    let lft = Lft::new(LftMatrices {
        a: ss.a().clone(),
        bu: ss.b().clone(),
        be: DMatrix::zeros(n, 1),
        bw: DMatrix::zeros(n, 0),
        cy: ss.c().clone(),
        dyu: ss.d().clone(),
        dye: DMatrix::identity(1, 1),
        dyw: DMatrix::zeros(1, 0),
        cz: DMatrix::zeros(0, n),
        dzu: DMatrix::zeros(0, nu),
        dze: DMatrix::zeros(0, 1),
        dzw: DMatrix::zeros(0, 0),
    })?;
    match g.sample_time {
        Some(ts) => lft.with_sample_time(ts),
        None => Ok(lft),
    }
}

/// The nominal LFT without its declared w and z channels (the model without any block).
pub fn without_blocks(nominal: &Lft) -> Result<Lft> {
    let m = nominal.matrices();
    let d = nominal.dims();
    with_time(
        nominal,
        // The u, e → y part is kept; only the w and z channels change.
        LftMatrices {
            bw: DMatrix::zeros(d.states, 0),
            dyw: DMatrix::zeros(d.y, 0),
            cz: DMatrix::zeros(0, d.states),
            dzu: DMatrix::zeros(0, d.u),
            dze: DMatrix::zeros(0, d.e),
            dzw: DMatrix::zeros(0, 0),
            ..m.clone()
        },
    )
}

/// The linear part of a [`Structure`].
#[derive(Clone, Debug)]
pub enum LinearPart {
    /// A nominal LFT (any noise path, possibly with declared channels).
    Lft(Box<Lft>),
    /// A polynomial G, realised with white output noise ([`realise`]).
    Polynomial(PolynomialModel),
}

impl From<Lft> for LinearPart {
    fn from(l: Lft) -> Self {
        LinearPart::Lft(Box::new(l))
    }
}

impl From<&Lft> for LinearPart {
    fn from(l: &Lft) -> Self {
        LinearPart::Lft(Box::new(l.clone()))
    }
}

impl From<PolynomialModel> for LinearPart {
    fn from(g: PolynomialModel) -> Self {
        LinearPart::Polynomial(g)
    }
}

impl From<&PolynomialModel> for LinearPart {
    fn from(g: &PolynomialModel) -> Self {
        LinearPart::Polynomial(g.clone())
    }
}

/// How the block's output reaches y at [`Site::OutputFeedback`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum FeedbackPath {
    /// Through G's own input path: y = G·(u − N(y)).
    Shared,
    /// Through the polynomial's last numerator: y = Σ B_i/F·u_i + B_w/F·N(y).
    LastNumerator,
}

/// One unknown block placed in a [`Structure`].
#[derive(Clone, Debug)]
pub struct PlacedBlock {
    /// The block's name.
    pub name: String,
    /// Where it sits.
    pub site: Site,
    /// Its dispersion.
    pub dispersion: Arc<dyn Dispersion>,
}

/// A structured model: a linear part, and where the unknown blocks sit with their
/// dispersions. The first block is placed in the linear part; each further one
/// ([`Structure::then`]) at a site of the model built so far (see [`chain`]).
#[derive(Clone, Debug)]
pub struct Structure {
    linear: LinearPart,
    blocks: Vec<PlacedBlock>,
    path: FeedbackPath,
}

impl Structure {
    /// The linear part alone (no block): y = G·u + H·e.
    pub fn linear(g: impl Into<LinearPart>) -> Self {
        Self {
            linear: g.into(),
            blocks: Vec::new(),
            path: FeedbackPath::Shared,
        }
    }

    /// The linear part `g` with one block called `N` at `site`.
    pub fn new(g: impl Into<LinearPart>, site: Site, dispersion: Arc<dyn Dispersion>) -> Self {
        Self {
            linear: g.into(),
            blocks: vec![PlacedBlock {
                name: "N".into(),
                site,
                dispersion,
            }],
            path: FeedbackPath::Shared,
        }
    }

    /// A Hammerstein model y = G·N(u) + e (or + H·e for an LFT `g`): the block at the input.
    ///
    /// ```
    /// use std::sync::Arc;
    /// use structid_core::{Data, IdentifySettings, KernelDispersion, Signal, Structure, identify};
    /// use structid_linear::PolynomialModel;
    /// let g = PolynomialModel { num: vec![vec![0.0, 1.0]], den: vec![1.0, -0.5], sample_time: None };
    /// let model = Structure::hammerstein(&g, Arc::new(KernelDispersion::gaussian(0.5).unwrap()))
    ///     .model()
    ///     .unwrap();
    /// // y_k = 0.5·y_(k−1) + tanh(u_(k−1)), noise-free.
    /// let u = Signal::from_fn(120, 1, |k, _| 2.0 * (0.37 * k as f64).sin());
    /// let mut y = vec![0.0; 120];
    /// for k in 1..120 { y[k] = 0.5 * y[k - 1] + u.get(k - 1, 0).tanh(); }
    /// let data = Data::new(u, Signal::new(1, y).unwrap()).unwrap();
    /// let id = identify(&model, &data, &IdentifySettings::builder().beta(1e-6).build().unwrap()).unwrap();
    /// assert!((id.blocks[0].predict(&[1.0]) - 1f64.tanh()).abs() < 0.05);
    /// ```
    pub fn hammerstein(g: impl Into<LinearPart>, dispersion: Arc<dyn Dispersion>) -> Self {
        Self::new(g, Site::Input, dispersion)
    }

    /// A Wiener model y = N(G·u) + e: a sensor map of the noise-free linear output. z = G·u
    /// depends on u only, so it is measurable without being measured (z = L_zu·u).
    ///
    /// ```
    /// use std::sync::Arc;
    /// use structid_core::{MapBinding, PolynomialDispersion, Structure, ZSource};
    /// use structid_linear::PolynomialModel;
    /// use structid_lti::Signal;
    /// let g = PolynomialModel { num: vec![vec![0.0, 1.0]], den: vec![1.0, -0.5], sample_time: Some(0.1) };
    /// let lft = Structure::wiener(&g, Arc::new(PolynomialDispersion::new(3).unwrap())).lft().unwrap();
    /// assert_eq!((lft.dims().u, lft.dims().w, lft.dims().z), (1, 1, 1));
    /// assert_eq!(lft.measurability().unwrap(), ZSource::InputOnly);
    /// // y = tanh(G·u): with u a unit step, G·u = 0, 1, 1.5, …
    /// let tanh = |z: &[f64]| z[0].tanh();
    /// let u = Signal::from_fn(3, 1, |_, _| 1.0);
    /// let sim = lft.simulate(&[MapBinding { inputs: &[0], output: 0, map: &tanh }], &u, None, None).unwrap();
    /// assert!((sim.y.get(2, 0) - 1.5f64.tanh()).abs() < 1e-12);
    /// ```
    pub fn wiener(g: impl Into<LinearPart>, dispersion: Arc<dyn Dispersion>) -> Self {
        Self::new(g, Site::Output, dispersion)
    }

    /// Output feedback y = G·(u − N(y)) + e (G needs an input delay).
    pub fn output_feedback(g: impl Into<LinearPart>, dispersion: Arc<dyn Dispersion>) -> Self {
        Self::new(g, Site::OutputFeedback, dispersion)
    }

    /// Output feedback through a path of its own, y = Σ_i B_i/F·u_i + B_w/F·N(y) + e: the
    /// polynomial `g`'s last numerator B_w carries the block's output (the form refinement
    /// estimates and `[linear]` sections store; B_w = −B for the shared path).
    pub fn output_feedback_with_path(g: &PolynomialModel, dispersion: Arc<dyn Dispersion>) -> Self {
        Self {
            path: FeedbackPath::LastNumerator,
            ..Self::new(g, Site::OutputFeedback, dispersion)
        }
    }

    /// Rate feedback (friction-like) y = G·(u − N(ẏ)) + e, where the map reads the measured
    /// output's backward difference ẏ_k = (y_k − y_(k−1))/T_s (T_s the sample time of `g`, 1
    /// when it has none, y_(−1) = 0).
    ///
    /// The LFT carries the previous output as an extra state m_k = y_(k−1): with G = (A, B, C)
    ///
    /// ```text
    ///   x⁺ = A·x + B·u − B·w,   m⁺ = C·x + e,   y = C·x + e,   z = (C·x + e − m)/T_s
    /// ```
    ///
    /// z is a *dynamic* function of the measured output, z = Ψ(q)·y with Ψ = (1 − q⁻¹)/T_s (the
    /// paper's Definition 1 with an LTI Ψ_M), which [`Lft::measurability`] recognises as
    /// [`crate::ZSource::Dynamic`]. G must have one input and an input delay (nk ≥ 1);
    /// otherwise y_k would depend on N(ẏ_k), an algebraic loop.
    ///
    /// ```
    /// use std::sync::Arc;
    /// use structid_core::{PolynomialDispersion, Structure, ZSource};
    /// use structid_linear::PolynomialModel;
    /// use structid_lti::Signal;
    /// let d = Arc::new(PolynomialDispersion::new(3).unwrap());
    /// let g = PolynomialModel { num: vec![vec![0.0, 1.0]], den: vec![1.0, -0.5], sample_time: Some(0.1) };
    /// let lft = Structure::rate_feedback(&g, d.clone()).lft().unwrap();
    /// assert_eq!(lft.dims().states, 2);
    /// assert!(matches!(lft.measurability().unwrap(), ZSource::Dynamic { .. }));
    /// // z is the measured rate: y = 0, 1, 3 gives z = 0, 10, 20.
    /// let u = Signal::zeros(3, 1);
    /// let y = Signal::new(1, vec![0.0, 1.0, 3.0]).unwrap();
    /// let (z, _) = lft.compute_z(&u, &y).unwrap();
    /// assert!(z.as_slice().iter().zip([0.0, 10.0, 20.0]).all(|(a, b)| (a - b).abs() < 1e-12));
    ///
    /// let direct = PolynomialModel { num: vec![vec![1.0]], den: vec![1.0, -0.5], sample_time: None };
    /// assert!(Structure::rate_feedback(&direct, d).lft().unwrap_err().to_string().contains("delay"));
    /// ```
    pub fn rate_feedback(g: impl Into<LinearPart>, dispersion: Arc<dyn Dispersion>) -> Self {
        Self::new(g, Site::RateFeedback, dispersion)
    }

    /// Renames the block placed last.
    pub fn named(mut self, name: impl Into<String>) -> Self {
        if let Some(b) = self.blocks.last_mut() {
            b.name = name.into();
        }
        self
    }

    /// One more block, called `N<k>` (k its position from 1), at `site` of the model built so
    /// far: an input map ahead of it, a sensor map behind it, a map in feedback around it (see
    /// [`chain`]). Maps in series follow from the wrapping; the LFT is checked when it is
    /// built ([`Structure::lft`], [`Structure::model`]).
    ///
    /// ```
    /// use std::sync::Arc;
    /// use structid_core::{BlockAccess, KernelDispersion, Signal, Site, Structure};
    /// use structid_linear::PolynomialModel;
    /// let d = Arc::new(KernelDispersion::gaussian(0.5).unwrap());
    /// // y = N₂(G·N₁(u)) + e: a Hammerstein–Wiener structure.
    /// let g = PolynomialModel { num: vec![vec![0.0, 1.0]], den: vec![1.0, -0.5], sample_time: None };
    /// let s = Structure::hammerstein(&g, d.clone()).named("actuator")
    ///     .then(Site::Output, d).named("sensor");
    /// let model = s.model().unwrap();
    /// let square = |z: &[f64]| z[0] * z[0];
    /// let half = |z: &[f64]| 0.5 * z[0];
    /// let u = Signal::new(1, vec![1.0, 2.0, 0.0]).unwrap();
    /// let y = model.simulate(&[&square, &half], &u, None, None).unwrap().y;
    /// // G·u² = 0, 1, 0.5 + 4; then halved.
    /// assert_eq!(y.channel(0), vec![0.0, 0.5, 2.25]);
    /// ```
    pub fn then(mut self, site: Site, dispersion: Arc<dyn Dispersion>) -> Self {
        let name = format!("N{}", self.blocks.len() + 1);
        self.blocks.push(PlacedBlock {
            name,
            site,
            dispersion,
        });
        self
    }

    /// The linear part.
    pub fn linear_part(&self) -> &LinearPart {
        &self.linear
    }

    /// The first block, if any.
    pub fn block(&self) -> Option<&PlacedBlock> {
        self.blocks.first()
    }

    /// Every block, in the order placed.
    pub fn blocks(&self) -> &[PlacedBlock] {
        &self.blocks
    }

    /// Where the first block sits (`None` without a block).
    pub fn site(&self) -> Option<Site> {
        self.blocks.first().map(|b| b.site)
    }

    /// The structure's LFT: the nominal model of the linear part with the first block at its
    /// site (w column 0, z row 0), each further block wrapped around it in turn (w column and
    /// z row i, see [`chain`]); or without any block.
    pub fn lft(&self) -> Result<Lft> {
        let site = self.site();
        let mut lft = match &self.linear {
            LinearPart::Lft(nominal) => match site {
                None => without_blocks(nominal),
                Some(s) => s.insert(nominal),
            },
            LinearPart::Polynomial(g) => {
                polynomial_lft(g, site, self.path == FeedbackPath::LastNumerator)
            }
        }?;
        for b in self.blocks.iter().skip(1) {
            lft = chain::wrap(b.site, &lft)?;
        }
        Ok(lft)
    }

    /// The structured model to identify (block i reads z row i and writes w column i).
    ///
    /// # Errors
    /// The LFT's, and [`Error::AlgebraicLoop`] when the blocks form a true cycle.
    pub fn model(&self) -> Result<Model> {
        let blocks = self
            .blocks
            .iter()
            .enumerate()
            .map(|(i, b)| {
                NonlinearBlock::new(b.name.clone(), vec![i], i, Arc::clone(&b.dispersion))
            })
            .collect();
        let model = Model::new(self.lft()?, blocks)?;
        model.evaluation_order()?;
        Ok(model)
    }
}

/// The LFT of a polynomial G with a block at `site`: G realised with white output noise, then
/// the block inserted; the checks are those of G's coefficients, with the polynomial's terms.
/// With `feedback_path`, output feedback goes through G's last numerator.
pub(crate) fn polynomial_lft(
    g: &PolynomialModel,
    site: Option<Site>,
    feedback_path: bool,
) -> Result<Lft> {
    match (site, feedback_path) {
        (None, _) => realise(g),
        (Some(Site::OutputFeedback), true) => {
            if g.num.len() < 2 {
                return Err(Error::InvalidStructure(
                    "an output-feedback linear part needs at least one u input and the w input"
                        .into(),
                ));
            }
            let nu = g.num.len() - 1;
            if g.num[nu].first().is_some_and(|b| *b != 0.0) {
                return Err(Error::InvalidStructure(format!(
                    "the feedback path has a direct term (b_0 = {}); it needs an input delay \
                     nk ≥ 1, otherwise y_k depends on N(y_k) (an algebraic loop)",
                    g.num[nu][0]
                )));
            }
            let all = realise(g)?;
            let m = all.matrices();
            feedback_from_output(
                &all,
                m.bu.columns(0, nu).into_owned(),
                m.dyu.columns(0, nu).into_owned(),
                m.bu.columns(nu, 1).into_owned(),
                m.dyu.columns(nu, 1).into_owned(),
            )
        }
        (Some(Site::Input), _) => {
            if g.num.len() != 1 {
                return Err(Error::InvalidStructure(
                    "an input-nonlinearity linear part has exactly one input (the map's output)"
                        .into(),
                ));
            }
            at_input(&realise(g)?)
        }
        (Some(Site::Output), _) => {
            if g.num.is_empty() {
                return Err(Error::InvalidStructure(
                    "an output (sensor) map needs a linear part with at least one input".into(),
                ));
            }
            at_output(&realise(g)?)
        }
        (Some(Site::RateFeedback), _) => {
            if g.num.len() != 1 {
                return Err(Error::InvalidStructure(format!(
                    "rate feedback y = G·(u − N(ẏ)) + e needs a linear part with exactly one \
                     input; this one has {}",
                    g.num.len()
                )));
            }
            if g.num[0].first().is_some_and(|b| *b != 0.0) {
                return Err(Error::InvalidStructure(format!(
                    "rate feedback y = G·(u − N(ẏ)) + e needs G to have an input delay (nk ≥ 1, \
                     a numerator starting with 0; it starts with {}); otherwise y_k depends on \
                     N(ẏ_k), an algebraic loop",
                    g.num[0][0]
                )));
            }
            rate_feedback(&realise(g)?)
        }
        (Some(s), _) => s.insert(&realise(g)?),
    }
}

fn single_input(nominal: &Lft, what: &str) -> Result<()> {
    let d = nominal.dims();
    if d.u != 1 || d.y != 1 {
        return Err(Error::InvalidStructure(format!(
            "a block {what} is built for a nominal model with one input and one output; this one \
             has {} input(s) and {} output(s)",
            d.u, d.y
        )));
    }
    Ok(())
}

fn no_direct_feedthrough(nominal: &Lft, what: &str) -> Result<()> {
    let m = nominal.matrices();
    if m.dyu.iter().any(|v| *v != 0.0) {
        return Err(Error::InvalidStructure(format!(
            "a block {what} needs G to have an input delay (D_yu = 0); otherwise y_k depends on \
             the map of y_k itself, an algebraic loop"
        )));
    }
    Ok(())
}

fn with_time(nominal: &Lft, m: LftMatrices) -> Result<Lft> {
    let lft = Lft::new(m)?;
    match nominal.sample_time() {
        Some(ts) => lft.with_sample_time(ts),
        None => Ok(lft),
    }
}

/// y = G·N(u) + H·e: an actuator map ahead of the nominal model (one input).
fn at_input(nominal: &Lft) -> Result<Lft> {
    single_input(nominal, "at the input")?;
    let m = nominal.matrices();
    let n = nominal.dims().states;
    with_time(
        nominal,
        LftMatrices {
            a: m.a.clone(),
            bu: DMatrix::zeros(n, 1),
            be: m.be.clone(),
            bw: m.bu.clone(),
            cy: m.cy.clone(),
            dyu: DMatrix::zeros(1, 1),
            dye: m.dye.clone(),
            dyw: m.dyu.clone(),
            cz: DMatrix::zeros(1, n),
            dzu: DMatrix::identity(1, 1),
            dze: DMatrix::zeros(1, m.dye.ncols()),
            dzw: DMatrix::zeros(1, 1),
        },
    )
}

/// y = N(G·u) + H·e: a sensor map of the noise-free linear output (one output, any number of
/// inputs).
fn at_output(nominal: &Lft) -> Result<Lft> {
    if nominal.dims().y != 1 {
        return Err(Error::InvalidStructure(format!(
            "a block at the output is built for a nominal model with one output; this one has {}",
            nominal.dims().y
        )));
    }
    let m = nominal.matrices();
    let n = nominal.dims().states;
    let nu = nominal.dims().u;
    let ne = m.dye.ncols();
    let noise_dynamics = m.be.iter().any(|v| *v != 0.0);
    let matrices = if noise_dynamics {
        let mut a = DMatrix::zeros(2 * n, 2 * n);
        a.view_mut((0, 0), (n, n)).copy_from(&m.a);
        a.view_mut((n, n), (n, n)).copy_from(&m.a);
        let mut bu = DMatrix::zeros(2 * n, nu);
        bu.view_mut((0, 0), (n, nu)).copy_from(&m.bu);
        let mut be = DMatrix::zeros(2 * n, ne);
        be.view_mut((n, 0), (n, ne)).copy_from(&m.be);
        let mut cy = DMatrix::zeros(1, 2 * n);
        cy.view_mut((0, n), (1, n)).copy_from(&m.cy);
        let mut cz = DMatrix::zeros(1, 2 * n);
        cz.view_mut((0, 0), (1, n)).copy_from(&m.cy);
        LftMatrices {
            a,
            bu,
            be,
            bw: DMatrix::zeros(2 * n, 1),
            cy,
            dyu: DMatrix::zeros(1, nu),
            dye: m.dye.clone(),
            dyw: DMatrix::identity(1, 1),
            cz,
            dzu: m.dyu.clone(),
            dze: DMatrix::zeros(1, ne),
            dzw: DMatrix::zeros(1, 1),
        }
    } else {
        LftMatrices {
            a: m.a.clone(),
            bu: m.bu.clone(),
            be: m.be.clone(),
            bw: DMatrix::zeros(n, 1),
            cy: DMatrix::zeros(1, n),
            dyu: DMatrix::zeros(1, nu),
            dye: m.dye.clone(),
            dyw: DMatrix::identity(1, 1),
            cz: m.cy.clone(),
            dzu: m.dyu.clone(),
            dze: DMatrix::zeros(1, ne),
            dzw: DMatrix::zeros(1, 1),
        }
    };
    with_time(nominal, matrices)
}

/// y = G_u·u + G_w·N(y) + H·e with z = y: G_u = (A, `bu`, C_y, `dyu`) and the feedback path
/// G_w = (A, `bw`, C_y, `dyw`) (−G_u for y = G·(u − N(y))). The feedback path needs a delay
/// (`dyw` = 0).
fn feedback_from_output(
    nominal: &Lft,
    bu: DMatrix<f64>,
    dyu: DMatrix<f64>,
    bw: DMatrix<f64>,
    dyw: DMatrix<f64>,
) -> Result<Lft> {
    if nominal.dims().y != 1 {
        return Err(Error::InvalidStructure(format!(
            "a block in feedback from the output is built for a nominal model with one output; \
             this one has {}",
            nominal.dims().y
        )));
    }
    if dyw.iter().any(|v| *v != 0.0) {
        return Err(Error::InvalidStructure(
            "a block in feedback from the output needs G to have an input delay (D_yu = 0); \
             otherwise y_k depends on the map of y_k itself, an algebraic loop"
                .into(),
        ));
    }
    let m = nominal.matrices();
    with_time(
        nominal,
        LftMatrices {
            a: m.a.clone(),
            bu,
            be: m.be.clone(),
            bw,
            cy: m.cy.clone(),
            dyu: dyu.clone(),
            dye: m.dye.clone(),
            dyw: dyw.clone(),
            cz: m.cy.clone(),
            dzu: dyu,
            dze: m.dye.clone(),
            dzw: dyw,
        },
    )
}

/// y = G·(u − N(ẏ)) + H·e with ẏ_k = (y_k − y_(k−1))/T_s.
fn rate_feedback(nominal: &Lft) -> Result<Lft> {
    single_input(nominal, "in feedback from the output rate")?;
    no_direct_feedthrough(nominal, "in feedback from the output rate")?;
    let ts = nominal.sample_time().unwrap_or(1.0);
    let m = nominal.matrices();
    let n = nominal.dims().states;
    let ne = m.dye.ncols();
    // States [x; m] with m_k = y_(k−1).
    let mut a = DMatrix::zeros(n + 1, n + 1);
    a.view_mut((0, 0), (n, n)).copy_from(&m.a);
    a.view_mut((n, 0), (1, n)).copy_from(&m.cy);
    let mut bu = DMatrix::zeros(n + 1, 1);
    bu.view_mut((0, 0), (n, 1)).copy_from(&m.bu);
    let mut be = DMatrix::zeros(n + 1, ne);
    be.view_mut((0, 0), (n, ne)).copy_from(&m.be);
    be.view_mut((n, 0), (1, ne)).copy_from(&m.dye);
    let bw = -&bu;
    let mut cy = DMatrix::zeros(1, n + 1);
    cy.view_mut((0, 0), (1, n)).copy_from(&m.cy);
    let mut cz = &cy / ts;
    cz[(0, n)] = -1.0 / ts;
    with_time(
        nominal,
        LftMatrices {
            a,
            bu,
            be,
            bw,
            cy,
            dyu: DMatrix::zeros(1, 1),
            dye: m.dye.clone(),
            dyw: DMatrix::zeros(1, 1),
            cz,
            dzu: DMatrix::zeros(1, 1),
            dze: &m.dye / ts,
            dzw: DMatrix::zeros(1, 1),
        },
    )
}

/// The nominal LFT with only its declared w column `w` and z row `z`.
fn declared(nominal: &Lft, z: usize, w: usize) -> Result<Lft> {
    let d = nominal.dims();
    if z >= d.z || w >= d.w {
        return Err(Error::InvalidStructure(format!(
            "declared location (z row {z}, w column {w}) is outside the nominal model's {} z \
             row(s) and {} w column(s)",
            d.z, d.w
        )));
    }
    let m = nominal.matrices();
    with_time(
        nominal,
        // The u, e → y part is kept; only the w and z channels change.
        LftMatrices {
            bw: m.bw.columns(w, 1).into_owned(),
            dyw: m.dyw.columns(w, 1).into_owned(),
            cz: m.cz.rows(z, 1).into_owned(),
            dzu: m.dzu.rows(z, 1).into_owned(),
            dze: m.dze.rows(z, 1).into_owned(),
            dzw: DMatrix::from_element(1, 1, m.dzw[(z, w)]),
            ..m.clone()
        },
    )
}

pub mod chain;

#[cfg(test)]
mod tests;
