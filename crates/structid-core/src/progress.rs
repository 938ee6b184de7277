//! Observers of long work: how far a selection, a refinement or a discovery has got.
//!
//! The library draws nothing. A [`Progress`] in the settings of a long computation is called
//! after each unit of its work with the units done and, when known, their total; the
//! command-line tool connects it to a progress bar on a terminal. Without one (the default)
//! nothing is called.

use std::sync::Arc;

/// The callback of a [`Progress`]: `(done, total)`, `total` `None` when the amount of work is
/// not known in advance (a search that stops when it has converged).
pub type ProgressFn = dyn Fn(u64, Option<u64>) + Send + Sync;

/// An optional observer of long work; see the [module documentation](self).
///
/// Settings that hold one compare equal whatever their observers: an observer does not change
/// what is computed.
///
/// ```
/// use std::sync::atomic::{AtomicU64, Ordering};
/// use std::sync::Arc;
/// use structid_core::progress::Progress;
/// let seen = Arc::new(AtomicU64::new(0));
/// let s = Arc::clone(&seen);
/// let p = Progress::new(move |done, _total| s.store(done, Ordering::Relaxed));
/// p.report(3, Some(10));
/// assert_eq!(seen.load(Ordering::Relaxed), 3);
/// Progress::none().report(1, None); // nothing happens
/// assert_eq!(p, Progress::none());
/// ```
#[derive(Clone, Default)]
pub struct Progress(Option<Arc<ProgressFn>>);

impl Progress {
    /// An observer calling `f(done, total)`.
    pub fn new(f: impl Fn(u64, Option<u64>) + Send + Sync + 'static) -> Self {
        Progress(Some(Arc::new(f)))
    }

    /// No observer.
    pub fn none() -> Self {
        Progress(None)
    }

    /// Whether an observer is attached.
    pub fn is_active(&self) -> bool {
        self.0.is_some()
    }

    /// Tells the observer, if any, that `done` of `total` units are done.
    pub fn report(&self, done: u64, total: Option<u64>) {
        if let Some(f) = &self.0 {
            f(done, total);
        }
    }
}

impl std::fmt::Debug for Progress {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(if self.is_active() {
            "Progress(observer)"
        } else {
            "Progress(none)"
        })
    }
}

impl PartialEq for Progress {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::selection::{SelectionSettings, select};
    use crate::{IdentifySettings, KernelDispersion, paper};
    use std::sync::Mutex;

    /// The β search tells its observer once per trial, counting up: as many reports as the
    /// selection's curve has points.
    #[test]
    fn selection_reports_every_trial() {
        let d = Arc::new(KernelDispersion::gaussian(0.1).unwrap());
        let exp = paper::spray(200, 0.5, d, 1).unwrap();
        let heard = Arc::new(Mutex::new(Vec::new()));
        let h = Arc::clone(&heard);
        let how = SelectionSettings::builder()
            .progress(Progress::new(move |done, total| {
                h.lock().unwrap().push((done, total))
            }))
            .build()
            .unwrap();
        let sel = select(
            &exp.model,
            &exp.data,
            None,
            &IdentifySettings::default(),
            &how,
        )
        .unwrap();
        let heard = heard.lock().unwrap();
        let expected: Vec<(u64, Option<u64>)> =
            (1..=sel.curve.len() as u64).map(|i| (i, None)).collect();
        assert_eq!(*heard, expected);
        // Without an observer, the same choice.
        let plain = select(
            &exp.model,
            &exp.data,
            None,
            &IdentifySettings::default(),
            &SelectionSettings::default(),
        )
        .unwrap();
        assert_eq!(plain.beta, sel.beta);
    }
}
