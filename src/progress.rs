//! Progress of the steps a user waits for: loading a scene's meshes, building a BVH or an RBVH.
//! A 22-million-triangle scene takes a minute to load and build on two cores; without a count
//! and an estimate, a waiting user cannot tell a slow step from a hung one.
//!
//! The library only counts; what a count looks like is the caller's (the `rbvh` tool draws
//! indicatif bars on a terminal and nothing otherwise). A step is `begin`, any number of
//! `advance` calls, possibly from many threads at once (the builders are rayon-parallel), then
//! `end`. Steps do not nest: a caller sees one at a time.

/// Receives the progress of long steps. Implementations must be cheap in [`Progress::advance`]:
/// builders call it once per leaf, from every worker thread.
pub trait Progress: Sync {
    /// Step `what` starts; `total` units of work are to be done (0: unknown).
    fn begin(&self, what: &str, total: u64);
    /// `done` more units of the current step are finished.
    fn advance(&self, done: u64);
    /// The current step is finished (also after an error part-way).
    fn end(&self);
}

/// The progress that nobody watches: what the functions without a progress argument use.
#[derive(Clone, Copy, Debug, Default)]
pub struct Quiet;

impl Progress for Quiet {
    fn begin(&self, _what: &str, _total: u64) {}
    fn advance(&self, _done: u64) {}
    fn end(&self) {}
}

/// Runs `f` as step `what` of `total` units on `progress`, ending the step however `f` ends.
pub(crate) fn step<T>(progress: &dyn Progress, what: &str, total: u64, f: impl FnOnce() -> T) -> T {
    struct End<'a>(&'a dyn Progress);
    impl Drop for End<'_> {
        fn drop(&mut self) {
            self.0.end();
        }
    }
    progress.begin(what, total);
    let _end = End(progress);
    f()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Mutex;

    /// Records every call, in order.
    #[derive(Default)]
    struct Log(Mutex<Vec<String>>);

    impl Progress for Log {
        fn begin(&self, what: &str, total: u64) {
            self.0.lock().unwrap().push(format!("begin {what} {total}"));
        }
        fn advance(&self, done: u64) {
            self.0.lock().unwrap().push(format!("advance {done}"));
        }
        fn end(&self) {
            self.0.lock().unwrap().push("end".into());
        }
    }

    #[test]
    fn a_step_ends_even_when_it_panics() {
        let log = Log::default();
        let caught = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            step(&log, "x", 2, || {
                log.advance(1);
                panic!("part-way");
            })
        }));
        assert!(caught.is_err());
        assert_eq!(*log.0.lock().unwrap(), ["begin x 2", "advance 1", "end"]);
    }
}
