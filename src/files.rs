//! Files written whole or not at all: a temporary file beside the destination, renamed
//! over it only once complete and on disk, so that a reader never sees a partial file and
//! a failed or interrupted write leaves the previous file in place. And config files read
//! with the line of any error.
//!
//! Exports: [`write_atomic`], [`write_json`], [`read_config`].

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use crate::error::{Error, Result};

/// Writes `path` through `body` atomically: a temporary file in the same directory, renamed
/// over `path` only after `body` succeeded and the data reached the disk.
pub fn write_atomic(
    path: &Path,
    body: impl FnOnce(&mut BufWriter<&mut File>) -> std::io::Result<()>,
) -> Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let mut builder = tempfile::Builder::new();
    builder.prefix(".tarn-").suffix(".partial");
    // Outputs are ordinary files (tempfile's default is owner-only).
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        builder.permissions(std::fs::Permissions::from_mode(0o644));
    }
    let mut tmp = builder.tempfile_in(dir).map_err(|e| Error::io(dir, e))?;
    let failed = |e: std::io::Error| {
        if crate::interrupt::stop_requested() && e.to_string() == STOPPED {
            Error::Interrupted(format!("writing {}", path.display()))
        } else {
            Error::io(path, e)
        }
    };
    {
        let mut w = BufWriter::new(tmp.as_file_mut());
        body(&mut w).map_err(failed)?;
        w.flush().map_err(|e| Error::io(path, e))?;
    }
    tmp.as_file().sync_all().map_err(|e| Error::io(path, e))?;
    tmp.persist(path).map_err(|e| Error::io(path, e.error))?;
    Ok(())
}

const STOPPED: &str = "stop requested";

/// Every 65,536th item of a writer's loop: an error once a stop (SIGINT) was requested, so
/// that an export of millions of cells stops within a fraction of a second; the staged
/// files are then dropped and the previous outputs stay.
pub(crate) fn stop_point(i: usize) -> std::io::Result<()> {
    if i % 65_536 == 0 && crate::interrupt::stop_requested() {
        Err(std::io::Error::other(STOPPED))
    } else {
        Ok(())
    }
}

/// Writes `value` as pretty JSON, atomically.
pub fn write_json(path: &Path, value: &impl serde::Serialize) -> Result<()> {
    write_atomic(path, |w| {
        serde_json::to_writer_pretty(&mut *w, value).map_err(std::io::Error::other)?;
        w.write_all(b"\n")
    })
}

/// Parses a config file: TOML for a `.toml` file, JSON for any other extension. Errors name
/// the file, and the line (and column) where parsing failed.
pub fn read_config<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    let is_toml = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("toml"));
    if is_toml {
        toml::from_str(&text).map_err(|e| {
            let loc = e
                .span()
                .map(|s| format!("line {}", text[..s.start].lines().count().max(1)))
                .unwrap_or_else(|| "config".into());
            Error::format(path, loc, e.message().to_string())
        })
    } else {
        serde_json::from_str(&text).map_err(|e| {
            Error::format(
                path,
                format!("line {} column {}", e.line(), e.column()),
                e.to_string(),
            )
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn atomic_write_leaves_nothing_on_failure() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("x.bin");
        let r = write_atomic(&p, |w| {
            w.write_all(b"half")?;
            Err(std::io::Error::other("disk full"))
        });
        assert!(r.is_err());
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
        std::fs::write(&p, b"old").unwrap();
        let _ = write_atomic(&p, |_| Err(std::io::Error::other("boom")));
        assert_eq!(std::fs::read(&p).unwrap(), b"old");
    }
}
