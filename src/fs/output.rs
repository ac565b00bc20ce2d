//! Output files (images, benchmark JSON, BVH cache files) written so that nothing but the
//! named path is ever changed, and each file appears whole or not at all.
//!
//! A file is first written to a temporary file beside its path, created with an unpredictable
//! name and `O_EXCL` ([`tempfile::Builder`]): a symbolic link planted at a temporary name can
//! neither be followed nor guessed. It is then renamed over the path. Before and again just
//! before the rename, the path is checked ([`check_target`]): only a regular file is
//! replaced, and never one of the command's inputs. A FIFO at the path is written into instead
//! (the user named a pipe), when the caller allows it: the first check opens it, so a FIFO no
//! process reads is refused before the command's work, and holds it open until the write; a
//! symbolic link, a device, a socket or a directory is refused. [`commit_all`] puts several files in place, both or neither.
//!
//! This is the one way raypack writes a file: images, camera files, `bench --json`, ray files,
//! report pages and charts, and BVH cache files all go through [`stage`] (and
//! [`write_file`], which stages and commits one file). `tests/one_reader_one_writer.rs` fails
//! when a new write elsewhere bypasses it.
//!
//! What remains: another process that can write the directory may change what is at the path
//! between the last check and the rename; the rename then replaces that entry itself (never
//! what a link points to), so nothing outside the directory entry is written.

use crate::fs::input::describe_type;
use std::io::Write;
use std::path::{Path, PathBuf};

/// Why an output file could not be written.
#[derive(Debug, thiserror::Error)]
#[error("cannot write {}: {source}", path.display())]
pub struct OutputError {
    /// The output path.
    pub path: PathBuf,
    /// What went wrong (the message says what was found at the path).
    pub source: std::io::Error,
}

fn fail(path: &Path, kind: std::io::ErrorKind, message: String) -> OutputError {
    OutputError { path: path.to_path_buf(), source: std::io::Error::new(kind, message) }
}

fn io_error(path: &Path) -> impl Fn(std::io::Error) -> OutputError + '_ {
    move |source| OutputError { path: path.to_path_buf(), source }
}

/// How to write an output file.
#[derive(Clone, Debug)]
pub struct OutputOptions {
    /// Permission bits of the new file: `0o666` (less the umask) for images, `0o644` for cache
    /// files.
    pub mode: u32,
    /// Give the file exactly [`OutputOptions::mode`], whatever the umask (cache files that
    /// other users read).
    pub exact_mode: bool,
    /// Files that must not be overwritten (the command's inputs), compared by identity
    /// (device and inode), so another name for the same file is refused too.
    pub inputs: Vec<PathBuf>,
    /// Write into a FIFO found at the path (the user named a pipe) instead of refusing it.
    pub allow_fifo: bool,
    /// `fsync` the file before renaming it into place.
    pub sync: bool,
}

impl Default for OutputOptions {
    fn default() -> Self {
        Self { mode: 0o666, exact_mode: false, inputs: Vec::new(), allow_fifo: true, sync: true }
    }
}

impl OutputOptions {
    /// The defaults, refusing to overwrite `inputs`.
    pub fn protecting(inputs: &[&Path]) -> Self {
        Self { inputs: inputs.iter().map(|p| p.to_path_buf()).collect(), ..Self::default() }
    }
}

/// What is at an output path.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Target {
    /// Nothing: the file will be created.
    Absent,
    /// A regular file that is not an input: it will be replaced.
    Regular,
    /// A FIFO: the bytes will be written into it.
    Fifo,
}

/// Checks what is at `path` and whether it may be written (see the module docs).
pub fn check_target(path: &Path, opts: &OutputOptions) -> Result<Target, OutputError> {
    let meta = match std::fs::symlink_metadata(path) {
        Ok(m) => m,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            // Checked now so that a command fails before its work, not after.
            let dir = parent_dir(path);
            return match std::fs::metadata(dir) {
                Ok(m) if m.is_dir() => Ok(Target::Absent),
                Ok(m) => Err(fail(
                    path,
                    std::io::ErrorKind::NotADirectory,
                    format!("{} is {}, not a directory", dir.display(), describe_type(&m)),
                )),
                Err(e) => Err(fail(path, e.kind(), format!("directory {}: {e}", dir.display()))),
            };
        }
        Err(e) => return Err(io_error(path)(e)),
    };
    let t = meta.file_type();
    if t.is_symlink() {
        let to = std::fs::read_link(path).map(|p| format!(" (to {})", p.display())).unwrap_or_default();
        return Err(fail(
            path,
            std::io::ErrorKind::InvalidInput,
            format!(
                "is a symbolic link{to}; raypack neither writes through links nor replaces them (name the file \
                 itself, or remove the link)"
            ),
        ));
    }
    if t.is_file() {
        if let Some(input) = opts.inputs.iter().find(|i| same_file(path, &meta, i)) {
            return Err(fail(
                path,
                std::io::ErrorKind::InvalidInput,
                format!("is the input file {}; refusing to overwrite it", input.display()),
            ));
        }
        return Ok(Target::Regular);
    }
    #[cfg(unix)]
    if opts.allow_fifo && std::os::unix::fs::FileTypeExt::is_fifo(&t) {
        hold_fifo(path, &meta)?;
        return Ok(Target::Fifo);
    }
    Err(fail(
        path,
        std::io::ErrorKind::InvalidInput,
        format!("is {}, not a regular file; raypack replaces only regular files", describe_type(&meta)),
    ))
}

/// The directory `path` is in (`.` for a bare file name).
fn parent_dir(path: &Path) -> &Path {
    match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    }
}

/// True when `meta` (of the regular file at an output path) and the file at `input` are the
/// same file.
#[cfg(unix)]
fn same_file(_path: &Path, meta: &std::fs::Metadata, input: &Path) -> bool {
    use std::os::unix::fs::MetadataExt;
    std::fs::metadata(input).is_ok_and(|other| meta.dev() == other.dev() && meta.ino() == other.ino())
}

#[cfg(not(unix))]
fn same_file(path: &Path, _meta: &std::fs::Metadata, input: &Path) -> bool {
    std::fs::canonicalize(path).is_ok_and(|p| std::fs::canonicalize(input).is_ok_and(|i| i == p))
}

/// A file written beside its path, not yet in place ([`Staged::commit`], [`commit_all`]).
/// Dropping it removes the temporary file.
#[derive(Debug)]
pub struct Staged {
    path: PathBuf,
    target: Target,
    pending: Pending,
    opts: OutputOptions,
}

#[derive(Debug)]
enum Pending {
    /// The temporary file in the path's directory.
    File(tempfile::NamedTempFile),
    /// The bytes for a FIFO.
    Bytes(Vec<u8>),
}

/// Writes the file for `path` through `write` (see the module docs); nothing is at `path`
/// until [`Staged::commit`].
pub fn stage(
    path: &Path,
    opts: &OutputOptions,
    write: &mut dyn FnMut(&mut dyn Write) -> std::io::Result<()>,
) -> Result<Staged, OutputError> {
    let target = check_target(path, opts)?;
    let pending = match target {
        Target::Fifo => {
            let mut bytes = Vec::new();
            write(&mut bytes).map_err(io_error(path))?;
            Pending::Bytes(bytes)
        }
        Target::Absent | Target::Regular => Pending::File(write_temporary(path, opts, write)?),
    };
    Ok(Staged { path: path.to_path_buf(), target, pending, opts: opts.clone() })
}

fn write_temporary(
    path: &Path,
    opts: &OutputOptions,
    write: &mut dyn FnMut(&mut dyn Write) -> std::io::Result<()>,
) -> Result<tempfile::NamedTempFile, OutputError> {
    let dir = parent_dir(path);
    let name = path
        .file_name()
        .ok_or_else(|| fail(path, std::io::ErrorKind::InvalidInput, "does not name a file".into()))?
        .to_string_lossy();
    let prefix = format!(".{name}.");
    let mut builder = tempfile::Builder::new();
    builder.prefix(&prefix).suffix(".tmp");
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        builder.permissions(std::fs::Permissions::from_mode(opts.mode));
    }
    let mut tmp = builder.tempfile_in(dir).map_err(io_error(path))?;
    // Locked while it is written (the lock goes with the last descriptor, even on SIGKILL), so
    // that [`remove_stale_temporaries`] can tell a live writer's file from a dead one's.
    #[cfg(unix)]
    {
        use std::os::fd::AsRawFd;
        // SAFETY: flock on a descriptor `tmp` owns and keeps open, with integer arguments only.
        unsafe { libc::flock(tmp.as_file().as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) };
    }
    let tmp_err = |source| OutputError { path: tmp.path().to_path_buf(), source };
    #[cfg(unix)]
    if opts.exact_mode {
        use std::os::unix::fs::PermissionsExt;
        tmp.as_file().set_permissions(std::fs::Permissions::from_mode(opts.mode)).map_err(tmp_err)?;
    }
    {
        let mut w = std::io::BufWriter::with_capacity(1 << 20, tmp.as_file_mut());
        write(&mut w).and_then(|()| w.flush()).map_err(io_error(path))?;
    }
    if opts.sync {
        tmp.as_file().sync_all().map_err(io_error(path))?;
    }
    Ok(tmp)
}

impl Staged {
    /// The path the file goes to.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Puts the file in place.
    pub fn commit(self) -> Result<(), OutputError> {
        commit_all(vec![self])
    }

    /// Renames or writes the file into place after checking the path once more; returns
    /// whether it created the path (nothing was there).
    fn put_in_place(self) -> Result<bool, OutputError> {
        let now = check_target(&self.path, &self.opts)?;
        match (self.pending, now) {
            (Pending::Bytes(bytes), Target::Fifo) => write_fifo(&self.path, &bytes).map(|()| false),
            (Pending::File(tmp), Target::Absent) => match tmp.persist_noclobber(&self.path) {
                Ok(_) => Ok(true),
                // Created meanwhile: replace it only if it is a regular file that may go.
                Err(e) if e.error.kind() == std::io::ErrorKind::AlreadyExists => {
                    check_regular(&self.path, &self.opts)?;
                    e.file.persist(&self.path).map(|_| false).map_err(|e| io_error(&self.path)(e.error))
                }
                Err(e) => Err(io_error(&self.path)(e.error)),
            },
            (Pending::File(tmp), Target::Regular) => {
                tmp.persist(&self.path).map(|_| false).map_err(|e| io_error(&self.path)(e.error))
            }
            (_, now) => Err(fail(
                &self.path,
                std::io::ErrorKind::Other,
                format!("changed while the file was written (was {:?}, is {now:?})", self.target),
            )),
        }
    }
}

fn check_regular(path: &Path, opts: &OutputOptions) -> Result<(), OutputError> {
    match check_target(path, opts)? {
        Target::Regular => Ok(()),
        other => Err(fail(path, std::io::ErrorKind::Other, format!("changed while the file was written ({other:?})"))),
    }
}

/// FIFOs opened for writing when their path was checked, held open until their bytes are
/// written: the reader found then sees no end of file in between, and a FIFO without a
/// reader is refused by the first check, before any work, not after it.
#[cfg(unix)]
static HELD_FIFOS: std::sync::Mutex<Vec<std::fs::File>> = std::sync::Mutex::new(Vec::new());

/// The device and inode of `meta`.
#[cfg(unix)]
fn identity(meta: &std::fs::Metadata) -> (u64, u64) {
    use std::os::unix::fs::MetadataExt;
    (meta.dev(), meta.ino())
}

/// Opens the FIFO at `path` for writing without waiting: fails at once when no process reads
/// it.
#[cfg(unix)]
fn open_fifo(path: &Path) -> Result<std::fs::File, OutputError> {
    use std::os::unix::fs::{FileTypeExt, OpenOptionsExt};
    let file = std::fs::OpenOptions::new()
        .write(true)
        // Non-blocking: an open for writing with no reader fails (ENXIO) instead of waiting.
        .custom_flags(libc::O_NONBLOCK | libc::O_NOCTTY | libc::O_NOFOLLOW)
        .open(path)
        .map_err(|e| match e.raw_os_error() {
            Some(libc::ENXIO) => fail(
                path,
                std::io::ErrorKind::BrokenPipe,
                "is a FIFO (named pipe) that no process reads; start its reader first".into(),
            ),
            _ => io_error(path)(e),
        })?;
    if !file.metadata().map_err(io_error(path))?.file_type().is_fifo() {
        return Err(fail(path, std::io::ErrorKind::Other, "changed while the file was written".into()));
    }
    Ok(file)
}

/// Makes sure the FIFO `meta` describes, at `path`, has a reader and stays open for the
/// write ([`HELD_FIFOS`]).
#[cfg(unix)]
fn hold_fifo(path: &Path, meta: &std::fs::Metadata) -> Result<(), OutputError> {
    let mut held = HELD_FIFOS.lock().unwrap_or_else(|e| e.into_inner());
    if held.iter().any(|f| f.metadata().is_ok_and(|m| identity(&m) == identity(meta))) {
        return Ok(());
    }
    held.push(open_fifo(path)?);
    Ok(())
}

/// Writes `bytes` into the FIFO at `path` (through the descriptor its check opened, if it is
/// the same FIFO); fails at once when no process reads it.
#[cfg(unix)]
fn write_fifo(path: &Path, bytes: &[u8]) -> Result<(), OutputError> {
    use std::os::fd::AsRawFd;
    let now = std::fs::symlink_metadata(path).map(|m| identity(&m)).ok();
    let held = {
        let mut held = HELD_FIFOS.lock().unwrap_or_else(|e| e.into_inner());
        let at = held.iter().position(|f| f.metadata().is_ok_and(|m| Some(identity(&m)) == now));
        at.map(|i| held.swap_remove(i))
    };
    let mut file = match held {
        Some(f) => f,
        None => open_fifo(path)?,
    };
    // Blocking writes from here on: the reader sets the pace.
    let fd = file.as_raw_fd();
    // SAFETY: fcntl on a descriptor `file` owns and keeps open, with integer arguments only.
    let cleared = unsafe { libc::fcntl(fd, libc::F_SETFL, libc::fcntl(fd, libc::F_GETFL) & !libc::O_NONBLOCK) };
    if cleared < 0 {
        return Err(io_error(path)(std::io::Error::last_os_error()));
    }
    file.write_all(bytes).and_then(|()| file.flush()).map_err(io_error(path))
}

#[cfg(not(unix))]
fn write_fifo(path: &Path, _bytes: &[u8]) -> Result<(), OutputError> {
    Err(fail(path, std::io::ErrorKind::Unsupported, "FIFOs are not supported here".into()))
}

/// Puts every staged file in place, or none: all paths are checked first, and when one fails
/// after others were put in place, the files this call created are removed again. (A file
/// that replaced an older one cannot be undone; that failure needs another process changing
/// the directory between the checks and the renames.)
pub fn commit_all(staged: Vec<Staged>) -> Result<(), OutputError> {
    for s in &staged {
        let now = check_target(&s.path, &s.opts)?;
        if now == Target::Fifo && matches!(s.pending, Pending::File(_)) {
            return Err(fail(&s.path, std::io::ErrorKind::Other, "became a FIFO while the file was written".into()));
        }
    }
    let mut created = Vec::new();
    for s in staged {
        let path = s.path.clone();
        match s.put_in_place() {
            Ok(true) => created.push(path),
            Ok(false) => {}
            Err(e) => {
                for p in created {
                    let _ = std::fs::remove_file(p);
                }
                return Err(e);
            }
        }
    }
    Ok(())
}

/// Removes the temporary files of `path` (`.NAME.XXXXXX.tmp` beside it) that a writer killed
/// before it could remove them left behind: those owned by this user that no process holds
/// locked (a live writer locks its temporary file until it is renamed into place). Returns how
/// many were removed; a directory that cannot be read removes none.
#[cfg(unix)]
pub fn remove_stale_temporaries(path: &Path) -> usize {
    use std::os::fd::AsRawFd;
    use std::os::unix::fs::{MetadataExt, OpenOptionsExt};
    let (dir, Some(name)) = (parent_dir(path), path.file_name()) else { return 0 };
    let prefix = format!(".{}.", name.to_string_lossy());
    let Ok(entries) = std::fs::read_dir(dir) else { return 0 };
    // SAFETY: geteuid has no preconditions and cannot fail.
    let me = unsafe { libc::geteuid() };
    let mut removed = 0;
    for entry in entries.flatten() {
        let file_name = entry.file_name();
        let n = file_name.to_string_lossy();
        if !(n.starts_with(&prefix) && n.ends_with(".tmp") && n.len() > prefix.len() + ".tmp".len()) {
            continue;
        }
        let p = entry.path();
        let Ok(meta) = std::fs::symlink_metadata(&p) else { continue };
        if !meta.is_file() || meta.uid() != me {
            continue;
        }
        let opened = std::fs::OpenOptions::new()
            .read(true)
            .custom_flags(libc::O_NONBLOCK | libc::O_NOCTTY | libc::O_NOFOLLOW)
            .open(&p);
        let Ok(file) = opened else { continue };
        // SAFETY: flock on a descriptor `file` owns and keeps open, with integer arguments only.
        if unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } != 0 {
            continue; // a live writer holds it
        }
        // Still the file that was opened (not replaced meanwhile): remove it.
        let same = file.metadata().is_ok_and(|m| identity(&m) == identity(&meta));
        if same && std::fs::symlink_metadata(&p).is_ok_and(|m| identity(&m) == identity(&meta)) {
            removed += usize::from(std::fs::remove_file(&p).is_ok());
        }
    }
    removed
}

/// Writes `bytes` to `path` with the default [`OutputOptions`]: whole or not at all, never
/// through a link or over anything but a regular file.
pub fn write_file(path: &Path, bytes: &[u8]) -> Result<(), OutputError> {
    write_file_with(path, bytes, &OutputOptions::default())
}

/// [`write_file`] with options.
pub fn write_file_with(path: &Path, bytes: &[u8], opts: &OutputOptions) -> Result<(), OutputError> {
    stage(path, opts, &mut |w| w.write_all(bytes))?.commit()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> =
            std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().into_string().unwrap()).collect();
        v.sort();
        v
    }

    #[test]
    fn writes_whole_files_and_refuses_links_directories_and_inputs() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("out.txt");
        write_file(&out, b"one").unwrap();
        write_file(&out, b"two").unwrap();
        assert_eq!(std::fs::read(&out).unwrap(), b"two");
        let input = dir.path().join("in.txt");
        std::fs::write(&input, b"input").unwrap();
        let e = write_file_with(&input, b"x", &OutputOptions::protecting(&[&input])).unwrap_err();
        assert!(e.to_string().contains("is the input file"), "{e}");
        std::fs::create_dir(dir.path().join("d")).unwrap();
        let e = write_file(&dir.path().join("d"), b"x").unwrap_err();
        assert!(e.to_string().contains("is a directory"), "{e}");
        #[cfg(unix)]
        {
            let link = dir.path().join("link");
            std::os::unix::fs::symlink(&input, &link).unwrap();
            let e = write_file(&link, b"x").unwrap_err();
            assert!(e.to_string().contains("symbolic link"), "{e}");
        }
        assert_eq!(std::fs::read(&input).unwrap(), b"input");
        // A failed writer leaves nothing behind.
        let e = stage(&dir.path().join("new.txt"), &OutputOptions::default(), &mut |_| {
            Err(std::io::Error::other("encoder failed"))
        });
        assert!(e.is_err());
        let mut expected = vec!["d", "in.txt", "out.txt"];
        if cfg!(unix) {
            expected.insert(2, "link");
        }
        assert_eq!(names(dir.path()), expected);
    }

    #[test]
    fn commit_all_puts_both_or_neither() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join("a"), dir.path().join("b"));
        let opts = OutputOptions::default();
        let sa = stage(&a, &opts, &mut |w| w.write_all(b"a")).unwrap();
        let sb = stage(&b, &opts, &mut |w| w.write_all(b"b")).unwrap();
        // `b` becomes a directory after staging: neither file appears.
        std::fs::create_dir(&b).unwrap();
        assert!(commit_all(vec![sa, sb]).is_err());
        assert_eq!(names(dir.path()), ["b"]);
    }
}
