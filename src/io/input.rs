//! Reading the files a user names: regular files only.
//!
//! A device such as `/dev/zero` would be read forever, a FIFO with no writer blocks its reader
//! at `open`, and a directory is a mistake; each is refused by name before it is opened. Every
//! file the crate reads from a path goes through here: scenes and what they name (meshes,
//! buffers, textures), point clouds, environments, ray files, RBVH files, paint strokes,
//! goldens.

use std::fs::{File, Metadata};
use std::path::Path;

use crate::{Error, Result};

/// Refuses `path` unless `metadata` (its, following links) is a regular file's.
pub(crate) fn regular_file(path: &Path, metadata: &Metadata) -> Result<()> {
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

/// Opens the regular file at `path` for reading: [`Error::Io`] where it is missing or
/// unreadable, [`Error::Parse`] where it is no regular file.
pub fn open(path: &Path) -> Result<File> {
    let metadata = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
    regular_file(path, &metadata)?;
    File::open(path).map_err(|e| Error::io(path, e))
}

/// The bytes of the regular file at `path`, as [`open`] refuses it.
pub fn read(path: &Path) -> Result<Vec<u8>> {
    let metadata = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
    regular_file(path, &metadata)?;
    std::fs::read(path).map_err(|e| Error::io(path, e))
}

/// The text of the regular file at `path`, as [`open`] refuses it; not UTF-8 is
/// [`Error::Io`] (`InvalidData`).
pub fn read_to_string(path: &Path) -> Result<String> {
    let metadata = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
    regular_file(path, &metadata)?;
    std::fs::read_to_string(path).map_err(|e| Error::io(path, e))
}

#[cfg(all(test, unix))]
mod tests {
    use super::*;

    #[test]
    fn a_pipe_a_device_or_a_directory_is_refused_before_it_is_opened() {
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("rays.fifo");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status();
        // Opened, a FIFO with no writer would block this test for ever.
        let mut refused = vec![dir.path().to_path_buf(), "/dev/zero".into()];
        if made.is_ok_and(|s| s.success()) {
            refused.push(fifo);
        }
        for path in &refused {
            for err in [
                open(path).err(),
                read(path).err(),
                read_to_string(path).err(),
            ] {
                let err = err.expect("refused").to_string();
                assert!(err.contains("not a regular file"), "{err}");
                assert!(err.contains(&*path.to_string_lossy()), "{err}");
            }
        }
        let file = dir.path().join("plain.txt");
        std::fs::write(&file, "text").unwrap();
        assert_eq!(read_to_string(&file).unwrap(), "text");
        let missing = read(&dir.path().join("missing")).unwrap_err();
        assert!(matches!(missing, Error::Io { .. }), "{missing}");
    }
}
