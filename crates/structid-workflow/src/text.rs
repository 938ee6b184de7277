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
    // The figures label their values the same way.
    structid_plot::format_value(v)
}
