//! report.md: a discovery in Markdown, verdict first.

use super::*;

pub(super) fn e(v: f64) -> String {
    structid_discover::discover::rms_text(v)
}

pub(super) fn pct(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.1} %")
    } else {
        "—".into()
    }
}

pub(super) fn g4(v: f64) -> String {
    if !v.is_finite() {
        return e(v);
    }
    if v == 0.0 || (1e-3..1e5).contains(&v.abs()) {
        format!("{v:.4}")
    } else {
        format!("{v:.3e}")
    }
}

/// `|`-safe text for a Markdown table cell.
pub(super) fn cell(s: &str) -> String {
    s.replace('|', "\\|").replace('\n', " ")
}

/// A location as reports name it: its key and what it means.
pub fn location_text(nominal: &Nominal, l: Site) -> String {
    format!("`{}` ({})", nominal.key(l), nominal.describe(l))
}

pub(super) fn gap_table(s: &mut String, estimation: &Gap, validation: &Gap) {
    let _ = writeln!(s, "| | estimation record | validation record |");
    let _ = writeln!(s, "|---|---|---|");
    let _ = writeln!(
        s,
        "| simulation RMS of y − ŷ | {} | {} |",
        e(estimation.rms),
        e(validation.rms)
    );
    if estimation.records.len() > 1 || validation.records.len() > 1 {
        let each = |g: &Gap| {
            g.records
                .iter()
                .enumerate()
                .map(|(i, r)| format!("{}: {}", i + 1, e(r.rms)))
                .collect::<Vec<_>>()
                .join("; ")
        };
        let _ = writeln!(
            s,
            "| simulation RMS per record | {} | {} |",
            each(estimation),
            each(validation)
        );
    }
    let _ = writeln!(
        s,
        "| one-step prediction RMS of ε | {} | {} |",
        e(estimation.prediction_rms),
        e(validation.prediction_rms)
    );
    let _ = writeln!(
        s,
        "| fit | {} | {} |",
        pct(estimation.fit_percent),
        pct(validation.fit_percent)
    );
    let _ = writeln!(
        s,
        "| model-free noise level of ε (MAD of Δε) | {} | {} |",
        e(estimation.noise_std),
        e(validation.noise_std)
    );
    let _ = writeln!(
        s,
        "| noise level of y − ŷ (semivariogram, coloured) | {} | {} |",
        e(estimation.noise.std),
        e(validation.noise.std)
    );
    let _ = writeln!(
        s,
        "| RMS(ε) / MAD-based level | {:.2} | {:.2} |",
        estimation.prediction_rms / estimation.noise_std.max(f64::MIN_POSITIVE),
        validation.prediction_rms / validation.noise_std.max(f64::MIN_POSITIVE)
    );
    let _ = writeln!(
        s,
        "| missing effect | {} | {} |",
        if estimation.missing_effect {
            "yes"
        } else {
            "no"
        },
        if validation.missing_effect {
            "yes"
        } else {
            "no"
        }
    );
    s.push('\n');
    let _ = writeln!(
        s,
        "Portmanteau tests (the family at the 0.1 % level, Bonferroni; ε are the one-step \
         prediction errors):\n"
    );
    let _ = writeln!(
        s,
        "| test | record | statistic | critical value | lags | result |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|");
    for (record, g) in [("estimation", estimation), ("validation", validation)] {
        for t in &g.tests {
            let _ = writeln!(
                s,
                "| {} | {record} | {:.1} | {:.1} | {} | {} |",
                cell(&t.name),
                t.statistic,
                t.critical,
                t.lags,
                if t.passes() { "pass" } else { "**FAIL**" }
            );
        }
    }
    s.push('\n');
    for (record, g) in [("estimation", estimation), ("validation", validation)] {
        let _ = writeln!(s, "- {record} record: {}", g.verdict);
    }
    s.push('\n');
}

pub(super) fn windows_section(s: &mut String, records: [(&str, &Gap, &TimeAxis); 2], band: f64) {
    for (record, g, time) in records {
        if g.windows.is_empty() {
            let _ = writeln!(
                s,
                "- {record} record: none; the moving RMS of the residual stays below {band}·σ̂ = {}.",
                e(band * g.noise_std)
            );
            continue;
        }
        let samples: usize = g.windows.iter().map(|w| w.len()).sum();
        let _ = writeln!(
            s,
            "- {record} record: {} window(s) above {band}·σ̂ = {}, {samples} of {} samples \
             ({:.1} %):\n",
            g.windows.len(),
            e(band * g.noise_std),
            g.residual.len(),
            100.0 * samples as f64 / g.residual.len().max(1) as f64
        );
        if time.is_time {
            let _ = writeln!(s, "  | samples | {} |", time.label);
            let _ = writeln!(s, "  |---|---|");
        } else {
            let _ = writeln!(s, "  | samples |");
            let _ = writeln!(s, "  |---|");
        }
        for w in g.windows.iter().take(MAX_WINDOW_ROWS) {
            if time.is_time {
                let _ = writeln!(
                    s,
                    "  | {}…{} | {} … {} |",
                    w.start,
                    w.end.saturating_sub(1),
                    g4(time.at(w.start)),
                    g4(time.at(w.end.saturating_sub(1)))
                );
            } else {
                let _ = writeln!(s, "  | {}…{} |", w.start, w.end.saturating_sub(1));
            }
        }
        if g.windows.len() > MAX_WINDOW_ROWS {
            let _ = writeln!(
                s,
                "\n  … and {} more (all in report.json).",
                g.windows.len() - MAX_WINDOW_ROWS
            );
        }
        s.push('\n');
    }
}

pub(super) fn regions_section(s: &mut String, estimation: &Gap, validation: &Gap) {
    let _ = writeln!(
        s,
        "For each candidate signal, the region where the residual energy concentrates most \
         (candidates ranked by η², the share of the variance of ε² that quantile bins of the \
         signal explain; lift = energy share / sample share):\n"
    );
    let _ = writeln!(
        s,
        "| record | signal | region | share of samples | share of residual energy | lift | η² |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|");
    for (record, g) in [("estimation", estimation), ("validation", validation)] {
        for r in &g.regions {
            let _ = writeln!(
                s,
                "| {record} | {} | `{}` | {:.1} % | {:.1} % | {:.2} | {:.3} |",
                cell(&r.signal),
                cell(&r.describe()),
                100.0 * r.sample_share,
                100.0 * r.energy_share,
                r.lift,
                r.eta_squared
            );
        }
    }
    s.push('\n');
}

/// The candidate table of the naming step and the rule's decision, as report.md shows them.
pub(super) fn candidate_table(s: &mut String, f: &Finding, alpha: f64) {
    let sel = &f.selection;
    let _ = writeln!(
        s,
        "Candidate table at this location. The best row has the smallest validation RMS; a row \
         is as good as the best unless the paired test of the log ratio of their mean squared \
         validation errors over blocks of the record says it is worse at α = {alpha}; among \
         the rows as good as the best that may be named, the simplest is chosen (a family before the \
         nonparametric map, then fewer parameters):\n"
    );
    let _ = writeln!(
        s,
        "| row | parameters | validation RMS | p (worse than the best) | as good | chosen |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|");
    for (i, row) in f.table.iter().enumerate() {
        let p = match sel.p_worse_than_best.get(i).copied().flatten() {
            _ if i == sel.best => "best".to_string(),
            Some(p) => format!("{p:.3}"),
            None => "—".into(),
        };
        let parameters = match row.form {
            structid_discover::table::Form::Nonparametric { .. } => "—".to_string(),
            _ => row.parameters.to_string(),
        };
        let _ = writeln!(
            s,
            "| {}{} | {parameters} | {} | {p} | {} | {} |",
            cell(&row.label),
            if row.eligible {
                ""
            } else {
                " (may not be named)"
            },
            e(row.validation_rms),
            if sel.as_good.get(i).copied().unwrap_or(false) {
                "yes"
            } else {
                "no"
            },
            if sel.chosen == Some(i) { "**yes**" } else { "" }
        );
    }
    s.push('\n');
}

pub(super) fn parameters_text(fit: &EffectFit) -> String {
    // Derived quantities (a saturation's knee) follow the fitted parameters.
    fit.parameters
        .iter()
        .chain(&fit.derived())
        .map(|p| {
            format!(
                "{} = {} [{}, {}]",
                p.name,
                g4(p.value),
                g4(p.interval.0),
                g4(p.interval.1)
            )
        })
        .collect::<Vec<_>>()
        .join("; ")
}

pub(super) fn nominal_text(mf: &ModelFile) -> String {
    let list = |v: &[f64]| {
        v.iter()
            .map(|x| format_number(*x))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let maps = if mf.blocks.is_empty() {
        String::new()
    } else {
        format!(
            ", with the known map(s) {}",
            mf.blocks
                .iter()
                .map(|b| format!("`{}`", b.name))
                .collect::<Vec<_>>()
                .join(", ")
        )
    };
    match &mf.linear {
        Some(spec) => format!(
            "`[linear]` {}, den = [{}], num = [{}]{maps}",
            spec.structure_name(),
            list(&spec.model.den),
            list(&spec.model.num[0])
        ),
        None => format!("`[lft]` with {} state(s){maps}", mf.lft.dims().states),
    }
}

/// The `--scoring` argument that reproduces `scoring` (empty for a free run, the default).
pub(super) fn scoring_argument(scoring: Scoring) -> String {
    match scoring {
        Scoring::Free => String::new(),
        Scoring::Windowed(w) => format!(" --scoring {}:{}", w.length(), w.init()),
    }
}

pub(super) fn validate_command(
    r: &ReportContext<'_>,
    w: &AugmentedFile,
    scoring: Scoring,
) -> String {
    format!(
        "structid validate --model {} --data {} --out {} --initial-state {}{}",
        r.run.out.join("augmented.toml").display(),
        r.run.validation.files("--data"),
        r.run.out.join("validation").display(),
        initial_state_name(w.initial_state),
        scoring_argument(scoring)
    )
}

pub(super) fn validate_estimate_command(
    r: &ReportContext<'_>,
    w: &AugmentedFile,
    scoring: Scoring,
) -> String {
    format!(
        "structid validate --estimate {} --data {} --out {} --initial-state {}{}",
        r.run.out.join(ESTIMATE_FILE).display(),
        r.run.validation.files("--data"),
        r.run.out.join("validation-estimate").display(),
        initial_state_name(w.initial_state),
        scoring_argument(scoring)
    )
}

pub(super) fn identify_command(r: &ReportContext<'_>, f: &Finding) -> String {
    let beta = f.hypothesis.beta;
    format!(
        "structid identify --model {} --data {} --out {} --beta {} --initial-state {}",
        r.run.out.join("augmented.toml").display(),
        r.run.estimation.files("--data"),
        r.run.out.join("identify").display(),
        format_number(beta),
        initial_state_name(initial_state(f.location).1)
    )
}

/// report.md: the discovery `d` in Markdown, verdict first, then the gap, where it sits, the
/// hypotheses, the effect found and the gap after, the figures and how to reproduce it.
pub fn markdown(d: &Discovery, r: &ReportContext<'_>) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# structid discover\n");
    let _ = writeln!(
        s,
        "**Verdict ({}):** {}\n",
        d.verdict_kind.describe(),
        d.verdict
    );
    let _ = writeln!(
        s,
        "Every simulation is scored by {}{}.\n",
        d.scoring.describe(),
        d.input_noise
            .map(|l| format!(
                "; the nominal model's noise path has an input disturbance of {l:.4e} per unit \
                 of output noise (maximum likelihood: the plant integrates)"
            ))
            .unwrap_or_default()
    );
    let _ = writeln!(
        s,
        "Noise level σ̂ = {} ({}): the smallest semivariogram estimate over the residuals of \
         the models examined, from {}. The naming tolerance (within 1.5·σ̂) and the verdict \
         (a gap larger than the noise) use it.\n",
        e(d.noise.std),
        if d.noise.colour > 0.0 {
            format!("coloured, correlation φ̂^k with φ̂ = {:.2}", d.noise.colour)
        } else {
            "white".to_string()
        },
        d.noise.source
    );
    let _ = writeln!(
        s,
        "Nominal model `{}` ({}); estimation record {} ({} samples), validation record {} \
         ({} samples); {:.1} s.\n",
        r.run.model_path.display(),
        nominal_text(r.run.model),
        r.run.estimation.names(),
        r.run.estimation.data.len(),
        r.run.validation.names(),
        r.run.validation.data.len(),
        d.seconds
    );

    linear_rival_md(&mut s, d);
    let _ = writeln!(s, "## 1. The gap: nominal model against the records\n");
    gap_table(&mut s, &d.estimation_gap, &d.validation_gap);

    let band = r.run.settings.gap().band;
    let _ = writeln!(s, "## 2. Where in time\n");
    let _ = writeln!(
        s,
        "Windows where the moving RMS of the residual exceeds {band}·σ̂:\n"
    );
    windows_section(
        &mut s,
        [
            ("estimation", &d.estimation_gap, &r.run.estimation.time),
            ("validation", &d.validation_gap, &r.run.validation.time),
        ],
        band,
    );

    let _ = writeln!(s, "## 3. Where in operating space\n");
    regions_section(&mut s, &d.estimation_gap, &d.validation_gap);

    if d.hypotheses.is_empty() {
        let _ = writeln!(
            s,
            "No hypotheses were tried: the nominal model's residual is within {}× its noise \
             level and passes every test on both records.\n",
            r.run.settings.gap().noise_ratio
        );
    } else {
        if d.finding.is_none() {
            let _ = writeln!(
                s,
                "A test of the nominal model's gap failed (section 1), so every candidate \
                 location was tried; none reduces the validation RMS enough to confirm a \
                 missing effect (see the verdict).\n"
            );
        }
        let _ = writeln!(s, "## 4. Where in the structure: hypotheses\n");
        let _ = writeln!(
            s,
            "One unknown static block N at each candidate location, identified on the \
             estimation record (Fourier kernel plus polynomial trend, β by marginal likelihood) \
             and ranked by the simulation RMS on the validation record:\n"
        );
        let _ = writeln!(
            s,
            "| rank | location | dispersion | β | σ | estimation RMS | validation RMS | seconds | failure |"
        );
        let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|");
        for (i, h) in d.hypotheses.iter().enumerate() {
            let _ = writeln!(
                s,
                "| {} | {} | {} | {} | {} | {} | {} | {:.2} | {} |",
                i + 1,
                cell(&location_text(r.run.nominal, h.location)),
                cell(&h.dispersion),
                e(h.beta),
                h.sigma.map(g4).unwrap_or_else(|| "fixed".into()),
                e(h.estimation_rms),
                e(h.validation_rms),
                h.seconds,
                h.failure.as_deref().map(cell).unwrap_or_default()
            );
        }
        s.push('\n');
    }

    if let Some(f) = &d.finding {
        finding_md(&mut s, d, r, f);
    } else if !d.hypotheses.is_empty() && d.hypotheses.iter().all(|h| h.failure.is_some()) {
        let _ = writeln!(
            s,
            "No hypothesis could be identified and simulated, so no augmented model was written.\n"
        );
    }

    let _ = writeln!(s, "## Figures\n");
    for (file, what) in r.figures {
        let _ = writeln!(s, "- [{file}]({file}): {what}");
    }
    s.push('\n');
    let _ = writeln!(s, "## Reproduce\n");
    let _ = writeln!(s, "```sh\n{}", r.run.command);
    if let (Some(f), Some(w)) = (&d.finding, r.augmented) {
        let _ = writeln!(s, "{}", validate_command(r, w, d.scoring));
        let _ = writeln!(s, "{}", validate_estimate_command(r, w, d.scoring));
        let _ = writeln!(s, "{}", identify_command(r, f));
        let _ = writeln!(s, "```\n");
        let _ = writeln!(
            s,
            "The first line reruns the discovery. The second simulates `augmented.toml` with its \
             map on the validation record (initial state {}, no settling samples): its RMS is \
             that of the gap after ({}). The third validates the stored estimate \
             `{ESTIMATE_FILE}` alike, without the model file or the estimation record. The \
             fourth re-estimates N nonparametrically with the hypothesis' dispersion and β.",
            initial_state_name(w.initial_state),
            e(f.augmented.validation_gap.rms)
        );
    } else {
        let _ = writeln!(s, "```");
    }
    s
}

/// G alone with one more mode, the linear model a finding must beat, when it was fitted.
pub(super) fn linear_rival_md(s: &mut String, d: &Discovery) {
    let Some(r) = &d.linear_rival else {
        return;
    };
    let test = match &r.comparison {
        Some(c) => format!(
            "the finding against it, paired over {} blocks of the validation record: mean \
             ln(MSE ratio) {:+.3}, p = {:.3} that the finding is better",
            c.blocks,
            c.mean_log_ratio,
            1.0 - c.p_worse
        ),
        None => match r.leaves_direction_effect {
            Some(true) => format!(
                "its own residual keeps the dynamic finding's direction effect (|t| > {} at \
                 the finding's block)",
                structid_discover::hysteresis::DIRECTION_T
            ),
            Some(false) => "its own residual leaves no direction effect at the dynamic \
                            finding's block"
                .to_string(),
            None => {
                "no paired test (no finding, or one that cannot be tested against it)".to_string()
            }
        },
    };
    let _ = writeln!(
        s,
        "**G alone with one more mode** (the linear model a finding must beat): F = {:?}, \
         B = {:?}; validation RMS {}; {test} → {}.\n",
        r.g.den,
        r.g.num,
        e(r.validation_rms),
        if r.explains {
            "it closes the gap: the linear model was wrong"
        } else {
            "it does not explain the gap"
        }
    );
}

/// Sections 5 and 6 of the report: what the finding is, and the augmented model's gap.
pub(super) fn finding_md(s: &mut String, d: &Discovery, r: &ReportContext<'_>, f: &Finding) {
    if let Some(n) = &f.nominal_refinement {
        let _ = writeln!(
            s,
            "**G re-estimated with the map in the loop** ({}): F = {:?}, B = {:?} → F = {:?}, \
             B = {:?}; validation RMS {} → {}.\n",
            if n.adopted {
                "kept"
            } else {
                "not kept: no better"
            },
            n.before.den,
            n.before.num,
            n.after.den,
            n.after.num,
            e(n.validation_rms_before),
            e(n.validation_rms_after)
        );
    }
    let _ = writeln!(s, "## 5. What it is\n");
    let kind = match &f.classification {
        Classification::Named(_) => "named",
        Classification::Unnamed => "unnamed",
        Classification::Dynamic => "dynamic",
        Classification::TimeVarying(_) => "time-varying",
    };
    let _ = writeln!(
        s,
        "**{}** ({kind}) {}.\n",
        f.effect(),
        r.run.nominal.describe(f.location)
    );
    if let Some(h) = &f.input_hysteresis {
        let _ = writeln!(
            s,
            "- {}: w = u + λ·s, s_k = clamp(s_(k−1) + u_k − u_(k−1), −c, c), y = G·w, with G \
             re-estimated behind it (F = {:?}, B = {:?}): validation RMS {}, against {} for G \
             re-estimated alone and {} for the static approximation below. The augmented \
             model files hold that static approximation; a model file cannot declare the \
             hysteresis.\n",
            h.describe(),
            h.g.den,
            h.g.num,
            e(h.validation_rms),
            e(h.without_hysteresis_rms),
            e(f.augmented.validation_gap.rms)
        );
    }
    if let Classification::Named(fit) = &f.classification {
        let _ = writeln!(s, "- map: `{}`", fit.expression);
        let _ = writeln!(s, "- parameters (95 % intervals): {}", parameters_text(fit));
    }
    let _ = writeln!(
        s,
        "- named from the {} estimate; its validation RMS {}{}",
        f.estimator,
        e(f.nonparametric_rms),
        f.total_variation_rms
            .map(|v| format!(" (total variation tried: {})", e(v)))
            .unwrap_or_default()
    );
    let _ = writeln!(
        s,
        "- equivalent locations (the same model for a linear G): {}",
        if f.equivalent_locations.len() > 1 {
            f.equivalent_locations
                .iter()
                .map(|l| format!("`{}`", r.run.nominal.key(*l)))
                .collect::<Vec<_>>()
                .join(", ")
        } else {
            format!("none besides `{}`", r.run.nominal.key(f.location))
        }
    );
    s.push('\n');
    candidate_table(s, f, r.run.settings.significance());
    if let Some(st) = &f.stationarity {
        let _ = writeln!(s, "Stationarity: {}.\n", st.describe());
    }
    families_md(s, f);
    let _ = writeln!(
        s,
        "Direction test (residual deconvolved to the block's output, split by the direction of \
         z within z-bins): the direction explains {:.1} % of its energy, t = {:.2}, {} samples; \
         threshold {:.0} % → {}.\n",
        100.0 * f.direction.explained,
        f.direction.t_statistic,
        f.direction.samples,
        100.0 * r.run.settings.hysteresis_threshold(),
        if f.direction.dynamic {
            "dynamic (hysteresis or backlash suspected)"
        } else {
            "static"
        }
    );
    if !f.remarks.is_empty() {
        let _ = writeln!(s, "Remarks:\n");
        for m in &f.remarks {
            let _ = writeln!(s, "- {m}");
        }
        s.push('\n');
    }
    gap_after_md(s, d, r, f);
}

/// The families fitted to the finding's points, best BIC first.
pub(super) fn families_md(s: &mut String, f: &Finding) {
    let _ = writeln!(
        s,
        "Families fitted to the points (z_k, ŵ_k), best BIC first (validation RMS for those \
         refined and simulated):\n"
    );
    let _ = writeln!(
        s,
        "| rank | family | parameters (95 % interval) | RMS | BIC | validation RMS |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|");
    for (i, fit) in f.naming.ranked.iter().enumerate() {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {:.1} | {} |",
            i + 1,
            cell(&fit.effect.name()),
            cell(&parameters_text(fit)),
            e(fit.rms),
            fit.bic,
            f.family_rms
                .get(i)
                .copied()
                .flatten()
                .map(e)
                .unwrap_or_else(|| "—".into())
        );
    }
    s.push('\n');
}

/// The validation gap of the nominal → the augmented model, as the summary and the report
/// both give it: the RMS with the shrink factor, and the fit in percent.
pub(super) fn validation_change(d: &Discovery, f: &Finding) -> (String, String) {
    let after = &f.augmented.validation_gap;
    (
        format!(
            "{} → {} ({})",
            e(d.validation_gap.rms),
            e(after.rms),
            structid_discover::gap::shrink_text(f.shrink, 2)
        ),
        format!(
            "{} → {}",
            pct(d.validation_gap.fit_percent),
            pct(after.fit_percent)
        ),
    )
}

/// Section 6 of the report: the augmented model's gap and the shrink.
pub(super) fn gap_after_md(s: &mut String, d: &Discovery, r: &ReportContext<'_>, f: &Finding) {
    let _ = writeln!(s, "## 6. The gap after: augmented model\n");
    let _ = writeln!(
        s,
        "The nominal model with N {} ({}).\n",
        r.run.nominal.describe(f.location),
        match &f.augmented.map {
            AugmentedMap::Expression(x) => format!("N(z) = `{x}`"),
            AugmentedMap::Table { z, .. } => format!(
                "N as a table of {} points in `{}`",
                z.len(),
                table_name(r, f)
            ),
        }
    );
    gap_table(s, &f.augmented.estimation_gap, &f.augmented.validation_gap);
    let (rms, fit) = validation_change(d, f);
    let _ = writeln!(s, "**Shrink factor:** validation RMS {rms}; fit {fit}.\n");
    if d.validation_gap.records.len() > 1 {
        let per: Vec<String> = d
            .validation_gap
            .records
            .iter()
            .zip(&f.augmented.validation_gap.records)
            .enumerate()
            .map(|(i, (a, b))| {
                format!(
                    "record {} ({}): {} → {} ({:.2}×)",
                    i + 1,
                    r.run
                        .validation
                        .paths
                        .get(i)
                        .map(|p| format!("`{}`", p.display()))
                        .unwrap_or_default(),
                    e(a.rms),
                    e(b.rms),
                    a.rms / b.rms
                )
            })
            .collect();
        let _ = writeln!(
            s,
            "Per validation record (the shrink above pools their scored samples): {}.\n",
            per.join("; ")
        );
    }
    if let Some(w) = r.augmented {
        let _ = writeln!(
            s,
            "The augmented model is `augmented.toml` ({}{}; block `{}` with the map as its \
             `truth` and the hypothesis' dispersion, so that `structid identify` can re-estimate \
             it).\n",
            w.form,
            w.table
                .as_ref()
                .map(|t| format!(", table `{}`", t.name))
                .unwrap_or_default(),
            block_name(f)
        );
    }
}

/// The name of the finding's block in the augmented model (`N`, or `N2`, … when the nominal
/// model already had maps).
pub(super) fn block_name(f: &Finding) -> &str {
    f.augmented
        .model
        .blocks()
        .first()
        .map_or(BLOCK, |b| b.name.as_str())
}

/// The file of the finding's table as the augmented file names it.
pub(super) fn table_name(r: &ReportContext<'_>, f: &Finding) -> String {
    r.augmented
        .and_then(|w| w.table.as_ref())
        .map(|t| t.name.clone())
        .unwrap_or_else(|| structid_discover::augmented::table_file_name(block_name(f)))
}
