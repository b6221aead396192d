//! Writing a file so that it is either wholly there or not changed at all.

use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};

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
/// A symbolic link is followed: the file it names is replaced, the link kept. What is not a
/// regular file where it stands is written through (appended to) as it is, since replacing it
/// would lose what it is: a device such as `/dev/null` stays a device, a FIFO passes the bytes
/// to its reader, and so is a file reached through `/proc` (`/dev/stdout`, `/dev/fd/N`), which a
/// descriptor holds open. A directory is refused.
///
/// Errors name `path`, whatever step failed, since that is the file the user asked for.
pub fn write_atomically(
    path: &Path,
    write: impl FnOnce(&mut BufWriter<File>) -> io::Result<()>,
) -> crate::Result<()> {
    match rename_target(path).map_err(|e| Error::io(path, e))? {
        Some(target) => write_then_persist(&target, write).map_err(|e| Error::io(path, e)),
        None => write_through(path, write).map_err(|e| Error::io(path, e)),
    }
}

/// The file that [`write_atomically`] renames its complete content over: `path` with its
/// symbolic links followed, so that a link is kept and the file it names replaced; `None`
/// where it writes through instead (not a regular file where the kernel follows `path`, or a
/// link into `/proc`); an error for a directory.
pub fn rename_target(path: &Path) -> io::Result<Option<PathBuf>> {
    match std::fs::metadata(path) {
        Ok(m) if m.is_dir() => {
            return Err(io::Error::new(
                io::ErrorKind::IsADirectory,
                "a directory, not a file to write",
            ))
        }
        Ok(m) if !m.is_file() => return Ok(None),
        _ => {}
    }
    let mut path = path.to_path_buf();
    // As the kernel's limit on links followed in one lookup (Linux's 40).
    for _ in 0..40 {
        // Its folder as the kernel resolves it: `/dev/fd/1` lies in `/proc/self/fd` (`/dev/fd`
        // is itself a link), where the file a descriptor holds is not to be replaced.
        let folder = match path.parent() {
            Some(folder) if !folder.as_os_str().is_empty() => folder,
            _ => Path::new("."),
        };
        let in_proc = |p: &Path| p.starts_with("/proc");
        if in_proc(&path) || std::fs::canonicalize(folder).is_ok_and(|f| in_proc(&f)) {
            return Ok(None);
        }
        match std::fs::symlink_metadata(&path) {
            Ok(m) if m.file_type().is_symlink() => {
                let link = std::fs::read_link(&path)?;
                path = match path.parent() {
                    Some(dir) if link.is_relative() => dir.join(link),
                    _ => link,
                };
            }
            _ => return Ok(Some(path)),
        }
    }
    Err(io::Error::new(
        io::ErrorKind::InvalidInput,
        "too many levels of symbolic links",
    ))
}

/// Writes into what is at `path` without replacing it (a device, a FIFO, a descriptor's file),
/// after what it holds: a shell's `> out` has emptied it already, and what the command printed
/// there before stays.
fn write_through(
    path: &Path,
    write: impl FnOnce(&mut BufWriter<File>) -> io::Result<()>,
) -> io::Result<()> {
    let mut writer = BufWriter::new(File::options().append(true).open(path)?);
    write(&mut writer)?;
    writer.flush()
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

    #[cfg(unix)]
    #[test]
    fn a_link_is_followed_and_kept() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("target.png");
        std::fs::write(&target, b"old").unwrap();
        let link = dir.path().join("link.png");
        std::os::unix::fs::symlink("target.png", &link).unwrap();
        write_atomically(&link, |w| w.write_all(b"new")).unwrap();
        assert!(std::fs::symlink_metadata(&link)
            .unwrap()
            .file_type()
            .is_symlink());
        assert_eq!(std::fs::read(&target).unwrap(), b"new");
        // A descriptor's file (`/dev/stdout`, whatever it is now) is written through, not
        // replaced behind the descriptor.
        #[cfg(target_os = "linux")]
        assert_eq!(rename_target(Path::new("/dev/fd/1")).unwrap(), None);
    }

    #[cfg(unix)]
    #[test]
    fn a_fifo_is_written_through_and_stays_a_fifo() {
        use std::os::unix::fs::FileTypeExt;
        let dir = tempfile::tempdir().unwrap();
        let fifo = super::super::fifo_in(dir.path(), "out.fifo");
        // Each end in a thread of its own, so that a write that replaced the FIFO rather than
        // going through it fails the test (its reader never ends) instead of hanging it.
        let (done, ended) = std::sync::mpsc::channel();
        for reads in [true, false] {
            let (fifo, done) = (fifo.clone(), done.clone());
            std::thread::spawn(move || {
                let bytes = if reads {
                    std::fs::read(&fifo).unwrap_or_default()
                } else {
                    write_atomically(&fifo, |w| w.write_all(b"through")).unwrap();
                    Vec::new()
                };
                let _ = done.send((reads, bytes));
            });
        }
        let mut read = Vec::new();
        for _ in 0..2 {
            let (reads, bytes) = ended
                .recv_timeout(std::time::Duration::from_secs(30))
                .expect("the write through the FIFO and its read end");
            if reads {
                read = bytes;
            }
        }
        assert_eq!(read, b"through");
        assert!(std::fs::symlink_metadata(&fifo)
            .unwrap()
            .file_type()
            .is_fifo());
    }

    #[test]
    fn a_directory_is_refused_by_name() {
        let dir = tempfile::tempdir().unwrap();
        let err = write_atomically(dir.path(), |w| w.write_all(b"x")).unwrap_err();
        assert!(
            err.to_string().contains(&*dir.path().to_string_lossy()),
            "{err}"
        );
        assert!(dir.path().is_dir());
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
