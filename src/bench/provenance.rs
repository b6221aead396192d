//! Where a measurement came from: when, from which commit, and with how many lavapipe threads —
//! what it takes to compare two benchmark files fairly.

use std::process::Command;
use std::time::{SystemTime, UNIX_EPOCH};

use crate::gpu::Context;

/// The current time in UTC as ISO 8601 (`YYYY-MM-DDThh:mm:ssZ`). A clock before 1970 reads as the
/// epoch.
pub fn utc_now() -> String {
    let secs = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    iso8601(secs)
}

/// `secs` since the Unix epoch as ISO 8601 in UTC.
///
/// The date is Howard Hinnant's `civil_from_days` ("chrono-Compatible Low-Level Date Algorithms",
/// <https://howardhinnant.github.io/date_algorithms.html>): shifting the year to start in March
/// puts the leap day last, so days map to dates through 400-year eras without tables.
pub fn iso8601(secs: u64) -> String {
    let days = secs / 86_400;
    let rem = secs % 86_400;
    let z = days + 719_468; // days from 0000-03-01 to 1970-01-01
    let era = z / 146_097;
    let doe = z % 146_097; // day of era, [0, 146096]
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365; // [0, 399]
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100); // day of year from March 1, [0, 365]
    let mp = (5 * doy + 2) / 153; // month from March, [0, 11]
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + u64::from(month <= 2);
    format!(
        "{year:04}-{month:02}-{day:02}T{:02}:{:02}:{:02}Z",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60
    )
}

/// `git rev-parse HEAD` in the current directory, or None when git or a repository is missing.
pub fn git_commit() -> Option<String> {
    let out = Command::new("git")
        .args(["rev-parse", "HEAD"])
        .output()
        .ok()?;
    let commit = String::from_utf8(out.stdout).ok()?.trim().to_string();
    (out.status.success() && !commit.is_empty()).then_some(commit)
}

/// The worker threads lavapipe (Mesa's llvmpipe) runs compute dispatches on, or None for any
/// other device. Mesa reads `LP_NUM_THREADS` once, when the device is created; unset, it uses one
/// thread per CPU, which `available_parallelism` reports (up to Mesa's own cap, `LP_MAX_THREADS`).
pub fn lavapipe_threads(ctx: &Context) -> Option<u32> {
    if !ctx.device_name().contains("llvmpipe") {
        return None;
    }
    std::env::var("LP_NUM_THREADS")
        .ok()
        .and_then(|v| v.trim().parse().ok())
        .or_else(|| {
            std::thread::available_parallelism()
                .ok()
                .map(|n| n.get() as u32)
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn known_instants() {
        assert_eq!(iso8601(0), "1970-01-01T00:00:00Z");
        assert_eq!(iso8601(951_782_400), "2000-02-29T00:00:00Z");
        assert_eq!(iso8601(1_709_251_199), "2024-02-29T23:59:59Z");
        assert_eq!(iso8601(4_102_444_800), "2100-01-01T00:00:00Z");
    }
}
