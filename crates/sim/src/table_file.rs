//! Reading a user's table file (aerodynamic table, wake tables): the one reader every table path
//! of the configuration goes through.
//!
//! A table path must name a regular file of at most [`MAX_TABLE_FILE_BYTES`]. The kind is checked
//! on the path's metadata *before* the file is opened (opening a FIFO blocks until a writer
//! comes; `/dev/zero` and `/dev/urandom` never end), checked again on the opened file, and the
//! size bound is enforced while reading (a file that grows while it is read is cut off at the
//! bound and refused), so no path makes a configuration hang or fill the memory.

use std::io::Read;
use std::path::Path;

use crate::error::{Result, SimError};

/// The largest table file read, bytes (64 MiB).
pub const MAX_TABLE_FILE_BYTES: u64 = 64 * 1024 * 1024;

/// The allowed range of a table path, in words, for the errors.
fn allowed() -> String {
    format!(
        "a regular file of at most {} MiB ({MAX_TABLE_FILE_BYTES} bytes)",
        MAX_TABLE_FILE_BYTES / (1024 * 1024)
    )
}

/// The text of the table file at `path`, named by the configuration field `field` (e.g.
/// `wake.tables.low`) in the errors.
///
/// Errors: [`SimError::InvalidConfig`] (naming the field, the path and the limit) when the path
/// is not a regular file (a folder, a FIFO, a device) or is larger than
/// [`MAX_TABLE_FILE_BYTES`]; [`SimError::Io`] (naming the path and the field) when it cannot be
/// read or is not UTF-8.
pub fn read_table_file(path: &Path, field: &str) -> Result<String> {
    let shown = path.display().to_string();
    let io = |e: std::io::Error| SimError::Io {
        path: shown.clone(),
        reason: format!("{e} (`{field}`)"),
    };
    let refuse =
        |what: String| SimError::invalid_config(field, format!("{shown:?} ({what})"), &allowed());
    let check = |meta: &std::fs::Metadata| -> Result<()> {
        if !meta.is_file() {
            return Err(refuse(kind(meta).to_owned()));
        }
        if meta.len() > MAX_TABLE_FILE_BYTES {
            return Err(refuse(format!("{} bytes", meta.len())));
        }
        Ok(())
    };
    // Before opening: opening a FIFO would block.
    check(&std::fs::metadata(path).map_err(io)?)?;
    let file = std::fs::File::open(path).map_err(io)?;
    // The path may have been replaced between the check and the open.
    check(&file.metadata().map_err(io)?)?;
    let mut bytes = Vec::new();
    file.take(MAX_TABLE_FILE_BYTES + 1)
        .read_to_end(&mut bytes)
        .map_err(io)?;
    if bytes.len() as u64 > MAX_TABLE_FILE_BYTES {
        return Err(refuse("grew past the limit while it was read".to_owned()));
    }
    String::from_utf8(bytes).map_err(|e| SimError::Io {
        path: shown.clone(),
        reason: format!("not UTF-8 text: {e} (`{field}`)"),
    })
}

/// What a path that is not a regular file is, in words.
fn kind(meta: &std::fs::Metadata) -> &'static str {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        let t = meta.file_type();
        if t.is_fifo() {
            return "a FIFO, not a regular file";
        }
        if t.is_char_device() || t.is_block_device() {
            return "a device, not a regular file";
        }
        if t.is_socket() {
            return "a socket, not a regular file";
        }
    }
    if meta.is_dir() {
        "a folder, not a regular file"
    } else {
        "not a regular file"
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn message(path: &str) -> String {
        read_table_file(Path::new(path), "wake.tables.low")
            .unwrap_err()
            .to_string()
    }

    #[test]
    fn devices_and_folders_are_refused_before_they_are_read() {
        for (path, what) in [
            ("/dev/zero", "device"),
            ("/dev/urandom", "device"),
            ("/", "folder"),
        ] {
            let m = message(path);
            assert!(m.contains("wake.tables.low"), "{m}");
            assert!(m.contains(path) && m.contains(what), "{m}");
            assert!(m.contains("64 MiB"), "{m}");
        }
    }

    #[cfg(unix)]
    #[test]
    fn a_fifo_is_refused_without_opening_it() {
        let dir = std::env::temp_dir().join(format!("accd-fifo-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let fifo = dir.join("table.json");
        // No libc crate here: the FIFO is made by the system's tool.
        let made = std::process::Command::new("mkfifo").arg(&fifo).status();
        if !matches!(made, Ok(s) if s.success()) {
            return; // no mkfifo on this machine
        }
        let m = message(fifo.to_str().unwrap()); // would block forever if it opened the FIFO
        std::fs::remove_dir_all(&dir).unwrap();
        assert!(m.contains("FIFO") && m.contains("wake.tables.low"), "{m}");
    }

    #[test]
    fn a_file_over_the_limit_is_refused_and_a_missing_one_named() {
        let dir = std::env::temp_dir().join(format!("accd-big-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let big = dir.join("big.json");
        let f = std::fs::File::create(&big).unwrap();
        f.set_len(MAX_TABLE_FILE_BYTES + 1).unwrap(); // sparse: no disk used
        let m = message(big.to_str().unwrap());
        assert!(
            m.contains(&format!("{} bytes", MAX_TABLE_FILE_BYTES + 1)),
            "{m}"
        );
        let small = dir.join("small.json");
        std::fs::write(&small, "{}").unwrap();
        assert_eq!(
            read_table_file(&small, "accd.aero_table").unwrap(),
            "{}".to_owned()
        );
        std::fs::remove_dir_all(&dir).unwrap();
        let m = message(small.to_str().unwrap());
        assert!(
            m.contains("cannot read") && m.contains("wake.tables.low"),
            "{m}"
        );
    }
}
