//! Progress bars for long commands: drawn on a terminal, absent when stderr is a file or a
//! pipe (scripts and logs get no control characters).

use std::io::IsTerminal;
use std::time::Duration;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use structid_core::progress::Progress;

/// A bar of `len` units named `unit` (`cases`, `alternations`, …), or, without a length, a
/// spinner counting them; hidden unless stderr is a terminal.
pub(crate) fn bar(len: Option<u64>, unit: &str) -> ProgressBar {
    if !std::io::stderr().is_terminal() {
        return ProgressBar::hidden();
    }
    let pb = ProgressBar::with_draw_target(len, ProgressDrawTarget::stderr());
    let template = if len.is_some() {
        "{spinner} [{elapsed_precise}] {bar:30} {pos}/{len} {prefix}, {eta} left  {wide_msg}"
    } else {
        "{spinner} [{elapsed_precise}] {pos} {prefix}  {wide_msg}"
    };
    if let Ok(style) = ProgressStyle::with_template(template) {
        pb.set_style(style);
    }
    pb.set_prefix(unit.to_string());
    pb.enable_steady_tick(Duration::from_millis(250));
    pb
}

/// A spinner with a message and the elapsed time, for one long step that reports nothing
/// on its way (a large exact solve); hidden unless stderr is a terminal.
pub(crate) fn spinner(message: String) -> ProgressBar {
    if !std::io::stderr().is_terminal() {
        return ProgressBar::hidden();
    }
    let pb = ProgressBar::with_draw_target(None, ProgressDrawTarget::stderr());
    if let Ok(style) = ProgressStyle::with_template("{spinner} [{elapsed_precise}] {wide_msg}") {
        pb.set_style(style);
    }
    pb.set_message(message);
    pb.enable_steady_tick(Duration::from_millis(250));
    pb
}

/// The library's observer moving `pb`: its position to the units done and its length to
/// their total when the library knows it.
pub(crate) fn observer(pb: &ProgressBar) -> Progress {
    if pb.is_hidden() {
        return Progress::none();
    }
    let pb = pb.clone();
    Progress::new(move |done, total| {
        if let Some(t) = total {
            pb.set_length(t);
        }
        pb.set_position(done);
    })
}

/// An observer writing `label: N β trials` into the message of `pb` (a selection inside
/// a longer run whose bar counts something else).
pub(crate) fn message_observer(pb: &ProgressBar, label: &'static str) -> Progress {
    if pb.is_hidden() {
        return Progress::none();
    }
    let pb = pb.clone();
    Progress::new(move |done, _| pb.set_message(format!("{label}: {done} β trials")))
}
