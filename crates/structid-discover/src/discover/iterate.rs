//! Several effects, one at a time: discover, adopt the augmented model as the next nominal
//! model, and discover again.

use std::time::Instant;

use structid_core::{Data, Error, Result};

use crate::hypotheses::Nominal;

use super::second_block::{SecondBlock, second_blocks};
use super::{Classification, DiscoverSettings, Discovery, Finding, Verdict, discover};

/// Settings of [`discover_effects`].
#[derive(Clone, Debug, PartialEq)]
pub struct EffectsSettings {
    max_effects: usize,
    min_improvement: f64,
}

impl Default for EffectsSettings {
    /// At most three effects; a step must cut the validation RMS by at least 10 %.
    fn default() -> Self {
        Self {
            max_effects: 3,
            min_improvement: 0.10,
        }
    }
}

impl EffectsSettings {
    /// At most `max_effects` adopted steps (≥ 1; a step that is run again after a second-block
    /// row, or that is not adopted, does not count).
    ///
    /// ```
    /// use structid_discover::discover::EffectsSettings;
    /// assert_eq!(EffectsSettings::default().with_max_effects(2).unwrap().max_effects(), 2);
    /// assert!(EffectsSettings::default().with_max_effects(0).is_err());
    /// ```
    pub fn with_max_effects(mut self, max_effects: usize) -> Result<Self> {
        if max_effects == 0 {
            return Err(Error::InvalidParameter {
                name: "max_effects".into(),
                value: 0.0,
                reason: "at least one effect must be looked for".into(),
            });
        }
        self.max_effects = max_effects;
        Ok(self)
    }

    /// The share by which a step must cut the validation RMS of the model it started from to
    /// be adopted, in [0, 1): a step whose augmented model has validation RMS above
    /// (1 − `share`) × its nominal model's is not adopted, and the iteration stops.
    pub fn with_min_improvement(mut self, share: f64) -> Result<Self> {
        if !(share.is_finite() && (0.0..1.0).contains(&share)) {
            return Err(Error::InvalidParameter {
                name: "min_improvement".into(),
                value: share,
                reason: "must be a share in [0, 1)".into(),
            });
        }
        self.min_improvement = share;
        Ok(self)
    }

    /// The most adopted steps.
    pub fn max_effects(&self) -> usize {
        self.max_effects
    }

    /// The share a step must cut the validation RMS by.
    pub fn min_improvement(&self) -> f64 {
        self.min_improvement
    }
}

/// Why [`discover_effects`] stopped.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
#[serde(rename_all = "kebab-case", tag = "reason")]
pub enum StopReason {
    /// The last step's verdict: the gap of the model it started from is noise.
    NoMissingEffect,
    /// The last step's verdict: the gap is larger than the noise, but no single static block
    /// at the candidate locations explains it.
    Unexplained,
    /// The last step found a dynamic effect (hysteresis or backlash suspected): its static
    /// approximation is not adopted as a model to build on.
    Dynamic,
    /// The last step found a map that changes over the record (time-varying): its static
    /// approximation is not built on.
    TimeVarying,
    /// The last step's augmented model cut the validation RMS by less than the required share
    /// ([`EffectsSettings::with_min_improvement`]); `ratio` is its RMS over the RMS it started from.
    NoImprovement {
        /// Validation RMS after / before the step.
        ratio: f64,
    },
    /// [`EffectsSettings::max_effects`] steps were adopted.
    MaxEffects,
    /// The linear model was wrong ([`Verdict::LinearModel`]: the last step's block is a gain,
    /// or G with one more mode closes the gap); G is to be re-estimated before looking
    /// further.
    LinearModel,
}

impl StopReason {
    /// The reason in words.
    pub fn describe(&self, settings: &EffectsSettings) -> String {
        match self {
            StopReason::NoMissingEffect => "the remaining gap is noise (no missing effect)".into(),
            StopReason::Unexplained => {
                "the remaining gap is larger than the noise, but no single static block at the \
                 candidate locations explains it"
                    .into()
            }
            StopReason::Dynamic => "the last effect found is dynamic (hysteresis or backlash \
                                    suspected); its static approximation is not built on"
                .into(),
            StopReason::TimeVarying => "the last effect found changes over the record \
                                        (time-varying); its static approximation is not built on"
                .into(),
            StopReason::NoImprovement { ratio } => format!(
                "the last step cut the validation RMS by {:.1} %, less than the {:.0} % required",
                100.0 * (1.0 - ratio),
                100.0 * settings.min_improvement
            ),
            StopReason::LinearModel => "the linear model was wrong (the last step's block is a \
                                        gain, or G with one more mode closes the gap): \
                                        re-estimate it before looking further"
                .into(),
            StopReason::MaxEffects => format!(
                "{} effect(s) were found, the most allowed",
                settings.max_effects
            ),
        }
    }
}

/// One step of [`discover_effects`].
#[derive(Clone, Debug)]
pub struct Step {
    /// The nominal model the step started from (the given one, then the augmented model of
    /// the last adopted step).
    pub nominal: Nominal,
    /// What discovery found on it.
    pub discovery: Discovery,
    /// Whether its finding was adopted as the next nominal model (and counts as an effect).
    pub adopted: bool,
    /// The second-block row ([`SecondBlock`]) that re-estimated this step's map before the
    /// next step, when one cut the validation RMS of the step's augmented model by the
    /// required share: the map the next step builds on is that row's first map.
    pub second_block: Option<SecondBlock>,
    /// When the step's effect looked dynamic and its static reading was built on instead
    /// (see [`discover_effects`]): the dynamic discovery, which [`Step::discovery`] (the
    /// static reading) replaced. It is put back when the next step does not confirm a second
    /// effect.
    pub dynamic: Option<Discovery>,
}

impl Step {
    /// The step's finding as the next step builds on it: as found, or with its map replaced
    /// by the first map of its second-block row ([`Step::second_block`]) and a remark that
    /// says so (its named family, fitted before the row, is dropped). `None` when the step
    /// found nothing.
    pub fn adopted_finding(&self) -> Option<Finding> {
        let mut f = self.discovery.finding.clone()?;
        if let Some(row) = &self.second_block {
            f.augmented.map = row.first_map.clone();
            f.augmented.fit = None;
            f.remarks.push(format!(
                "the map was re-estimated together with a second block {} (validation RMS {} \
                 with both blocks, against {} with this one alone): the next step builds on \
                 the re-estimated map",
                row.site.describe(),
                super::rms_text(row.validation_rms),
                super::rms_text(f.augmented.validation_gap.rms)
            ));
        }
        Some(f)
    }
}

/// Everything [`discover_effects`] found.
#[derive(Clone, Debug)]
pub struct Effects {
    /// Every step, in order (the last one may not be adopted).
    pub steps: Vec<Step>,
    /// Why the iteration stopped.
    pub stop: StopReason,
    /// The settings it ran with.
    pub settings: EffectsSettings,
    /// Wall-clock seconds.
    pub seconds: f64,
}

impl Effects {
    /// The adopted steps' findings, in order: the effects found.
    pub fn findings(&self) -> Vec<&Finding> {
        self.steps
            .iter()
            .filter(|s| s.adopted)
            .filter_map(|s| s.discovery.finding.as_ref())
            .collect()
    }

    /// The last adopted finding: its augmented model carries every effect found.
    pub fn last(&self) -> Option<&Finding> {
        self.findings().last().copied()
    }

    /// The validation RMS of the given nominal model, then after each adopted step.
    pub fn validation_rms(&self) -> Vec<f64> {
        let mut out: Vec<f64> = self
            .steps
            .first()
            .map(|s| s.discovery.validation_gap.rms)
            .into_iter()
            .collect();
        out.extend(
            self.findings()
                .iter()
                .map(|f| f.augmented.validation_gap.rms),
        );
        out
    }
}

/// Finds several effects one at a time: runs [`discover`] on `nominal`, adopts the finding's
/// augmented model (every map found so far fixed inside it, [`super::Augmented::as_nominal`])
/// as the next nominal model, and repeats.
///
/// A map found while another effect is unmodelled carries that effect's bias, so a step
/// that finds nothing more is not yet the end: the last adopted map and a second block at
/// each other site are fitted jointly ([`SecondBlock`]), and when the best of those rows cuts
/// the validation RMS of the adopted model by [`EffectsSettings::min_improvement`], the
/// adopted map is replaced by its joint re-estimate and the step is run again from there.
/// A step whose effect looks dynamic may instead be two static effects, the direction
/// dependence being what the second leaves beside the first (friction beside a spring). Its
/// *static reading* ([`discover`] at the same site with the direction test set aside) is
/// built on when it names a family there, and the next step must then find a second effect at
/// another site that, with the first, cuts the validation RMS of the dynamic step's best model
/// (its static approximation, the model it started from, or a hysteresis fitted at the input)
/// by [`EffectsSettings::min_improvement`]. Without a named static reading, the second-block
/// rows decide: if a static second block explains the direction dependence as well (it cuts
/// the same reference by the same share), the step's static approximation is built on;
/// otherwise the iteration stops at the dynamic effect. A static reading and a row are each
/// validated as a pair: when the next step does not find the second effect, the step goes
/// back to what it was (a dynamic step is then not adopted) and the iteration stops.
///
/// It stops when a step's verdict is "no missing effect", "unexplained" or "the linear model
/// was wrong", when a step finds a dynamic or a time-varying effect, when a step's augmented
/// model cuts the validation RMS of the model it started from by less than
/// [`EffectsSettings::min_improvement`] (10 % by default; that step is reported but not
/// adopted), in each case unless a static reading or a second-block row carries it on as
/// above, or after
/// [`EffectsSettings::max_effects`] adopted steps. Every step after the first is scored as the
/// first was (the scoring the first step resolved), so that their RMS values compare.
///
/// Errors: those of [`discover`] on the first step. A later step that fails stops the
/// iteration with its error, unless it was to confirm a pair: the pair is then not
/// confirmed, and a dynamic step goes back to its dynamic verdict (its rows still tried after
/// a static reading), where the iteration stops.
pub fn discover_effects(
    nominal: &Nominal,
    est: &Data,
    val: &Data,
    settings: &DiscoverSettings,
    effects: &EffectsSettings,
) -> crate::error::Result<Effects> {
    let t0 = Instant::now();
    let mut steps: Vec<Step> = Vec::new();
    let mut current = nominal.clone();
    let mut run = Run {
        est,
        val,
        settings: settings.clone(),
        effects,
    };
    // The step whose map a second-block row replaced, or whose dynamic discovery a static
    // reading replaced, until the next step confirms it by adopting an effect: a row, or a
    // reading, stands as a pair, not as its first map alone.
    let mut unconfirmed: Option<usize> = None;
    let stop = loop {
        let d = match discover(&current, est, val, &run.settings) {
            Ok(d) => d,
            Err(e) => {
                let Some(i) = unconfirmed.take() else {
                    return Err(e);
                };
                // The step that was to confirm a pair failed: the pair is not confirmed.
                match unconfirm(&mut steps[i], &run) {
                    Unconfirmed::Retry(next) => {
                        unconfirmed = Some(i);
                        current = *next;
                        continue;
                    }
                    Unconfirmed::Stop(Some(reason)) => break reason,
                    Unconfirmed::Stop(None) => return Err(e),
                }
            }
        };
        run.settings.scoring = Some(d.scoring);
        let adopted_so_far = steps.iter().filter(|s| s.adopted).count();
        let more = adopted_so_far + 1 < effects.max_effects;
        let mut step = Step {
            nominal: current.clone(),
            discovery: d,
            adopted: false,
            second_block: None,
            dynamic: None,
        };
        let mut verdict = judge(&step, effects);
        if verdict.is_ok()
            && let Some(i) = unconfirmed
            && !confirms_static_reading(&steps[i], &step, effects)
        {
            verdict = Err(StopReason::Dynamic);
        }
        if verdict.is_ok() {
            unconfirmed = None;
        } else if let Some(i) = unconfirmed.take() {
            steps.push(step);
            match unconfirm(&mut steps[i], &run) {
                Unconfirmed::Retry(next) => {
                    unconfirmed = Some(i);
                    current = *next;
                    continue;
                }
                Unconfirmed::Stop(reason) => {
                    break reason.unwrap_or_else(|| verdict.expect_err("not adopted"));
                }
            }
        }
        match verdict {
            Ok(()) => step.adopted = true,
            Err(StopReason::Dynamic) if more => {
                // Is the direction dependence a second, static effect?
                let next = with_static_reading(&mut step, &run)
                    .or_else(|| with_second_block(&mut step, &run));
                let Some(next) = next else {
                    steps.push(step);
                    break StopReason::Dynamic;
                };
                unconfirmed = Some(steps.len());
                steps.push(step);
                current = next;
                continue;
            }
            Err(reason) => {
                // Did the last adopted map hide the next effect?
                let last = steps
                    .iter()
                    .rposition(|s| s.adopted && s.second_block.is_none());
                let retry = last.and_then(|i| {
                    retry_with_second_block(&mut steps[i], &run).map(|next| (i, next))
                });
                steps.push(step);
                match retry {
                    Some((i, next)) => {
                        unconfirmed = Some(i);
                        current = next;
                        continue;
                    }
                    None => break reason,
                }
            }
        }
        let next = step
            .adopted_finding()
            .expect("an adopted step has a finding")
            .augmented
            .as_nominal(&current)?;
        steps.push(step);
        if adopted_so_far + 1 >= effects.max_effects {
            break StopReason::MaxEffects;
        }
        current = next;
    };
    Ok(Effects {
        steps,
        stop,
        settings: effects.clone(),
        seconds: t0.elapsed().as_secs_f64(),
    })
}

/// What every step of the iteration runs with: the records, the discovery settings (with
/// the scoring the first step resolved, once it has) and the iteration's own settings.
struct Run<'a> {
    est: &'a Data,
    val: &'a Data,
    settings: DiscoverSettings,
    effects: &'a EffectsSettings,
}

/// What becomes of a step whose pair (its static reading, or its second-block row) the next
/// step did not confirm.
enum Unconfirmed {
    /// The step was put back and now carries a second-block row: run again from this nominal
    /// model, which the next step must confirm in turn.
    Retry(Box<Nominal>),
    /// The step was put back; the iteration stops, for this reason when it is the step's own
    /// (`None`: the reason is the next step's).
    Stop(Option<StopReason>),
}

/// Puts `step` back as it was before its unconfirmed pair. A row is dropped (a dynamic step
/// is then not adopted). A static reading gives way to the dynamic discovery it replaced,
/// which the second-block rows then decide, as they decide a dynamic step without a reading.
fn unconfirm(step: &mut Step, run: &Run) -> Unconfirmed {
    if step.second_block.take().is_some() {
        let dynamic = judge(step, run.effects) == Err(StopReason::Dynamic);
        step.adopted &= !dynamic;
        return Unconfirmed::Stop(dynamic.then_some(StopReason::Dynamic));
    }
    let Some(dynamic) = step.dynamic.take() else {
        return Unconfirmed::Stop(None);
    };
    step.discovery = dynamic;
    step.adopted = false;
    match with_second_block(step, run) {
        Some(next) => Unconfirmed::Retry(Box::new(next)),
        None => Unconfirmed::Stop(Some(StopReason::Dynamic)),
    }
}

/// Puts a dynamic step's static reading ([`static_reading`]) in place of its discovery, keeps
/// the dynamic discovery in [`Step::dynamic`] and adopts the step; returns the nominal model
/// the next step runs from, or `None` (the step unchanged) without a reading. The reading is
/// the first of a pair: it is adopted without a gain of its own, and the next step confirms
/// the pair ([`confirms_static_reading`]).
fn with_static_reading(step: &mut Step, run: &Run) -> Option<Nominal> {
    let reading = static_reading(&step.nominal, step, run)?;
    let next = reading
        .finding
        .as_ref()?
        .augmented
        .as_nominal(&step.nominal)
        .ok()?;
    step.dynamic = Some(std::mem::replace(&mut step.discovery, reading));
    step.adopted = true;
    Some(next)
}

/// Sets the best second-block row of a dynamic step, when one cuts the validation RMS of
/// its static approximation (or of the model it started from, when lower) by the required
/// share, and adopts the step; returns the nominal model the next step runs from (the step's
/// map replaced by the row's first map), or `None` (the step unchanged).
fn with_second_block(step: &mut Step, run: &Run) -> Option<Nominal> {
    let f = step.discovery.finding.as_ref()?;
    let reference = f
        .augmented
        .validation_gap
        .rms
        .min(step.discovery.validation_gap.rms);
    let next = with_row(step, reference, run)?;
    step.adopted = true;
    Some(next)
}

/// The static reading of a step whose effect looked dynamic: [`discover`] on the same
/// nominal model at the dynamic finding's site alone, with the direction test set aside (its
/// threshold at 1: no share of the residual exceeds it), when it names a family there. A
/// direction dependence at one site is also what a second static effect leaves that the
/// first map cannot carry (friction beside a spring); the reading is the first map of that
/// explanation, and the next step must find the second ([`confirms_static_reading`]).
fn static_reading(nominal: &Nominal, step: &Step, run: &Run) -> Option<Discovery> {
    let site = step.discovery.finding.as_ref()?.location;
    let mut at_site = run.settings.clone();
    at_site.locations = Some(vec![site]);
    at_site.hysteresis_threshold = 1.0;
    let mut d = discover(nominal, run.est, run.val, &at_site).ok()?;
    if let Some(f) = d.finding.as_mut() {
        f.remarks.push(
            "the direction dependence first found here (hysteresis or backlash suspected) was \
             read as a static map here and a second static effect elsewhere, which the next \
             step found: together they validate better than the dynamic reading"
                .into(),
        );
    }
    let named = d
        .finding
        .as_ref()
        .is_some_and(|f| matches!(f.classification, Classification::Named(_)));
    (d.verdict_kind == Verdict::MissingEffect && named).then_some(d)
}

/// Whether `next`, adopted on top of a static reading (`reading`), confirms it: the two
/// static maps together cut the validation RMS of the dynamic step's best model (its static
/// approximation, the model it started from, or the hysteresis fitted at the input) by the
/// required share. A step that was not a static reading, or whose pair under test is a
/// second-block row, is confirmed by being adopted.
fn confirms_static_reading(reading: &Step, next: &Step, effects: &EffectsSettings) -> bool {
    let Some(dynamic) = reading
        .dynamic
        .as_ref()
        .filter(|_| reading.second_block.is_none())
    else {
        return true;
    };
    let Some(f) = &dynamic.finding else {
        return false;
    };
    let reference = f
        .augmented
        .validation_gap
        .rms
        .min(dynamic.validation_gap.rms)
        .min(
            f.input_hysteresis
                .as_ref()
                .map_or(f64::INFINITY, |h| h.validation_rms),
        );
    next.discovery.finding.as_ref().is_some_and(|g| {
        g.location != f.location
            && g.augmented.validation_gap.rms <= (1.0 - effects.min_improvement) * reference
    })
}

/// Whether a step's finding is adopted as it stands, or why not.
fn judge(step: &Step, effects: &EffectsSettings) -> std::result::Result<(), StopReason> {
    let d = &step.discovery;
    match (&d.verdict_kind, &d.finding) {
        (Verdict::NoMissingEffect, _) => Err(StopReason::NoMissingEffect),
        (Verdict::LinearModel, _) => Err(StopReason::LinearModel),
        (Verdict::Unexplained, _) | (Verdict::MissingEffect, None) => Err(StopReason::Unexplained),
        (Verdict::MissingEffect, Some(f)) => {
            let ratio = f.augmented.validation_gap.rms / d.validation_gap.rms;
            if matches!(f.classification, Classification::Dynamic) {
                Err(StopReason::Dynamic)
            } else if matches!(f.classification, Classification::TimeVarying(_)) {
                Err(StopReason::TimeVarying)
            } else if ratio.is_nan() || ratio > 1.0 - effects.min_improvement {
                Err(StopReason::NoImprovement { ratio })
            } else {
                Ok(())
            }
        }
    }
}

/// Sets the second-block row of an adopted step that hid the next effect, when one beats it,
/// and returns the nominal model the step is run again from (the step's map replaced by the
/// row's first map).
fn retry_with_second_block(last: &mut Step, run: &Run) -> Option<Nominal> {
    let reference = last
        .discovery
        .finding
        .as_ref()?
        .augmented
        .validation_gap
        .rms;
    with_row(last, reference, run)
}

/// Sets the best second-block row of `step`'s finding when it cuts `reference` by the
/// required share, and returns the nominal model with the row's first map in place of the
/// step's; `None` (no row set) when no row does or that model cannot be built.
fn with_row(step: &mut Step, reference: f64, run: &Run) -> Option<Nominal> {
    let f = step.discovery.finding.as_ref()?;
    let row = best_second_block(&step.nominal, f, reference, run)?;
    step.second_block = Some(row);
    let next = step.adopted_finding()?.augmented.as_nominal(&step.nominal);
    if next.is_err() {
        step.second_block = None;
    }
    next.ok()
}

/// The second-block row of `first` (found on `nominal`) with the lowest validation RMS, when
/// it cuts `reference` (the validation RMS of the model to improve on) by the required share.
fn best_second_block(
    nominal: &Nominal,
    first: &Finding,
    reference: f64,
    run: &Run,
) -> Option<SecondBlock> {
    second_blocks(nominal, first, run.est, run.val, &run.settings)
        .into_iter()
        .filter(|r| r.validation_rms <= (1.0 - run.effects.min_improvement) * reference)
        .min_by(|a, b| a.validation_rms.total_cmp(&b.validation_rms))
}
