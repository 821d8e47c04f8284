//! Bytes written once, in order, and read back later: in memory, or in an anonymous
//! temporary file when they must not count against a memory budget (an external-memory
//! build's sorted runs and sections).
//!
//! The file is created beside the output (the same file system, which has room for the
//! output anyway) and unlinked at once: it has no name to leave behind, whatever happens
//! to the process.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::os::unix::fs::FileExt;
use std::path::Path;

/// Bytes read back a slice at a time: bounded memory whatever the spool's length.
const READ_CHUNK: usize = 1 << 20;

/// A file spool's write buffer: a build holds a couple of dozen spools open at once.
const WRITE_BUFFER: usize = 1 << 13;

pub(crate) enum Spool {
    Memory(Vec<u8>),
    /// A file being written.
    File {
        writer: BufWriter<File>,
        len: u64,
    },
    /// A file written whole: no write buffer held (a merge holds many runs open).
    Finished {
        file: File,
        len: u64,
    },
}

impl Spool {
    /// A spool in memory.
    pub(crate) fn memory() -> Spool {
        Spool::Memory(Vec::new())
    }

    /// A spool in an unnamed temporary file in `dir`.
    pub(crate) fn file(dir: &Path) -> std::io::Result<Spool> {
        let (path, file) = super::atomic::create_temporary(dir, "spool")?;
        std::fs::remove_file(&path)?;
        Ok(Spool::File {
            writer: BufWriter::with_capacity(WRITE_BUFFER, file),
            len: 0,
        })
    }

    /// In memory, or (when `on_disk`) in a file in `dir`.
    pub(crate) fn new(on_disk: bool, dir: &Path) -> std::io::Result<Spool> {
        if on_disk {
            Spool::file(dir)
        } else {
            Ok(Spool::memory())
        }
    }

    pub(crate) fn write(&mut self, bytes: &[u8]) -> std::io::Result<()> {
        match self {
            Spool::Memory(v) => {
                v.extend_from_slice(bytes);
                Ok(())
            }
            Spool::File { writer, len } => {
                *len += bytes.len() as u64;
                writer.write_all(bytes)
            }
            Spool::Finished { .. } => Err(std::io::Error::other("spool written after finish")),
        }
    }

    /// Bytes written so far.
    pub(crate) fn len(&self) -> u64 {
        match self {
            Spool::Memory(v) => v.len() as u64,
            Spool::File { len, .. } | Spool::Finished { len, .. } => *len,
        }
    }

    /// Bytes held in memory (a file spool holds its write buffer).
    pub(crate) fn held_bytes(&self) -> u64 {
        match self {
            Spool::Memory(v) => v.capacity() as u64,
            Spool::File { writer, .. } => writer.capacity() as u64,
            Spool::Finished { .. } => 0,
        }
    }

    /// Makes everything written readable (and frees a file's write buffer): call once
    /// writing is done.
    pub(crate) fn finish(&mut self) -> std::io::Result<()> {
        if let Spool::File { writer, len } = self {
            writer.flush()?;
            let len = *len;
            let file = writer.get_ref().try_clone()?;
            *self = Spool::Finished { file, len };
        }
        Ok(())
    }

    /// Fills `buf` from byte `at` on (after [`Spool::finish`]); fewer bytes at the end.
    /// Returns how many were read.
    pub(crate) fn read_at(&self, at: u64, buf: &mut [u8]) -> std::io::Result<usize> {
        let want = (self.len().saturating_sub(at)).min(buf.len() as u64) as usize;
        match self {
            Spool::Memory(v) => {
                buf[..want].copy_from_slice(&v[at as usize..at as usize + want]);
            }
            Spool::File { writer, .. } => writer.get_ref().read_exact_at(&mut buf[..want], at)?,
            Spool::Finished { file, .. } => file.read_exact_at(&mut buf[..want], at)?,
        }
        Ok(want)
    }

    /// Hands every byte to `out`, a bounded slice at a time (after [`Spool::finish`]).
    pub(crate) fn read_into(
        &self,
        out: &mut dyn FnMut(&[u8]) -> std::io::Result<()>,
    ) -> std::io::Result<()> {
        match self {
            Spool::Memory(v) => v.chunks(READ_CHUNK).try_for_each(out),
            Spool::File { len, .. } | Spool::Finished { len, .. } => {
                let mut buf = vec![0u8; READ_CHUNK.min(*len as usize)];
                let mut at = 0u64;
                while at < *len {
                    let n = self.read_at(at, &mut buf)?;
                    out(&buf[..n])?;
                    at += n as u64;
                }
                Ok(())
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn file_and_memory_spools_read_back_what_was_written() {
        let dir = std::env::temp_dir().join(format!("isobar-spool-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let bytes: Vec<u8> = (0..3 * READ_CHUNK + 77)
            .map(|i| (i * 31 % 251) as u8)
            .collect();
        for on_disk in [false, true] {
            let mut s = Spool::new(on_disk, &dir).unwrap();
            for piece in bytes.chunks(10_007) {
                s.write(piece).unwrap();
            }
            s.finish().unwrap();
            assert_eq!(s.len(), bytes.len() as u64);
            let mut back = Vec::new();
            s.read_into(&mut |b| {
                back.extend_from_slice(b);
                Ok(())
            })
            .unwrap();
            assert_eq!(back, bytes, "on disk: {on_disk}");
            let mut tail = [0u8; 100];
            let n = s.read_at(bytes.len() as u64 - 40, &mut tail).unwrap();
            assert_eq!(&tail[..n], &bytes[bytes.len() - 40..]);
        }
        // The file spool left no name behind.
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 0);
        std::fs::remove_dir(&dir).unwrap();
    }
}
