//! Writing a file so that it is either wholly there or not changed at all.

use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};

use crate::Error;

/// Writes `path` through `write`, all or nothing.
///
/// The content goes to a temporary file next to the target (`.<name>.tmp-<pid>`, in the same
/// directory so that the final rename cannot cross file systems), is flushed and synced, and only
/// then renamed over `path`. A reader therefore sees either the old file or the complete new one,
/// never a truncated file that might pass for a valid one. On any error the temporary file is
/// removed and `path` is left as it was.
///
/// Errors name `path`, whatever step failed, since that is the file the user asked for.
pub fn write_atomically(
    path: &Path,
    write: impl FnOnce(&mut BufWriter<File>) -> io::Result<()>,
) -> crate::Result<()> {
    let temp = temp_path(path)?;
    let result = write_then_rename(&temp, path, write);
    if result.is_err() {
        // The write already failed; a leftover temporary file is the lesser problem, and the
        // error that matters to the user is the first one.
        let _ = std::fs::remove_file(&temp);
    }
    result.map_err(|e| Error::io(path, e))
}

fn write_then_rename(
    temp: &Path,
    path: &Path,
    write: impl FnOnce(&mut BufWriter<File>) -> io::Result<()>,
) -> io::Result<()> {
    let mut writer = BufWriter::new(File::create(temp)?);
    write(&mut writer)?;
    writer.flush()?;
    let file = writer
        .into_inner()
        .map_err(io::IntoInnerError::into_error)?;
    // Sync before renaming: otherwise a crash could leave the new name pointing at a file whose
    // data never reached the disk.
    file.sync_all()?;
    drop(file);
    std::fs::rename(temp, path)
}

/// `dir/.<name>.tmp-<pid>`: hidden, in the target's directory, and distinct per process so that
/// two processes writing the same target do not share a temporary file.
fn temp_path(path: &Path) -> crate::Result<PathBuf> {
    let name = path.file_name().ok_or_else(|| {
        Error::io(
            path,
            io::Error::new(io::ErrorKind::InvalidInput, "not a file name to write to"),
        )
    })?;
    let mut temp_name = std::ffi::OsString::from(".");
    temp_name.push(name);
    temp_name.push(format!(".tmp-{}", std::process::id()));
    Ok(path.with_file_name(temp_name))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn temp_file_is_hidden_next_to_the_target() {
        let temp = temp_path(Path::new("out/picture.png")).unwrap();
        assert_eq!(temp.parent(), Some(Path::new("out")));
        let name = temp.file_name().unwrap().to_str().unwrap();
        assert!(name.starts_with(".picture.png.tmp-"), "{name}");
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
