//! Output files that are never half-written and never destroyed by a failed write.
//!
//! [`write_atomic`] writes a regular file through a temporary file in the same folder
//! (`.NAME.tmp-PID-N`), flushed to disk and renamed over `path` only when complete; on any
//! error (or a panic in the writer) the temporary file is removed and whatever was at `path`
//! keeps its bytes. [`check_writable`] is the same checks done before a long computation,
//! so that it never ends in "cannot write".
//!
//! Paths that are not regular files get their own rules:
//! - a device, FIFO or socket (`/dev/null`, `/dev/full`, `/dev/stdout` on a pipe, a named
//!   pipe) is written in place and never removed or replaced: there is no file whose bytes
//!   could be lost, and renaming over it would replace the node itself (issue 17: `--out
//!   /dev/full` deleted the device node);
//! - a symbolic link to a file (or to a missing file) is followed and its target replaced,
//!   so the link stays a link;
//! - a folder is refused.
//!
//! An existing regular file that this process cannot write (e.g. `chmod 444`) is refused
//! rather than replaced, since a rename would ignore its permission bits. The replaced
//! file keeps its permission bits; hard links to it keep the old content (as with any
//! editor's safe save).

use crate::error::IoError;
use std::fs::{File, OpenOptions};
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// Where the bytes of a write to `path` go.
enum Target {
    /// A device, FIFO or socket: written in place.
    Special,
    /// A regular file (existing or not) at this path, all final symlinks resolved.
    File(PathBuf),
}

/// Writes `path` by calling `write` with a buffered writer; see the module documentation.
/// The writer's error (or a flush, sync or rename error) is returned naming `path`.
pub fn write_atomic<T>(
    path: impl AsRef<Path>,
    write: impl FnOnce(&mut dyn Write) -> io::Result<T>,
) -> Result<T, IoError> {
    let path = path.as_ref();
    let err = |source: io::Error| IoError::Io { path: path.to_path_buf(), source };
    match target(path).map_err(err)? {
        Target::Special => write_in_place(path, write).map_err(err),
        Target::File(file) => {
            check_replaceable(&file).map_err(err)?;
            write_via_temp(&file, write).map_err(err)
        }
    }
}

/// Fails unless `path` could be written by [`write_atomic`] now: not a folder, not a read-only
/// file, and a temporary file can be created (and is removed again) in its folder. Creates
/// nothing else: the caller creates missing folders first.
pub fn check_writable(path: impl AsRef<Path>) -> Result<(), IoError> {
    let path = path.as_ref();
    let err = |source: io::Error| IoError::Io { path: path.to_path_buf(), source };
    match target(path).map_err(err)? {
        // Opening a FIFO for writing waits for a reader: devices are checked by the write.
        Target::Special => Ok(()),
        Target::File(file) => {
            check_replaceable(&file).map_err(err)?;
            let (tmp, handle) = create_temp(&file).map_err(err)?;
            drop(handle);
            std::fs::remove_file(&tmp).map_err(err)
        }
    }
}

fn target(path: &Path) -> io::Result<Target> {
    match std::fs::metadata(path) {
        Ok(m) if m.is_dir() => Err(io::Error::new(io::ErrorKind::InvalidInput, "is a folder, not a file")),
        Ok(m) if !m.is_file() => Ok(Target::Special),
        Ok(_) => Ok(Target::File(resolve_links(path)?)),
        Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(Target::File(resolve_links(path)?)),
        Err(e) => Err(e),
    }
}

/// `path` with its last component's symbolic links followed (also a dangling link, whose
/// target is then created). The folders above are left to the kernel, which resolves them
/// the same way for the temporary file and the rename.
fn resolve_links(path: &Path) -> io::Result<PathBuf> {
    let mut p = path.to_path_buf();
    for _ in 0..40 {
        match std::fs::symlink_metadata(&p) {
            Ok(m) if m.file_type().is_symlink() => {
                let link = std::fs::read_link(&p)?;
                p = match p.parent() {
                    Some(dir) => dir.join(link),
                    None => link,
                };
            }
            _ => return Ok(p),
        }
    }
    Err(io::Error::new(io::ErrorKind::InvalidInput, "too many levels of symbolic links"))
}

/// An existing file must be writable by us: a rename would replace even a read-only one.
fn check_replaceable(file: &Path) -> io::Result<()> {
    match OpenOptions::new().write(true).open(file) {
        Ok(_) => Ok(()),
        Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(()),
        Err(e) if e.kind() == io::ErrorKind::PermissionDenied => Err(io::Error::new(
            e.kind(),
            "the file exists and is not writable (read-only?); it was left as it is",
        )),
        Err(e) => Err(e),
    }
}

fn write_in_place<T>(path: &Path, write: impl FnOnce(&mut dyn Write) -> io::Result<T>) -> io::Result<T> {
    let mut w = BufWriter::new(OpenOptions::new().write(true).open(path)?);
    let value = write(&mut w)?;
    w.flush()?;
    Ok(value)
}

fn write_via_temp<T>(file: &Path, write: impl FnOnce(&mut dyn Write) -> io::Result<T>) -> io::Result<T> {
    let (tmp, handle) = create_temp(file)?;
    // Removes the temporary file on every early return and on a panic in `write`.
    let mut guard = RemoveOnDrop(Some(tmp));
    let mut w = BufWriter::new(handle);
    let value = write(&mut w)?;
    let handle = w.into_inner().map_err(|e| e.into_error())?;
    if let Ok(old) = std::fs::metadata(file) {
        handle.set_permissions(old.permissions())?;
    }
    // On disk before the rename, so that a crash never leaves an empty file at `file`.
    handle.sync_all()?;
    drop(handle);
    std::fs::rename(guard.path(), file)?;
    guard.disarm();
    Ok(value)
}

/// Creates `.NAME.tmp-PID-N` beside `file` (a fresh name: never opens an existing file).
fn create_temp(file: &Path) -> io::Result<(PathBuf, File)> {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let name = file.file_name().ok_or_else(|| io::Error::new(io::ErrorKind::InvalidInput, "no file name"))?;
    let dir = file.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    for _ in 0..1000 {
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let mut tmp_name = std::ffi::OsString::from(".");
        tmp_name.push(name);
        tmp_name.push(format!(".tmp-{}-{n}", std::process::id()));
        let tmp = dir.join(tmp_name);
        match OpenOptions::new().write(true).create_new(true).open(&tmp) {
            Ok(f) => return Ok((tmp, f)),
            // Left by an earlier process of the same id: take the next number.
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists => continue,
            Err(e) => return Err(e),
        }
    }
    Err(io::Error::new(io::ErrorKind::AlreadyExists, "no free temporary file name beside it"))
}

struct RemoveOnDrop(Option<PathBuf>);

impl RemoveOnDrop {
    fn path(&self) -> &Path {
        self.0.as_deref().expect("armed")
    }
    fn disarm(&mut self) {
        self.0 = None;
    }
}

impl Drop for RemoveOnDrop {
    fn drop(&mut self) {
        if let Some(p) = self.0.take() {
            let _ = std::fs::remove_file(p);
        }
    }
}
