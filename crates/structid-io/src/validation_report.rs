//! The JSON of a validation: per output the simulation RMS and fit, the one-step prediction
//! RMS and the residual tests with their verdicts, as `validation.json` lists them. The CLI
//! writes it; a library user gets the same document from a [`ValidationReport`].

use serde_json::{Value, json};
use structid_core::validation::ValidationReport;
use structid_core::validation::residual_tests::CorrelationTest;

use crate::error::IoError;

/// A correlation test as JSON: its lags, values and band, whether it passes and how many lags
/// lie outside the band.
///
/// # Errors
/// [`IoError::Json`] when serialisation fails (it does not for finite values).
pub fn test_json(t: &CorrelationTest) -> Result<Value, IoError> {
    let mut v = serde_json::to_value(t)?;
    if let Value::Object(m) = &mut v {
        m.insert("passes".into(), json!(t.passes()));
        m.insert("lags_outside".into(), json!(t.outside()));
    }
    Ok(v)
}

/// Per output (named by `y_names`): RMS, fit, prediction RMS, whiteness and the
/// cross-correlation with each input (named by `u_names`).
///
/// # Errors
/// [`IoError::Json`] when serialisation fails.
pub fn outputs_json(
    report: &ValidationReport,
    y_names: &[String],
    u_names: &[String],
) -> Result<Vec<Value>, IoError> {
    let mut outputs = Vec::new();
    for (c, name) in y_names.iter().enumerate() {
        let cross = u_names
            .iter()
            .zip(&report.input_correlation[c])
            .map(|(u, t)| {
                let mut v = test_json(t)?;
                if let Value::Object(m) = &mut v {
                    m.insert("input".into(), json!(u));
                }
                Ok(v)
            })
            .collect::<Result<Vec<Value>, IoError>>()?;
        outputs.push(json!({
            "name": name,
            "rms": report.rms[c],
            "fit_percent": report.fit_percent[c],
            "prediction_rms": report.prediction_rms[c],
            "whiteness": test_json(&report.whiteness[c])?,
            "input_correlation": cross,
        }));
    }
    Ok(outputs)
}
