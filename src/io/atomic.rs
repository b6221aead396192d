//! Writing a file so that it is either wholly there or not changed at all.

use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::Path;

use crate::Error;

/// Writes `path` through `write`, all or nothing.
///
/// The content goes to a temporary file next to the target (`tempfile`'s, hidden, in the same
/// directory so that the final rename cannot cross file systems), is flushed and synced, and only
/// then renamed over `path`. A reader therefore sees either the old file or the complete new one,
/// never a truncated file that might pass for a valid one. On any error the temporary file is
/// removed (when it is dropped) and `path` is left as it was. The file gets the permissions a
/// plain `File::create` would give it (0o666 less the umask), not a temporary file's 0o600.
///
/// Errors name `path`, whatever step failed, since that is the file the user asked for.
pub fn write_atomically(
    path: &Path,
    write: impl FnOnce(&mut BufWriter<File>) -> io::Result<()>,
) -> crate::Result<()> {
    write_then_persist(path, write).map_err(|e| Error::io(path, e))
}

fn write_then_persist(
    path: &Path,
    write: impl FnOnce(&mut BufWriter<File>) -> io::Result<()>,
) -> io::Result<()> {
    let name = path.file_name().ok_or_else(|| {
        io::Error::new(io::ErrorKind::InvalidInput, "not a file name to write to")
    })?;
    let dir = match path.parent() {
        Some(dir) if !dir.as_os_str().is_empty() => dir,
        _ => Path::new("."),
    };
    let mut prefix = std::ffi::OsString::from(".");
    prefix.push(name);
    prefix.push(".");
    let mut builder = tempfile::Builder::new();
    builder.prefix(&prefix).suffix(".tmp");
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        builder.permissions(std::fs::Permissions::from_mode(0o666));
    }
    let temp = builder.tempfile_in(dir)?;
    let mut writer = BufWriter::new(temp.reopen()?);
    write(&mut writer)?;
    writer.flush()?;
    let file = writer
        .into_inner()
        .map_err(io::IntoInnerError::into_error)?;
    // Sync before renaming: otherwise a crash could leave the new name pointing at a file whose
    // data never reached the disk.
    file.sync_all()?;
    drop(file);
    temp.persist(path).map_err(|e| e.error)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_write_leaves_only_the_target_with_the_permissions_of_a_created_file() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("picture.png");
        write_atomically(&target, |w| w.write_all(b"all")).unwrap();
        write_atomically(&target, |w| w.write_all(b"all again")).unwrap();
        assert_eq!(std::fs::read(&target).unwrap(), b"all again");
        let plain = dir.path().join("plain");
        File::create(&plain).unwrap();
        let names: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names.len(), 2, "{names:?}");
        let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions();
        assert_eq!(mode(&target), mode(&plain));
    }

    #[test]
    fn a_failing_writer_leaves_nothing_behind() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("x.bin");
        let err = write_atomically(&target, |w| {
            w.write_all(b"partial")?;
            Err(io::Error::other("boom"))
        })
        .unwrap_err();
        assert!(err.to_string().contains("x.bin"), "{err}");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    }
}
