//! The one progress bar: position, rate, the caller's message and ETA. indicatif hides it
//! when stderr is not a terminal; long runs print their own line per epoch there.

use indicatif::{ProgressBar, ProgressStyle};

/// A bar of `len` `unit`s (steps, images, ...) labelled `label`.
pub fn progress_bar(len: u64, label: &str, unit: &str) -> ProgressBar {
    let bar = ProgressBar::new(len);
    bar.set_style(
        ProgressStyle::with_template(&format!(
            "{{prefix}} [{{bar:30}}] {{pos}}/{{len}} {unit} {{per_sec}} {{msg}} ETA {{eta}}"
        ))
        .expect("valid template")
        .progress_chars("=> "),
    );
    bar.set_prefix(label.to_string());
    bar
}
