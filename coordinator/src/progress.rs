//! Progress of long renders: a bar with rate and ETA on a terminal, plain log lines otherwise
//! (CI logs and pipes should not fill with redraws).

use std::io::IsTerminal;
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressStyle};

/// Reports passes done against an optional total.
pub struct Reporter {
    bar: Option<ProgressBar>,
    last_log: Instant,
    unit: &'static str,
}

/// Seconds between log lines when not on a terminal.
const LOG_EVERY: Duration = Duration::from_secs(5);

impl Reporter {
    /// A reporter for `total` units (None: unknown, e.g. a time-limited render).
    pub fn new(total: Option<u64>, unit: &'static str) -> Reporter {
        let bar = std::io::stderr().is_terminal().then(|| {
            let bar = match total {
                Some(t) => ProgressBar::new(t),
                None => ProgressBar::new_spinner(),
            };
            let template = if total.is_some() {
                "{elapsed_precise} [{bar:40}] {pos}/{len} {msg} ({per_sec}, ETA {eta})"
            } else {
                "{elapsed_precise} {spinner} {pos} {msg} ({per_sec})"
            };
            bar.set_style(
                ProgressStyle::with_template(template)
                    .expect("the template is valid")
                    .progress_chars("=> "),
            );
            bar.set_message(unit);
            bar
        });
        Reporter {
            bar,
            last_log: Instant::now(),
            unit,
        }
    }

    /// Records progress.
    pub fn update(&mut self, done: u64, total: Option<u64>, elapsed: Duration) {
        if let Some(bar) = &self.bar {
            bar.set_position(done);
            return;
        }
        let finished = total.is_some_and(|t| done >= t);
        if self.last_log.elapsed() < LOG_EVERY && !finished {
            return;
        }
        self.last_log = Instant::now();
        let rate = done as f64 / elapsed.as_secs_f64().max(1e-9);
        match total {
            Some(t) => {
                let eta = (t - done.min(t)) as f64 / rate.max(1e-9);
                eprintln!(
                    "{done}/{t} {} ({rate:.2}/s, {:.1} s elapsed, ETA {eta:.0} s)",
                    self.unit,
                    elapsed.as_secs_f64()
                );
            }
            None => eprintln!(
                "{done} {} ({rate:.2}/s, {:.1} s elapsed)",
                self.unit,
                elapsed.as_secs_f64()
            ),
        }
    }

    /// Prints a line above the bar (or as a log line).
    pub fn println(&self, line: &str) {
        match &self.bar {
            Some(bar) => bar.println(line),
            None => eprintln!("{line}"),
        }
    }

    /// Clears the bar.
    pub fn finish(&self) {
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
    }
}
