//! Writing outputs safely: into a temporary file in the destination's directory, renamed into
//! place when complete, so an interrupted run never leaves a truncated file; and never over an
//! existing file unless the user said `--force`.

use std::path::Path;

/// Why an output was not written.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    #[error("{0} exists; pass --force to overwrite it")]
    Exists(String),
    // `error`, not `source`: the message includes it, and a source would print it twice.
    #[error("cannot write {path}: {error}")]
    Io { path: String, error: std::io::Error },
}

/// Fails if `path` exists and `force` is not set.
pub fn check_writable(path: &Path, force: bool) -> Result<(), OutputError> {
    if !force && path.exists() {
        return Err(OutputError::Exists(path.display().to_string()));
    }
    Ok(())
}

/// Writes `path` through `write`, which receives a temporary path in the same directory (so
/// the final rename stays on one file system); the temporary file is removed on failure.
pub fn write_atomically(
    path: &Path,
    force: bool,
    write: impl FnOnce(&Path) -> std::io::Result<()>,
) -> Result<(), OutputError> {
    check_writable(path, force)?;
    let io = |error| OutputError::Io {
        path: path.display().to_string(),
        error,
    };
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let suffix = path
        .extension()
        .map(|e| format!(".{}", e.to_string_lossy()))
        .unwrap_or_default();
    let tmp = tempfile::Builder::new()
        .prefix(".aarbf-partial-")
        .suffix(&suffix)
        .tempfile_in(dir)
        .map_err(io)?;
    write(tmp.path()).map_err(io)?;
    tmp.persist(path).map_err(|e| io(e.error))?;
    Ok(())
}

/// Writes `image` as an 8-bit sRGB PNG, atomically; an existing file only with `force`.
pub fn write_png(
    path: &Path,
    image: &crate::values::Image,
    force: bool,
) -> Result<(), OutputError> {
    let rgb = image.to_srgb8();
    write_atomically(path, force, |tmp| {
        rgb.save_with_format(tmp, image::ImageFormat::Png)
            .map_err(std::io::Error::other)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refuses_to_overwrite_and_leaves_nothing_on_failure() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.txt");
        write_atomically(&path, false, |p| std::fs::write(p, "one")).unwrap();
        let e = write_atomically(&path, false, |p| std::fs::write(p, "two")).unwrap_err();
        assert!(e.to_string().contains("--force"));
        write_atomically(&path, true, |p| std::fs::write(p, "two")).unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "two");
        // A failing writer leaves the old file and no temporary behind.
        let e = write_atomically(&path, true, |p| {
            std::fs::write(p, "half")?;
            Err(std::io::Error::other("interrupted"))
        });
        assert!(e.is_err());
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "two");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }
}
