//! What to try after an error, when the error alone says which workflow applies. The library's
//! errors carry data and name no command; each front end words a [`Remedy`] in its own terms
//! (a `structid` command, a Python function).

use structid_core::Error as CoreError;
use structid_discover::DiscoverError;

use crate::error::WorkflowError;

/// A workflow that handles what another refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum Remedy {
    /// The joint fit by simulation error ([`crate::joint`]): it fits maps in series and
    /// blocks whose input no measured signal gives (latent blocks), which identification by
    /// the dispersion cannot reach.
    JointFit,
    /// Estimating a nominal linear model from the data (output error, with integrators held
    /// for a plant that integrates): the nominal model given is worse than a constant.
    LinearNominal,
}

/// The remedy for `error` or any error in its chain of sources, if one applies.
///
/// ```
/// use structid_workflow::remedy::{Remedy, remedy};
/// let e = structid_core::Error::OutOfReach {
///     blocks: vec!["N".into()],
///     explanation: "block `N` is latent".into(),
/// };
/// assert_eq!(remedy(&e), Some(Remedy::JointFit));
/// // A z that is not measurable for another reason has its own advice in its message.
/// let other = structid_core::Error::NotMeasurable { explanation: "use a zero initial state".into() };
/// assert_eq!(remedy(&other), None);
/// let other = structid_core::Error::Numerical("a NaN".into());
/// assert_eq!(remedy(&other), None);
/// ```
pub fn remedy(error: &(dyn std::error::Error + 'static)) -> Option<Remedy> {
    let mut current = Some(error);
    while let Some(e) = current {
        if let Some(r) = direct(e) {
            return Some(r);
        }
        current = e.source();
    }
    None
}

/// The remedy of `e` itself, looking through the wrappers that forward their inner error
/// transparently (whose `source` skips it).
fn direct(e: &(dyn std::error::Error + 'static)) -> Option<Remedy> {
    if let Some(c) = e.downcast_ref::<CoreError>() {
        return of_core(c);
    }
    if let Some(d) = e.downcast_ref::<DiscoverError>() {
        return of_discover(d);
    }
    if let Some(structid_io::IoError::Core(c)) = e.downcast_ref::<structid_io::IoError>() {
        return of_core(c);
    }
    match e.downcast_ref::<WorkflowError>()? {
        WorkflowError::Core(c) => of_core(c),
        WorkflowError::Discover(d) => of_discover(d),
        WorkflowError::Io(structid_io::IoError::Core(c)) => of_core(c),
        WorkflowError::NotNominal(_) => Some(Remedy::LinearNominal),
        _ => None,
    }
}

fn of_discover(e: &DiscoverError) -> Option<Remedy> {
    match e {
        DiscoverError::PoorNominal { .. } => Some(Remedy::LinearNominal),
        DiscoverError::Core(c) => of_core(c),
        _ => None,
    }
}

fn of_core(e: &CoreError) -> Option<Remedy> {
    match e {
        CoreError::OutOfReach { .. } | CoreError::SeriesMaps { .. } => Some(Remedy::JointFit),
        CoreError::InRecord { source, .. } => of_core(source),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn poor() -> DiscoverError {
        DiscoverError::PoorNominal {
            record: "estimation".into(),
            model_rms: 10.0,
            constant_rms: 0.1,
            scoring: "one free run",
        }
    }

    /// Remedies are found through the wrappers that forward their inner error transparently,
    /// and not invented for errors that have none.
    #[test]
    fn remedies_are_found_through_transparent_wrappers() {
        let series = || CoreError::OutOfReach {
            blocks: vec!["N2".into()],
            explanation: "z of `N2` needs the output of `N1`".into(),
        };
        assert_eq!(remedy(&poor()), Some(Remedy::LinearNominal));
        assert_eq!(
            remedy(&WorkflowError::NotNominal("structure = \"input\"".into())),
            Some(Remedy::LinearNominal)
        );
        assert_eq!(
            remedy(&WorkflowError::Discover(poor())),
            Some(Remedy::LinearNominal)
        );
        assert_eq!(
            remedy(&WorkflowError::Core(series())),
            Some(Remedy::JointFit)
        );
        assert_eq!(
            remedy(&WorkflowError::Io(structid_io::IoError::Core(series()))),
            Some(Remedy::JointFit)
        );
        assert_eq!(
            remedy(&DiscoverError::Core(CoreError::Numerical("NaN".into()))),
            None
        );
        assert_eq!(remedy(&WorkflowError::Request("bad".into())), None);
        let in_record = CoreError::InRecord {
            record: 2,
            source: Box::new(series()),
        };
        assert_eq!(remedy(&in_record), Some(Remedy::JointFit));
    }
}
