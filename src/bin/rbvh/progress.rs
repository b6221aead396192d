//! What a waiting user sees: one line on stderr per step, a spinner with the time spent, which
//! becomes a bar with counts, rate and an estimate of the time left while the library reports a
//! counted step (`rbvh::progress`). indicatif draws nothing when stderr is not a terminal, so
//! logs and pipes stay clean.

use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressStyle};

/// A spinner that turns into a counting bar for the library's counted steps.
pub struct Bar {
    bar: ProgressBar,
    /// The spinner's own label, shown again after a counted step.
    label: Mutex<String>,
    /// Units done in the current counted step, and how many the bar shows: builders report
    /// millions of leaves from every thread, and the bar moves only every 1/500 of the step, so
    /// that a report costs one atomic addition rather than a clock read.
    done: AtomicU64,
    shown: AtomicU64,
    grain: AtomicU64,
    /// The library's step under way (its name and start), and each finished one with its wall
    /// time, in order: what `rbvh build --timings` prints.
    current: Mutex<Option<(String, Instant)>>,
    timings: Mutex<Vec<(String, Duration)>>,
}

fn spinner_style() -> ProgressStyle {
    ProgressStyle::with_template("{spinner} {msg} {elapsed}").expect("static template")
}

fn counting_style() -> ProgressStyle {
    ProgressStyle::with_template(
        "{spinner} {msg} [{bar:30}] {human_pos}/{human_len} {elapsed}, about {eta} left",
    )
    .expect("static template")
    .progress_chars("=> ")
}

impl Bar {
    /// A spinner labelled `label`, ticking on its own.
    pub fn new(label: &str) -> Bar {
        let bar = ProgressBar::new_spinner().with_message(label.to_string());
        bar.set_style(spinner_style());
        bar.enable_steady_tick(Duration::from_millis(120));
        Bar {
            bar,
            label: Mutex::new(label.to_string()),
            done: AtomicU64::new(0),
            shown: AtomicU64::new(0),
            grain: AtomicU64::new(1),
            current: Mutex::new(None),
            timings: Mutex::new(Vec::new()),
        }
    }

    /// The library's steps finished so far under this bar, each with its wall time, in order.
    pub fn timings(&self) -> Vec<(String, Duration)> {
        self.timings
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone()
    }

    /// Changes the spinner's label (for steps the library does not count).
    pub fn set_label(&self, label: String) {
        self.bar.set_message(label.clone());
        *self.label.lock().unwrap_or_else(|e| e.into_inner()) = label;
    }

    /// Prints `line` above the bar without tearing it.
    pub fn println(&self, line: &str) {
        self.bar.suspend(|| eprintln!("{line}"));
    }

    /// Removes the line.
    pub fn finish(self) {
        self.bar.finish_and_clear();
    }
}

impl rbvh::progress::Progress for Bar {
    fn begin(&self, what: &str, total: u64) {
        *self.current.lock().unwrap_or_else(|e| e.into_inner()) =
            Some((what.to_string(), Instant::now()));
        self.bar.set_message(what.to_string());
        self.done.store(0, Relaxed);
        self.shown.store(0, Relaxed);
        self.grain.store((total / 500).max(1), Relaxed);
        if total > 0 {
            self.bar.set_style(counting_style());
            self.bar.set_length(total);
            self.bar.set_position(0);
            self.bar.reset_eta();
        }
    }

    fn advance(&self, done: u64) {
        let now = self.done.fetch_add(done, Relaxed) + done;
        if now >= self.shown.load(Relaxed) + self.grain.load(Relaxed) {
            self.shown.store(now, Relaxed);
            self.bar.set_position(now);
        }
    }

    fn end(&self) {
        if let Some((what, start)) = self
            .current
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .take()
        {
            self.timings
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .push((what, start.elapsed()));
        }
        self.bar.set_style(spinner_style());
        let label = self.label.lock().unwrap_or_else(|e| e.into_inner()).clone();
        self.bar.set_message(label);
    }
}

/// Runs `f` under a spinner labelled `what`, handing it the bar for the library to count on.
pub fn step<T>(what: &str, f: impl FnOnce(&Bar) -> T) -> T {
    let bar = Bar::new(what);
    let out = f(&bar);
    bar.finish();
    out
}
