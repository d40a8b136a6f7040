//! Progress bars on a terminal (indicatif); silent when stderr is not one.

use indicatif::{ProgressBar, ProgressStyle};

/// A bar of `total` units labelled `what`, hidden off a terminal.
pub fn bar(total: u64, what: &str) -> ProgressBar {
    let bar = ProgressBar::new(total);
    bar.set_style(
        ProgressStyle::with_template("{msg:>12} [{bar:40}] {pos}/{len} {per_sec} eta {eta}")
            .expect("static template")
            .progress_chars("=> "),
    );
    bar.set_message(what.to_string());
    bar
}
