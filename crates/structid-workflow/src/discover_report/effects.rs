//! The reports of an iteration over several effects.

use super::*;

/// A second-block row's map in report.json: its expression, or the number of points of its
/// table (the table itself is in the model file the step's successor writes).
fn map_json(map: &AugmentedMap) -> Value {
    match map {
        AugmentedMap::Expression(x) => json!({ "expression": x }),
        AugmentedMap::Table { z, .. } => json!({ "points": z.len() }),
    }
}

/// The second-block row of a step, or its static reading of a dynamic effect, in a few
/// words; empty without either.
fn second_block_text(step: &structid_discover::discover::Step) -> String {
    match (&step.second_block, &step.dynamic) {
        (Some(row), _) => format!(
            "; re-estimated with a second block {} (validation RMS {} with both)",
            location_text(&step.nominal, row.site),
            rms_text(row.validation_rms)
        ),
        (None, Some(_)) => "; a direction dependence read as this static map beside a second \
                            effect"
            .into(),
        (None, None) => String::new(),
    }
}

/// What one step of an iteration found, in a few words.
pub(super) fn step_effect(r: &Nominal, d: &Discovery) -> String {
    match &d.finding {
        Some(f) => format!("{} {}", f.effect(), location_text(r, f.location)),
        None => d.verdict_kind.describe().to_string(),
    }
}

/// The section of report.md on an iteration over several effects ([`Effects`]): one row per
/// step with what it found, the validation RMS before and after and whether it was adopted,
/// then why the iteration stopped. The report that follows is the last adopted step's (or the
/// first step's when none was adopted).
pub fn effects_markdown(effects: &Effects) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "## Effects, one at a time
"
    );
    let _ = writeln!(
        s,
        "Each step runs discovery on the model the previous adopted step left (its maps fixed \
         in the loop), and is adopted when it cuts the validation RMS by at least {:.0} %. \
         An effect that looks dynamic may be two static ones: its site's static map, named, is \
         built on when the next step finds a second effect that together with it cuts the \
         validation RMS of the dynamic reading by the same share. When a step finds nothing \
         more, or such a pair is not found, the last map is fitted again together with a \
         second block at each other site; a pair that cuts the validation RMS by the same \
         share replaces the map, and the search goes on from there.\n",
        100.0 * effects.settings.min_improvement()
    );
    let _ = writeln!(
        s,
        "| step | found | validation RMS before | after | ratio | adopted |\n|---|---|---|---|---|---|"
    );
    for (i, step) in effects.steps.iter().enumerate() {
        let d = &step.discovery;
        let after = d.finding.as_ref().map(|f| f.augmented.validation_gap.rms);
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {} |",
            i + 1,
            cell(&format!(
                "{}{}",
                step_effect(&step.nominal, d),
                second_block_text(step)
            )),
            rms_text(d.validation_gap.rms),
            after.map(rms_text).unwrap_or_else(|| "—".into()),
            after
                .map(|a| format!("{:.3}", a / d.validation_gap.rms))
                .unwrap_or_else(|| "—".into()),
            if step.adopted { "yes" } else { "no" }
        );
    }
    let rms = effects.validation_rms();
    let _ = writeln!(
        s,
        "\n**Stopped:** {}. {} effect(s) adopted; validation RMS {}.\n",
        effects.stop.describe(&effects.settings),
        effects.findings().len(),
        rms.iter()
            .map(|v| rms_text(*v))
            .collect::<Vec<_>>()
            .join(" → ")
    );
    let _ = writeln!(
        s,
        "The sections below are those of the last adopted step (the first step when none was \
         adopted): its nominal model is the given one with the effects of the steps before it.\n"
    );
    s
}

/// The `effects` member of report.json for an iteration: every step (location, effect,
/// verdict, validation RMS before and after, adopted) and why it stopped.
///
/// # Errors
/// A part that does not serialise.
pub fn effects_json(effects: &Effects) -> Result<Value, serde_json::Error> {
    let steps: Vec<Value> = effects
        .steps
        .iter()
        .enumerate()
        .map(|(i, step)| {
            let d = &step.discovery;
            let f = d.finding.as_ref();
            json!({
                "step": i + 1,
                "verdict_kind": d.verdict_kind,
                "verdict": d.verdict,
                "location": f.map(|f| step.nominal.key(f.location)),
                "effect": f.map(|f| f.effect()),
                "expression": f.and_then(|f| match &f.augmented.map {
                    AugmentedMap::Expression(x) => Some(x.clone()),
                    AugmentedMap::Table { .. } => None,
                }),
                "known_maps": step.nominal.known_maps().iter().map(|k| k.name.clone()).collect::<Vec<_>>(),
                "validation_rms_before": d.validation_gap.rms,
                "validation_rms_after": f.map(|f| f.augmented.validation_gap.rms),
                "adopted": step.adopted,
                "second_block": step.second_block.as_ref().map(|row| json!({
                    "site": step.nominal.key(row.site),
                    "estimation_rms": row.estimation_rms,
                    "validation_rms": row.validation_rms,
                    "first_map": map_json(&row.first_map),
                    "second_map": map_json(&row.second_map),
                    "seconds": row.seconds,
                })),
                "dynamic_verdict": step.dynamic.as_ref().map(|d| d.verdict.clone()),
                "seconds": d.seconds,
            })
        })
        .collect();
    Ok(json!({
        "max_effects": effects.settings.max_effects(),
        "min_improvement": effects.settings.min_improvement(),
        "steps": steps,
        "stop": json_value(&effects.stop)?,
        "stop_text": effects.stop.describe(&effects.settings),
        "effects_found": effects.findings().len(),
        "validation_rms": effects.validation_rms(),
        "seconds": effects.seconds,
    }))
}

/// The lines the run prints for an iteration, before the last step's summary.
pub fn effects_summary(effects: &Effects) -> String {
    let mut s = String::new();
    for (i, step) in effects.steps.iter().enumerate() {
        let d = &step.discovery;
        let _ = writeln!(
            s,
            "step {}: {}{}; validation RMS {} → {}{}",
            i + 1,
            step_effect(&step.nominal, d),
            second_block_text(step),
            rms_text(d.validation_gap.rms),
            d.finding
                .as_ref()
                .map(|f| rms_text(f.augmented.validation_gap.rms))
                .unwrap_or_else(|| "—".into()),
            if step.adopted { " (adopted)" } else { "" }
        );
    }
    let _ = writeln!(
        s,
        "stopped: {} ({} effect(s))",
        effects.stop.describe(&effects.settings),
        effects.findings().len()
    );
    s
}
