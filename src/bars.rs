//! The progress bars: indicatif on stderr, shown only when stderr is a terminal. The one place
//! the binary draws progress; the library reports through [`Progress`].

use std::io::IsTerminal;

use indicatif::{ProgressBar, ProgressStyle};

use ftcbf_lab::progress::Progress;

/// What a bar counts.
#[derive(Debug, Clone, Copy)]
pub enum Unit {
    /// Closed-loop runs (trials, search evaluations): elapsed time, a wide bar and the ETA.
    Runs,
    /// Control steps of one run: a 40-column bar and the ETA.
    Steps,
}

/// A bar on stderr, hidden when stderr is not a terminal (a pipe, a file, CI).
pub fn bar(len: u64, label: &str, unit: Unit) -> ProgressBar {
    if !std::io::stderr().is_terminal() {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(len);
    let (template, chars) = match unit {
        Unit::Runs => (
            "{msg} [{elapsed_precise}] {wide_bar} {pos}/{len} runs, ETA {eta}",
            None,
        ),
        Unit::Steps => ("{msg} [{bar:40}] {pos}/{len} ({eta})", Some("=> ")),
    };
    let style =
        ProgressStyle::with_template(template).unwrap_or_else(|_| ProgressStyle::default_bar());
    bar.set_style(match chars {
        Some(c) => style.progress_chars(c),
        None => style,
    });
    bar.set_message(label.to_string());
    bar
}

/// The library's [`Progress`] drawn as a bar of runs; each `start` begins a fresh bar (a sweep
/// runs one batch per point).
pub struct RunsBar(ProgressBar);

impl RunsBar {
    /// A bar that appears on the first `start` (hidden off a terminal).
    pub fn new() -> Self {
        RunsBar(bar(0, "", Unit::Runs))
    }
}

impl Progress for RunsBar {
    fn start(&self, len: u64, label: &str) {
        self.0.reset();
        self.0.set_length(len);
        self.0.set_message(label.to_string());
    }
    fn advance(&self, n: u64) {
        self.0.inc(n);
    }
    fn phase(&self, label: &str) {
        self.0.set_message(label.to_string());
    }
    fn finish(&self) {
        self.0.finish_and_clear();
    }
}
