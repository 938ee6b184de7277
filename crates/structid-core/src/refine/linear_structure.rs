//! Where the uncertain linear block's map sits, and how the linear part is re-estimated.

use super::*;

/// Where the uncertain linear block's map sits, and how the linear part is re-estimated:
/// one of the [`Site`]s refinement supports, with the map's name.
///
/// * [`LinearStructure::output_feedback`]: y = G·(u − w) + e with w = N(y), z = y. G has one
///   output and the data's inputs. With a shared numerator (the default) the map acts at the
///   input of G exactly like u does: G is a SISO model driven by u − w (one u channel). With a
///   separate numerator ([`LinearStructure::with_separate_numerator`]), y = B_u/F·u + B_w/F·w
///   with a common F (any number of u channels), which also absorbs a feedback path that is
///   not exactly the input path. The feedback path needs a delay (B_w starting at q⁻¹): with a
///   direct term, y_k would depend on N(y_k), an algebraic loop.
/// * [`LinearStructure::input`]: an input nonlinearity (Hammerstein), y = G·N(u) + e, z = u.
/// * [`LinearStructure::rate_feedback`]: y = G·(u − N(ẏ)) + e, z = (y_k − y_(k−1))/T_s. G
///   is SISO from u with an input delay (as for a shared feedback numerator).
/// * [`LinearStructure::output`]: a sensor map, y = N(G·u) + e, z = G·u.
///
/// G is kept in the structure's form: for output feedback its inputs are [u…, w] (the last
/// numerator is the path of w, −B for the shared path), for an input map its one input is
/// w, for rate feedback and a sensor map its inputs are u. A location declared in a nominal
/// LFT is refined through [`LinearStructure::from_lft`].
///
/// ```
/// use std::sync::Arc;
/// use structid_core::{KernelDispersion, refine::LinearStructure};
/// use structid_linear::PolynomialModel;
/// let g = PolynomialModel { num: vec![vec![0.0, 1.0, 0.5]], den: vec![1.0, -1.5, 0.7], sample_time: None };
/// let s = LinearStructure::output_feedback("stiffness");
/// let g = s.initial_from_bla(&g).unwrap();
/// let model = s.model(&g, Arc::new(KernelDispersion::gaussian(0.1).unwrap())).unwrap();
/// assert_eq!(model.blocks()[0].name, "stiffness");
///
/// let g = PolynomialModel { num: vec![vec![0.0, 1.0]], den: vec![1.0, -0.5], sample_time: None };
/// let model = LinearStructure::input("actuator")
///     .model(&g, Arc::new(KernelDispersion::gaussian(0.3).unwrap()))
///     .unwrap();
/// assert_eq!(model.lft().dims().z, 1);
/// ```
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LinearStructure {
    pub(super) name: String,
    pub(super) site: Site,
    pub(super) separate: bool,
    pub(super) integrators: Option<usize>,
}

impl LinearStructure {
    /// Output feedback through G's own numerator; `name` names the map.
    pub fn output_feedback(name: impl Into<String>) -> Self {
        Self::at(name, Site::OutputFeedback)
    }

    /// An input map called `name`.
    pub fn input(name: impl Into<String>) -> Self {
        Self::at(name, Site::Input)
    }

    /// Rate feedback y = G·(u − N(ẏ)) + e with ẏ_k = (y_k − y_(k−1))/T_s (friction); `name`
    /// names the map. G has one input and an input delay.
    pub fn rate_feedback(name: impl Into<String>) -> Self {
        Self::at(name, Site::RateFeedback)
    }

    /// A sensor map y = N(G·u) + e called `name` (Wiener). G's gain is not identifiable from
    /// this structure (N(z/k) with k·G is the same system): the linear step keeps the map
    /// fixed, which pins it, and its poles are what the data determine.
    pub fn output(name: impl Into<String>) -> Self {
        Self::at(name, Site::Output)
    }

    pub(super) fn at(name: impl Into<String>, site: Site) -> Self {
        Self {
            name: name.into(),
            site,
            separate: false,
            integrators: None,
        }
    }

    /// The map `name` at a built-in `site`: [`Site::Input`], [`Site::Output`],
    /// [`Site::OutputFeedback`] or [`Site::RateFeedback`]. A [`Site::Declared`] location
    /// belongs to a nominal LFT, not to a polynomial G: [`LinearStructure::from_lft`] finds
    /// the G that such an LFT puts its map around.
    pub fn new(name: impl Into<String>, site: Site) -> Result<Self> {
        match site {
            Site::Declared { z, w } => Err(Error::InvalidStructure(format!(
                "a declared location (z row {z}, w column {w}) is a channel of a nominal LFT, \
                 not a place in a polynomial G; refine it with LinearStructure::from_lft, \
                 which finds the G that the LFT puts its map around"
            ))),
            site => Ok(Self::at(name, site)),
        }
    }

    /// The structure in which the declared location (z row `z`, w column `w`) of `nominal`
    /// puts its map, and the linear part G in that structure's form.
    ///
    /// A general LFT does not say which of its coefficients are "G": refinement re-estimates
    /// G only when the LFT restricted to that location *is* one of the built-in structures
    /// around a single polynomial block. The transfers from (u, w, e) to (y, z) are compared,
    /// by their Markov parameters, with those of output feedback (shared and separate
    /// numerator), rate feedback, an input map and an output map built from the transfer
    /// that plays G's part (u → y, w → y or u → z, read off the LFT as B/F with
    /// F = det(I − A·q⁻¹)); the first that agrees is returned. Otherwise, and when the noise
    /// path has dynamics (refinement re-estimates G by output error, under white output
    /// noise), the error says why. G keeps the LFT's sample time; modes that the transfer
    /// does not see are dropped only when they are at the origin (e.g. the rate site's
    /// previous-output state).
    ///
    /// ```
    /// use structid_core::{Site, refine::LinearStructure, model::structure::realise};
    /// use structid_linear::PolynomialModel;
    /// let g = PolynomialModel { num: vec![vec![0.0, 0.5]], den: vec![1.0, -0.8], sample_time: Some(0.1) };
    /// let lft = Site::RateFeedback.insert(&realise(&g).unwrap()).unwrap();
    /// let (s, found) = LinearStructure::from_lft("friction", &lft, 0, 0).unwrap();
    /// assert_eq!(s.site(), Site::RateFeedback);
    /// assert!((found.den[1] + 0.8).abs() < 1e-12 && (found.num[0][1] - 0.5).abs() < 1e-12);
    /// ```
    pub fn from_lft(
        name: impl Into<String>,
        nominal: &Lft,
        z: usize,
        w: usize,
    ) -> Result<(Self, PolynomialModel)> {
        recognise::from_lft(name.into(), nominal, z, w)
    }

    /// Holds `n` poles of G at z = 1 (integrators) fixed in the linear step: G = B/(F′·(1 −
    /// q⁻¹)ⁿ) and only B and F′ are re-estimated. `None` (the default) holds as many as the
    /// starting G has (factors (1 − q⁻¹) of its denominator, to a relative 1e-8).
    pub fn with_integrators(mut self, n: Option<usize>) -> Self {
        self.integrators = n;
        self
    }

    /// The number of integrators held fixed (`None`: those of the starting G).
    pub fn integrators(&self) -> Option<usize> {
        self.integrators
    }

    /// Fits the feedback path's numerator separately (y = B_u/F·u + B_w/F·w); only output
    /// feedback has a feedback path.
    pub fn with_separate_numerator(mut self, separate: bool) -> Self {
        self.separate = separate && self.site == Site::OutputFeedback;
        self
    }

    /// Whether the feedback path has its own numerator.
    pub fn separate_numerator(&self) -> bool {
        self.separate
    }

    /// Where the map sits.
    pub fn site(&self) -> Site {
        self.site
    }

    /// A short description for reports, e.g. `output feedback y = G·(u − N(y)) + e`.
    pub fn describe(&self) -> String {
        match (self.site, self.separate) {
            (Site::OutputFeedback, true) => "output feedback y = B_u/F·u + B_w/F·N(y) + e".into(),
            (Site::OutputFeedback, false) => "output feedback y = G·(u − N(y)) + e".into(),
            (Site::RateFeedback, _) => "rate feedback y = G·(u − N(ẏ)) + e".into(),
            (Site::Output, _) => "output (sensor) map y = N(G·u) + e".into(),
            _ => "input nonlinearity y = G·N(u) + e".into(),
        }
    }

    /// The name of the unknown map.
    pub fn block_name(&self) -> &str {
        &self.name
    }

    /// The LFT for the linear part `g` (in the structure's form): one map reading z\[0\] and
    /// writing w\[0\], white output noise (y = … + e) so that [`refine`]'s cost decreases.
    pub fn lft(&self, g: &PolynomialModel) -> Result<Lft> {
        match self.site {
            Site::OutputFeedback => structure::polynomial_lft(g, Some(Site::OutputFeedback), true)
                .map_err(|e| match e {
                    // Name the block in the message, as the model file's users know it.
                    Error::InvalidStructure(m) if m.starts_with("the feedback path") => {
                        Error::InvalidStructure(m.replacen(
                            "the feedback path",
                            &format!("the feedback path of `{}`", self.name),
                            1,
                        ))
                    }
                    other => other,
                }),
            site => structure::polynomial_lft(g, Some(site), false),
        }
    }

    /// The structured model for the linear part `g`, the map having dispersion `dispersion`.
    pub fn model(&self, g: &PolynomialModel, dispersion: Arc<dyn Dispersion>) -> Result<Model> {
        Model::new(
            self.lft(g)?,
            vec![NonlinearBlock::new(
                self.block_name().to_string(),
                vec![0],
                0,
                dispersion,
            )],
        )
    }

    /// Re-estimates the linear part with the maps' outputs fixed at their sample values
    /// `w_hat` (L × n_w), starting from `g`; with `free_initial_state` the initial state is
    /// estimated along with G (see [`output_error_with_state`]). The integrators of
    /// [`LinearStructure::with_integrators`] stay at z = 1.
    ///
    /// For output and rate feedback (shared numerator) G is SISO from v = u − ŵ; for an input
    /// map from ŵ. Data of several records are fitted together, each record simulated from
    /// rest or from its own initial state ([`output_error_records_with_state`]). A sensor map ([`Site::Output`]) reads z = G·u, which moves with G, so its
    /// linear step needs the map itself: use [`LinearStructure::estimate_linear_with_map`].
    pub fn estimate_linear(
        &self,
        data: &Data,
        w_hat: &Signal,
        g: &PolynomialModel,
        settings: &OeSettings,
        free_initial_state: bool,
    ) -> Result<OeFit> {
        let integrators = self.integrators_of(g)?;
        if w_hat.len() != data.len() {
            return Err(Error::DimensionMismatch {
                what: "map outputs ŵ of the linear step".into(),
                expected: format!("{} samples, like the data", data.len()),
                found: format!("{} samples", w_hat.len()),
            });
        }
        let fit = |inputs: &Signal, g: &PolynomialModel| {
            oe_fit_stacked(
                inputs,
                data.y(),
                data.record_bounds(),
                g,
                settings,
                free_initial_state,
                integrators,
            )
        };
        match self.site {
            Site::OutputFeedback | Site::RateFeedback => {
                let what = if self.site == Site::RateFeedback {
                    "rate feedback"
                } else {
                    "output feedback"
                };
                one_channel(data, what)?;
                let (u, len) = (data.u(), data.len());
                let nu = u.channels();
                if self.separate {
                    let inputs = Signal::from_fn(len, nu + 1, |k, c| {
                        if c < nu { u.get(k, c) } else { w_hat.get(k, 0) }
                    });
                    return fit(&inputs, g);
                }
                // Shared numerator: G is SISO from v = u − w; for output feedback the w column
                // of the result is −B.
                if nu != 1 {
                    return Err(Error::InvalidStructure(format!(
                        "{what} through G's own numerator needs exactly one input u, not {nu}{}",
                        if self.site == Site::OutputFeedback {
                            "; use a separate numerator"
                        } else {
                            ""
                        }
                    )));
                }
                let v = Signal::from_fn(len, 1, |k, _| u.get(k, 0) - w_hat.get(k, 0));
                let siso = PolynomialModel {
                    num: vec![g.num[0].clone()],
                    den: g.den.clone(),
                    sample_time: g.sample_time,
                };
                let mut fit = fit(&v, &siso)?;
                if self.site == Site::OutputFeedback {
                    let b = fit.model.num[0].clone();
                    fit.model.num.push(b.iter().map(|x| -x).collect());
                }
                Ok(fit)
            }
            Site::Input => {
                one_channel(data, "input nonlinearity")?;
                fit(w_hat, g)
            }
            Site::Output => Err(Error::InvalidStructure(
                "a sensor map y = N(G·u) + e reads z = G·u, which moves with G, so its linear \
                 step needs the map itself, not its sample values: use \
                 LinearStructure::estimate_linear_with_map"
                    .into(),
            )),
            Site::Declared { .. } => unreachable!("LinearStructure::new refuses declared sites"),
        }
    }

    /// Re-estimates the linear part with the map `map` fixed as a function, starting from
    /// `g`: what [`refine_linear`] does. For the feedback sites and an input map the map's
    /// input z is measured (y, its rate, or u), so this is [`LinearStructure::estimate_linear`]
    /// with ŵ = N̂(z). For a sensor map it minimises (1/L)·‖y − N̂(G·u)‖² over G by
    /// Levenberg–Marquardt, with the Jacobian N̂′(z)·∂z/∂θ (N̂′ by a central difference); the
    /// free initial state there enters z (an impulse input with its own numerator, started at
    /// zero).
    pub fn estimate_linear_with_map(
        &self,
        data: &Data,
        map: &dyn Interpolant,
        g: &PolynomialModel,
        settings: &OeSettings,
        free_initial_state: bool,
    ) -> Result<OeFit> {
        one_channel(data, self.site.name())?;
        let z = match self.site {
            Site::Output => {
                let integrators = self.integrators_of(g)?;
                return through_map::fit(data, map, g, settings, free_initial_state, integrators);
            }
            Site::Input => {
                if data.u().channels() != 1 {
                    return Err(Error::DimensionMismatch {
                        what: "input nonlinearity: inputs u".into(),
                        expected: "1".into(),
                        found: data.u().channels().to_string(),
                    });
                }
                data.u().clone()
            }
            Site::OutputFeedback => data.y().clone(),
            Site::RateFeedback => {
                // Each record starts from rest: y₋₁ = 0 at its first sample.
                let ts = g.sample_time.unwrap_or(1.0);
                let y = data.y();
                let starts = data.record_bounds();
                Signal::from_fn(data.len(), 1, |k, _| {
                    let previous = if starts.contains(&k) {
                        0.0
                    } else {
                        y.get(k - 1, 0)
                    };
                    (y.get(k, 0) - previous) / ts
                })
            }
            Site::Declared { .. } => unreachable!("LinearStructure::new refuses declared sites"),
        };
        let w_hat = Signal::new(1, map.eval_many(&z))?;
        self.estimate_linear(data, &w_hat, g, settings, free_initial_state)
    }

    /// The integrators held fixed for the linear part `g`: the structure's number, or those
    /// of `g` (checked to be there).
    pub(super) fn integrators_of(&self, g: &PolynomialModel) -> Result<usize> {
        match self.integrators {
            None => Ok(integrators::count(&g.den)),
            Some(n) => {
                integrators::deflate(&g.den, n)?;
                Ok(n)
            }
        }
    }

    /// A starting linear part for the data: the best linear approximation from u to y
    /// expanded to the structure's inputs, given the BLA `bla` (one output, the data's inputs).
    /// This is also how a nominal G (u → y) becomes the structure's G: for output feedback
    /// the feedback path is −B; for rate feedback, an input and an output map G is the
    /// nominal itself.
    pub fn initial_from_bla(&self, bla: &PolynomialModel) -> Result<PolynomialModel> {
        match self.site {
            Site::OutputFeedback => {
                if bla.num.is_empty() {
                    return Err(Error::InvalidStructure("the BLA has no inputs".into()));
                }
                let mut g = bla.clone();
                // The feedback path starts as the u path (shared) or as that of the first input.
                let mut bw: Vec<f64> = bla.num[0].iter().map(|x| -x).collect();
                if bw.first().is_some_and(|b| *b != 0.0) {
                    return Err(Error::InvalidStructure(
                        "the BLA has a direct term; estimate it with an input delay nk ≥ 1 for an \
                         output-feedback structure"
                            .into(),
                    ));
                }
                if bw.is_empty() {
                    bw.push(0.0);
                }
                g.num.push(bw);
                Ok(g)
            }
            Site::Input | Site::RateFeedback => {
                if bla.num.len() != 1 {
                    return Err(Error::InvalidStructure(format!(
                        "{} needs a linear part with one input, not {}",
                        self.describe(),
                        bla.num.len()
                    )));
                }
                if self.site == Site::RateFeedback && bla.num[0].first().is_some_and(|b| *b != 0.0)
                {
                    return Err(Error::InvalidStructure(
                        "the linear part has a direct term; rate feedback needs an input delay \
                         nk ≥ 1 (otherwise y_k depends on N(ẏ_k), an algebraic loop)"
                            .into(),
                    ));
                }
                Ok(bla.clone())
            }
            Site::Output => {
                if bla.num.is_empty() {
                    return Err(Error::InvalidStructure(
                        "the linear part has no inputs".into(),
                    ));
                }
                Ok(bla.clone())
            }
            Site::Declared { .. } => unreachable!("LinearStructure::new refuses declared sites"),
        }
    }
}
