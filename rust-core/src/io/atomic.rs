//! Crash-safe file replacement: write a hidden temporary sibling, then rename it over the
//! target. A reader (or a user re-running a job) sees either the old file or the complete
//! new one, never a half-written mesh.

use crate::error::{Error, Result};
use std::fs::{self, File, OpenOptions};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// Distinguishes temporary files of concurrent writes from the same process (e.g. frames
/// written in parallel into one folder).
static COUNTER: AtomicU64 = AtomicU64::new(0);

/// Writes `path` through `write`, which receives a buffered writer on a temporary file in
/// the same directory (a rename across file systems would not be atomic). On any error the
/// temporary file is removed and the previous `path`, if any, is left untouched.
pub(crate) fn write_atomically<F>(path: &Path, write: F) -> Result<()>
where
    F: FnOnce(&mut BufWriter<File>) -> std::io::Result<()>,
{
    let file_name = replaceable_name(path)?;
    let dir = parent_dir(path);
    let (tmp, file) =
        create_temporary(&dir, &file_name.to_string_lossy()).map_err(|e| Error::io(path, e))?;

    let mut writer = BufWriter::new(file);
    let written = write(&mut writer)
        .and_then(|_| writer.flush())
        .and_then(|_| writer.get_ref().sync_all());
    drop(writer);
    let finished = written.and_then(|_| fs::rename(&tmp, path));
    if let Err(e) = finished {
        // Best effort: the write already failed, and a leftover hidden file is harmless.
        let _ = fs::remove_file(&tmp);
        return Err(Error::io(path, e));
    }
    Ok(())
}

/// The file name of `path`, if whatever is there may be replaced: a rename replaces what
/// the name points at, and a device, a FIFO or a folder there is something the user has,
/// not an earlier output, so it is left alone. (A link to a regular file is replaced.)
fn replaceable_name(path: &Path) -> Result<&std::ffi::OsStr> {
    let file_name = path
        .file_name()
        .ok_or_else(|| Error::InvalidInput(format!("{}: not a file path", path.display())))?;
    if let Ok(meta) = fs::metadata(path) {
        if !meta.is_file() {
            return Err(Error::io(
                path,
                std::io::Error::other("exists and is not a regular file; not replaced"),
            ));
        }
    }
    Ok(file_name)
}

/// Checks, before the work whose result goes there, that `path` can be written the way
/// [`write_atomically`] writes it: a file name, not something other than a regular file,
/// in a folder where a temporary can be created (made and removed again here). A long
/// extraction then does not end in an error that a glance at the path would have given.
pub fn check_writable(path: &Path) -> Result<()> {
    let file_name = replaceable_name(path)?;
    let (tmp, file) = create_temporary(&parent_dir(path), &file_name.to_string_lossy())
        .map_err(|e| Error::io(path, e))?;
    drop(file);
    // Best effort: the check succeeded, and a leftover hidden file is harmless.
    let _ = fs::remove_file(tmp);
    Ok(())
}

/// The bytes of `path`, which must be a regular file (after links): a FIFO would block the
/// read forever and a device such as /dev/zero never ends.
pub(crate) fn read_regular_file(path: &Path) -> Result<Vec<u8>> {
    let mut bytes = Vec::new();
    std::io::Read::read_to_end(&mut open_regular(path)?, &mut bytes)
        .map_err(|e| Error::io(path, e))?;
    Ok(bytes)
}

/// Opens `path` for reading if it is a regular file (after links), checked before opening
/// (opening a FIFO blocks until something writes to it) and again on the open file.
pub(crate) fn open_regular(path: &Path) -> Result<File> {
    let regular = |meta: std::io::Result<fs::Metadata>| match meta {
        Ok(m) if m.is_file() => Ok(()),
        Ok(_) => Err(Error::io(
            path,
            std::io::Error::other("not a regular file (a folder, device or pipe)"),
        )),
        Err(e) => Err(Error::io(path, e)),
    };
    regular(fs::metadata(path))?;
    let file = File::open(path).map_err(|e| Error::io(path, e))?;
    regular(file.metadata())?;
    Ok(file)
}

/// The folder `path` is in (`.` for a bare file name): where its temporaries go.
pub(crate) fn parent_dir(path: &Path) -> PathBuf {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// Creates `.name.tmpPID-N` exclusively (never clobbering another writer's temporary).
pub(super) fn create_temporary(dir: &Path, name: &str) -> std::io::Result<(PathBuf, File)> {
    loop {
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let tmp = dir.join(format!(".{name}.tmp{}-{n}", std::process::id()));
        match OpenOptions::new()
            .read(true)
            .write(true)
            .create_new(true)
            .open(&tmp)
        {
            Ok(file) => return Ok((tmp, file)),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
            Err(e) => return Err(e),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn leftovers(dir: &Path) -> Vec<String> {
        fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.contains(".tmp"))
            .collect()
    }

    #[test]
    fn failed_write_keeps_the_old_file_and_leaves_no_temporary() {
        let dir = std::env::temp_dir().join(format!("isobar-atomic-{}", std::process::id()));
        fs::create_dir_all(&dir).unwrap();
        let path = dir.join("mesh.ply");
        write_atomically(&path, |w| w.write_all(b"old contents")).unwrap();
        assert!(leftovers(&dir).is_empty());

        let err = write_atomically(&path, |w| {
            w.write_all(b"half of the new")?;
            Err(std::io::Error::other("disk full (simulated)"))
        })
        .unwrap_err();
        assert!(err.to_string().contains("mesh.ply"), "{err}");
        assert!(err.to_string().contains("disk full"), "{err}");
        assert_eq!(fs::read(&path).unwrap(), b"old contents");
        assert!(leftovers(&dir).is_empty());

        write_atomically(&path, |w| w.write_all(b"new")).unwrap();
        assert_eq!(fs::read(&path).unwrap(), b"new");
        assert!(leftovers(&dir).is_empty());
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn folders_and_pipes_are_neither_replaced_nor_read() {
        let dir = std::env::temp_dir().join(format!("isobar-atomic-nf-{}", std::process::id()));
        let folder = dir.join("out.ply");
        fs::create_dir_all(&folder).unwrap();
        let e = write_atomically(&folder, |w| w.write_all(b"mesh")).unwrap_err();
        assert!(e.to_string().contains("not a regular file"), "{e}");
        assert!(folder.is_dir(), "the folder is still there");
        assert!(leftovers(&dir).is_empty());
        // A link to an earlier output is still written through, as before.
        let earlier = dir.join("earlier.ply");
        fs::write(&earlier, b"old").unwrap();
        let link = dir.join("link.ply");
        std::os::unix::fs::symlink(&earlier, &link).unwrap();
        write_atomically(&link, |w| w.write_all(b"new")).unwrap();
        assert_eq!(fs::read(&link).unwrap(), b"new");
        // A FIFO: reading it would block until a writer came; refused before opening.
        let fifo = dir.join("frame.vtk");
        let name = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
        // SAFETY: a NUL-terminated path.
        assert_eq!(unsafe { libc::mkfifo(name.as_ptr(), 0o600) }, 0);
        let e = read_regular_file(&fifo).unwrap_err();
        assert!(e.to_string().contains("frame.vtk"), "{e}");
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn missing_directory_is_an_io_error_naming_the_file() {
        let path = Path::new("/nonexistent-isobar-dir/out.vtp");
        let err = write_atomically(path, |_| Ok(())).unwrap_err();
        assert!(matches!(err, Error::Io { .. }));
        assert!(err.to_string().contains("out.vtp"));
    }
}
