//! Where a measurement came from: when, from which commit, and with how many lavapipe threads —
//! what it takes to compare two benchmark files fairly.

use std::process::Command;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use crate::gpu::Context;

/// The current time in UTC as ISO 8601 / RFC 3339 (`YYYY-MM-DDThh:mm:ssZ`).
pub fn utc_now() -> String {
    iso8601(SystemTime::now())
}

/// `time` as ISO 8601 / RFC 3339 in UTC, to the second. A clock outside the years 1970–9999
/// (which humantime refuses to format) reads as the nearer end.
pub fn iso8601(time: SystemTime) -> String {
    let last = UNIX_EPOCH + Duration::from_secs(253_402_300_799); // 9999-12-31T23:59:59Z
    humantime::format_rfc3339_seconds(time.clamp(UNIX_EPOCH, last)).to_string()
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
        let at = |secs| iso8601(UNIX_EPOCH + Duration::from_secs(secs));
        assert_eq!(at(0), "1970-01-01T00:00:00Z");
        assert_eq!(at(951_782_400), "2000-02-29T00:00:00Z");
        assert_eq!(at(1_709_251_199), "2024-02-29T23:59:59Z");
        assert_eq!(at(4_102_444_800), "2100-01-01T00:00:00Z");
        assert_eq!(
            iso8601(UNIX_EPOCH - Duration::from_secs(5)),
            "1970-01-01T00:00:00Z"
        );
        assert_eq!(at(u64::MAX / 4), "9999-12-31T23:59:59Z");
    }
}
