//! Numbers as the reports and summaries print them.

/// Four significant digits, scientific notation outside [10⁻³, 10⁵).
///
/// ```
/// use structid_workflow::text::short;
/// assert_eq!(short(0.012345), "0.01235");
/// assert_eq!(short(123.0), "123");
/// assert_eq!(short(1.5e-7), "1.5e-7");
/// ```
pub fn short(v: f64) -> String {
    if !v.is_finite() {
        return v.to_string();
    }
    if v == 0.0 {
        return "0".into();
    }
    let a = v.abs();
    if !(1e-3..1e5).contains(&a) {
        let s = format!("{v:.3e}");
        match s.split_once('e') {
            Some((m, e)) => format!("{}e{e}", m.trim_end_matches('0').trim_end_matches('.')),
            None => s,
        }
    } else {
        let decimals = (3.0 - a.log10().floor()).clamp(0.0, 6.0) as usize;
        let s = format!("{v:.decimals$}");
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s
        }
    }
}
