//! Estimated (or known) static maps: anything that can be evaluated at a point z ∈ ℝᵖ.

use structid_lti::Signal;

/// A static map N: ℝᵖ → ℝ, evaluated at single points or at a batch of points.
///
/// Identification returns one `Interpolant` per nonlinear block; simulation accepts any
/// `Interpolant`, and every closure `Fn(&[f64]) -> f64` is one:
///
/// ```
/// use structid_core::Interpolant;
/// let sat = |z: &[f64]| z[0].clamp(-1.0, 1.0);
/// assert_eq!(sat.eval(&[3.0]), 1.0);
/// ```
pub trait Interpolant: Send + Sync {
    /// Value of the map at one point `z` (length p).
    fn eval(&self, z: &[f64]) -> f64;

    /// Values at every sample of `z` (one point per sample, `z.channels()` = p).
    fn eval_many(&self, z: &Signal) -> Vec<f64> {
        (0..z.len()).map(|k| self.eval(z.sample(k))).collect()
    }

    /// The map as plain data that serde can write ([`crate::stored::StoredMap`]), or `None`
    /// (the default) when it has no stored form, as for a closure. Every map that
    /// identification returns for this crate's dispersions has one, so that an
    /// [`crate::estimate::Estimate`] can be written and read back.
    fn stored(&self) -> Option<crate::stored::StoredMap> {
        None
    }
}

impl<F> Interpolant for F
where
    F: Fn(&[f64]) -> f64 + Send + Sync,
{
    fn eval(&self, z: &[f64]) -> f64 {
        self(z)
    }
}
