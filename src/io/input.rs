//! Reading the files a user names: files and pipes, nothing else.
//!
//! A device such as `/dev/zero` would be read forever and a directory is a mistake: each is
//! refused by name before it is opened. A stream's file (rays, RBVH files, point clouds, paint
//! strokes, goldens, read once from start to end) may also be a pipe (`--rays <(make-rays)`,
//! `/dev/stdin`), which, like any reader of one, waits for its writer. What a scene names
//! (meshes, their buffers and textures) and an environment map, which the EXR reader seeks in,
//! must be regular files (`regular_file`).

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

/// Refuses `path` unless it is a regular file or a pipe, before it is opened.
fn file_or_pipe(path: &Path) -> Result<()> {
    let metadata = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
    #[cfg(unix)]
    let pipe = std::os::unix::fs::FileTypeExt::is_fifo(&metadata.file_type());
    #[cfg(not(unix))]
    let pipe = false;
    if metadata.is_file() || pipe {
        Ok(())
    } else {
        Err(Error::parse(
            path,
            None,
            "not a file or a pipe (a directory or device)",
        ))
    }
}

/// Opens the file or pipe at `path` for reading: [`Error::Io`] where it is missing or
/// unreadable, [`Error::Parse`] where it is neither.
pub fn open(path: &Path) -> Result<File> {
    file_or_pipe(path)?;
    File::open(path).map_err(|e| Error::io(path, e))
}

/// The bytes of the file or pipe at `path`, as [`open`] refuses it.
pub fn read(path: &Path) -> Result<Vec<u8>> {
    file_or_pipe(path)?;
    std::fs::read(path).map_err(|e| Error::io(path, e))
}

/// The text of the file or pipe at `path`, as [`open`] refuses it; not UTF-8 is
/// [`Error::Io`] (`InvalidData`).
pub fn read_to_string(path: &Path) -> Result<String> {
    file_or_pipe(path)?;
    std::fs::read_to_string(path).map_err(|e| Error::io(path, e))
}

#[cfg(all(test, unix))]
mod tests {
    use super::*;

    #[test]
    fn a_device_or_a_directory_is_refused_before_it_is_opened() {
        let dir = tempfile::tempdir().unwrap();
        for path in [dir.path(), Path::new("/dev/zero")] {
            for err in [
                open(path).err(),
                read(path).err(),
                read_to_string(path).err(),
            ] {
                let err = err.expect("refused").to_string();
                assert!(err.contains("not a file or a pipe"), "{err}");
                assert!(err.contains(&*path.to_string_lossy()), "{err}");
            }
        }
        let file = dir.path().join("plain.txt");
        std::fs::write(&file, "text").unwrap();
        assert_eq!(read_to_string(&file).unwrap(), "text");
        let missing = read(&dir.path().join("missing")).unwrap_err();
        assert!(matches!(missing, Error::Io { .. }), "{missing}");
    }

    #[test]
    fn a_pipe_is_read_to_its_end() {
        let dir = tempfile::tempdir().unwrap();
        let fifo = super::super::fifo_in(dir.path(), "rays.fifo");
        let writer = {
            let fifo = fifo.clone();
            std::thread::spawn(move || std::fs::write(fifo, "streamed").unwrap())
        };
        assert_eq!(read_to_string(&fifo).unwrap(), "streamed");
        writer.join().unwrap();
    }
}
