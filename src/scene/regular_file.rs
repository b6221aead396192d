//! The check every file a scene names goes through before it is opened.

use std::path::Path;

use crate::{Error, Result};

/// Refuses anything but a regular file: a device such as `/dev/zero` or a FIFO would be read
/// forever, and a directory is a mistake. Every file a scene names goes through this.
pub(super) fn regular_file(path: &Path, metadata: &std::fs::Metadata) -> Result<()> {
    if metadata.is_file() {
        Ok(())
    } else {
        Err(Error::parse(
            path,
            None,
            "not a regular file (a directory, device or pipe)",
        ))
    }
}
