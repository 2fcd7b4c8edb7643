//! Reading a file a user named (scene, buffer, image, texture, job file,
//! journal record): only a regular file, and no more than a bound.
//!
//! The file is opened without blocking (a FIFO's open would otherwise wait
//! for a writer), its metadata checked on the opened handle (no FIFOs,
//! devices, sockets or directories, and no race with a rename between a
//! check and the open), its size checked against the bound before reading,
//! and the read stops past the bound (a file that grows while it is read).
//! Errors are `io::Error`s whose message says the kind or the bound; the
//! caller's error names the file.

use std::fs::File;
use std::io::{self, Read};
use std::path::Path;

/// The most bytes of a scene file (OBJ, MTL, glTF, GLB) or a glTF buffer.
pub const MAX_SCENE_FILE_BYTES: u64 = 1 << 30;
/// The most bytes of an image file (a texture, a glTF image).
pub const MAX_IMAGE_FILE_BYTES: u64 = 256 << 20;

/// Why a named file is not read.
#[derive(Debug, thiserror::Error)]
pub enum FileRefused {
    #[error("{kind}, not a regular file")]
    NotRegular { kind: &'static str },
    #[error("{size} bytes, more than the limit of {limit} bytes")]
    TooLarge { size: u64, limit: u64 },
    #[error("grew past the limit of {limit} bytes while it was read")]
    Grew { limit: u64 },
}

impl From<FileRefused> for io::Error {
    fn from(refused: FileRefused) -> io::Error {
        let kind = match refused {
            FileRefused::NotRegular { .. } => io::ErrorKind::InvalidInput,
            FileRefused::TooLarge { .. } | FileRefused::Grew { .. } => io::ErrorKind::FileTooLarge,
        };
        io::Error::new(kind, refused)
    }
}

/// What a file that is not regular is.
fn kind_of(file_type: std::fs::FileType) -> &'static str {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if file_type.is_fifo() {
            return "a FIFO";
        }
        if file_type.is_char_device() {
            return "a character device";
        }
        if file_type.is_block_device() {
            return "a block device";
        }
        if file_type.is_socket() {
            return "a socket";
        }
    }
    if file_type.is_dir() {
        "a directory"
    } else {
        "a special file"
    }
}

/// Opens `path` for reading if it is a regular file of at most `limit`
/// bytes; returns it and its size.
pub fn open_regular(path: &Path, limit: u64) -> io::Result<(File, u64)> {
    let mut options = std::fs::OpenOptions::new();
    options.read(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        // A FIFO's open waits for a writer; non-blocking, it returns at once
        // and the type check below refuses it.
        options.custom_flags(libc::O_NONBLOCK);
    }
    let file = options.open(path)?;
    let metadata = file.metadata()?;
    if !metadata.file_type().is_file() {
        return Err(FileRefused::NotRegular {
            kind: kind_of(metadata.file_type()),
        }
        .into());
    }
    if metadata.len() > limit {
        return Err(FileRefused::TooLarge {
            size: metadata.len(),
            limit,
        }
        .into());
    }
    Ok((file, metadata.len()))
}

/// The bytes of the regular file `path`, at most `limit` of them (see the
/// [module documentation](self)).
pub fn read_regular(path: &Path, limit: u64) -> io::Result<Vec<u8>> {
    let (file, size) = open_regular(path, limit)?;
    let mut bytes = Vec::with_capacity(size as usize);
    file.take(limit.saturating_add(1)).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > limit {
        return Err(FileRefused::Grew { limit }.into());
    }
    Ok(bytes)
}

/// [`read_regular`] as UTF-8 text.
pub fn read_regular_text(path: &Path, limit: u64) -> io::Result<String> {
    String::from_utf8(read_regular(path, limit)?)
        .map_err(|e| io::Error::new(io::ErrorKind::InvalidData, e.utf8_error()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_regular_file_within_the_limit_reads_whole() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a");
        std::fs::write(&path, b"twelve bytes").unwrap();
        assert_eq!(read_regular(&path, 12).unwrap(), b"twelve bytes");
        let error = read_regular(&path, 11).unwrap_err().to_string();
        assert!(
            error.contains("12 bytes, more than the limit of 11 bytes"),
            "{error}"
        );
    }

    #[test]
    fn devices_directories_and_fifos_are_refused_without_reading() {
        let dir = tempfile::tempdir().unwrap();
        let error = read_regular(dir.path(), 1 << 20).unwrap_err().to_string();
        assert!(error.contains("a directory, not a regular file"), "{error}");
        let error = read_regular(Path::new("/dev/zero"), u64::MAX)
            .unwrap_err()
            .to_string();
        assert!(
            error.contains("a character device, not a regular file"),
            "{error}"
        );
        let fifo = dir.path().join("fifo");
        let made = std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap();
        assert!(made.success());
        // No writer: a blocking open would wait for ever.
        let error = read_regular(&fifo, 1 << 20).unwrap_err().to_string();
        assert!(error.contains("a FIFO, not a regular file"), "{error}");
    }
}
