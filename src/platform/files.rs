//! Files read and written with care, one way everywhere.
//!
//! - A write replaces a file whole or not at all: the bytes go to a temporary
//!   file of a name no other write shares, are fsynced, renamed over the
//!   target, and the directory is fsynced, so that a reader (or a reboot)
//!   sees the old file or the new one, never half of one.
//! - A read refuses a file larger than what its kind can be before reading
//!   it, so that a wrong path cannot fill the memory, and takes only a
//!   regular file: a FIFO would wait forever for a writer, and a device
//!   (`/dev/zero`) never ends.

use std::fs::{self, File, OpenOptions};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// What failed on which file.
#[derive(Debug, thiserror::Error)]
#[error("{}: cannot {action}: {source}", path.display())]
pub struct FileError {
    pub path: PathBuf,
    /// What was being done, as a verb phrase: "create", "replace", ….
    pub action: &'static str,
    pub source: std::io::Error,
}

fn failed<'a>(
    path: &'a Path,
    action: &'static str,
) -> impl FnOnce(std::io::Error) -> FileError + 'a {
    move |source| FileError {
        path: path.to_path_buf(),
        action,
        source,
    }
}

/// The part of a temporary file's name that marks it as one:
/// `.NAME.tmp-PID-N`. Only a write killed mid-way leaves one behind.
pub const TEMPORARY_MARK: &str = ".tmp-";

/// Whether a directory entry is the temporary file of a write.
pub fn is_temporary(file_name: &str) -> bool {
    file_name.starts_with('.') && file_name.contains(TEMPORARY_MARK)
}

/// A file being written whole or not at all (see the module), for outputs
/// written piece by piece (an MCAP file of a whole session): write to
/// [`AtomicFile::file`], then [`AtomicFile::commit`]. Dropped without a
/// commit, it removes what it wrote and leaves the old file, if any.
pub struct AtomicFile {
    path: PathBuf,
    dir: PathBuf,
    temporary: PathBuf,
    file: File,
    committed: bool,
}

impl AtomicFile {
    /// Starts a write of `path`, creating its directory if needed.
    pub fn create(path: &Path) -> Result<Self, FileError> {
        static WRITES: AtomicU64 = AtomicU64::new(0);
        let dir = match path.parent() {
            Some(dir) if !dir.as_os_str().is_empty() => dir,
            _ => Path::new("."),
        };
        fs::create_dir_all(dir).map_err(failed(dir, "create the directory"))?;
        let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("file");
        let temporary = dir.join(format!(
            ".{name}{TEMPORARY_MARK}{}-{}",
            std::process::id(),
            WRITES.fetch_add(1, Ordering::Relaxed)
        ));
        let file = OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&temporary)
            .map_err(failed(&temporary, "create"))?;
        Ok(Self {
            path: path.to_path_buf(),
            dir: dir.to_path_buf(),
            temporary,
            file,
            committed: false,
        })
    }

    /// The temporary file to write to.
    pub fn file(&mut self) -> &mut File {
        &mut self.file
    }

    /// The error of a write to [`AtomicFile::file`], naming the file.
    pub fn write_error(&self, source: std::io::Error) -> FileError {
        failed(&self.temporary, "write")(source)
    }

    /// Syncs the file and puts it in place of the old one.
    pub fn commit(mut self) -> Result<(), FileError> {
        self.file
            .sync_all()
            .map_err(failed(&self.temporary, "sync"))?;
        fs::rename(&self.temporary, &self.path).map_err(failed(&self.path, "replace"))?;
        self.committed = true;
        File::open(&self.dir)
            .and_then(|d| d.sync_all())
            .map_err(failed(&self.dir, "sync the directory"))
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        if !self.committed {
            let _ = fs::remove_file(&self.temporary);
        }
    }
}

/// Writes `bytes` to `path` atomically and durably (see the module), creating
/// the directory if needed. On failure the temporary file is removed and the
/// old file, if any, is untouched.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> Result<(), FileError> {
    let mut file = AtomicFile::create(path)?;
    file.file()
        .write_all(bytes)
        .map_err(|e| file.write_error(e))?;
    file.commit()
}

/// Why a bounded read failed.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    #[error(transparent)]
    File(#[from] FileError),
    /// The file is larger than its kind can be.
    #[error("{}: larger than {max_bytes} bytes: not an input of this kind", path.display())]
    TooLarge { path: PathBuf, max_bytes: u64 },
}

/// Opens a regular file to read, and nothing else. The open itself does not
/// wait: it is non-blocking, so that a FIFO (which would wait for a writer)
/// or a device is refused by what the opened file is, not by a separate look
/// at the path that the file could change under. Reads of a regular file
/// never block, so the flag changes nothing for them.
pub fn open_regular(path: &Path) -> Result<File, FileError> {
    use std::os::unix::fs::{FileTypeExt, OpenOptionsExt};
    let file = OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NONBLOCK)
        .open(path)
        .map_err(failed(path, "open"))?;
    let kind = file.metadata().map_err(failed(path, "read"))?.file_type();
    if kind.is_file() {
        return Ok(file);
    }
    let what = if kind.is_dir() {
        "a directory"
    } else if kind.is_fifo() {
        "a FIFO (named pipe)"
    } else if kind.is_char_device() {
        "a character device"
    } else if kind.is_block_device() {
        "a block device"
    } else if kind.is_socket() {
        "a socket"
    } else {
        "not a regular file"
    };
    Err(FileError {
        path: path.to_path_buf(),
        action: "read",
        source: std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!("{what}, where a regular file was expected"),
        ),
    })
}

/// Reads a whole file of at most `max_bytes` into `bytes` (cleared first and
/// reused from file to file: fresh memory costs page faults every time).
pub fn read_bounded_into(
    path: &Path,
    max_bytes: u64,
    bytes: &mut Vec<u8>,
) -> Result<(), ReadError> {
    let file = open_regular(path)?;
    // Sized from the file's length, so that a file is read without regrowing;
    // `take` guards against a file that grows after that.
    let expected = file
        .metadata()
        .map(|m| m.len().min(max_bytes + 1))
        .unwrap_or(0);
    bytes.clear();
    bytes.reserve(expected as usize + 1);
    file.take(max_bytes + 1)
        .read_to_end(bytes)
        .map_err(failed(path, "read"))?;
    if bytes.len() as u64 > max_bytes {
        return Err(ReadError::TooLarge {
            path: path.to_path_buf(),
            max_bytes,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let dir =
            std::env::temp_dir().join(format!("groundcal-files-{}-{name}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        dir
    }

    #[test]
    fn a_write_replaces_whole_and_leaves_no_temporary() {
        let dir = scratch("write");
        let path = dir.join("active.json");
        write_atomically(&path, b"one").unwrap();
        write_atomically(&path, b"two").unwrap();
        assert_eq!(fs::read(&path).unwrap(), b"two");
        let names: Vec<String> = fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        assert_eq!(names, ["active.json"]);
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_failed_write_names_the_file_and_keeps_the_old_one() {
        let dir = scratch("failed");
        let path = dir.join("target");
        // A directory where the file should go: the rename fails.
        fs::create_dir_all(path.join("occupied")).unwrap();
        let e = write_atomically(&path, b"new").unwrap_err();
        assert_eq!(e.action, "replace");
        assert!(e.to_string().contains("target"), "{e}");
        assert!(path.join("occupied").is_dir());
        assert!(!fs::read_dir(&dir)
            .unwrap()
            .any(|e| is_temporary(&e.unwrap().file_name().to_string_lossy())));
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_read_refuses_a_file_larger_than_its_kind() {
        let dir = scratch("read");
        fs::create_dir_all(&dir).unwrap();
        let path = dir.join("f");
        fs::write(&path, [7u8; 100]).unwrap();
        let mut bytes = Vec::new();
        read_bounded_into(&path, 100, &mut bytes).unwrap();
        assert_eq!(bytes.len(), 100);
        let e = read_bounded_into(&path, 99, &mut bytes).unwrap_err();
        assert!(
            matches!(e, ReadError::TooLarge { max_bytes: 99, .. }),
            "{e}"
        );
        let e = read_bounded_into(&dir.join("missing"), 99, &mut bytes).unwrap_err();
        assert!(e.to_string().contains("cannot open"), "{e}");
        fs::remove_dir_all(&dir).unwrap();
    }

    /// A FIFO would wait for a writer that never comes, a device never
    /// ends: both are refused at once, by what they are.
    #[test]
    fn a_read_takes_only_a_regular_file() {
        let dir = scratch("kinds");
        fs::create_dir_all(&dir).unwrap();
        let fifo = dir.join("fifo");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status();
        assert!(made.unwrap().success(), "mkfifo");
        let mut bytes = Vec::new();
        let (done, finished) = std::sync::mpsc::channel();
        let reading = fifo.clone();
        std::thread::spawn(move || {
            let mut bytes = Vec::new();
            let _ = done
                .send(read_bounded_into(&reading, 1 << 20, &mut bytes).map_err(|e| e.to_string()));
        });
        let e = finished
            .recv_timeout(std::time::Duration::from_secs(5))
            .expect("the read of a FIFO waited for a writer")
            .unwrap_err();
        assert!(e.contains("FIFO") && e.contains("fifo"), "{e}");
        let e = read_bounded_into(Path::new("/dev/zero"), 1 << 20, &mut bytes).unwrap_err();
        assert!(
            e.to_string()
                .contains("/dev/zero: cannot read: a character device"),
            "{e}"
        );
        let e = read_bounded_into(&dir, 1 << 20, &mut bytes).unwrap_err();
        assert!(e.to_string().contains("a directory"), "{e}");
        fs::remove_dir_all(&dir).unwrap();
    }
}
