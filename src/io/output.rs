//! Writing outputs safely: into a temporary file in the destination's directory, renamed into
//! place when complete, so an interrupted run never leaves a truncated file; and never over an
//! existing file unless the user said `--force`.

use std::path::Path;

/// Why an output was not written.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    /// The output exists and `--force` was not given (its path as displayed).
    #[error("{0} exists; pass --force to overwrite it")]
    Exists(String),
    /// Writing the temporary file or renaming it into place failed.
    // `error`, not `source`: the message includes it, and a source would print it twice.
    #[error("cannot write {path}: {error}")]
    Io {
        /// The output's path as displayed.
        path: String,
        /// The I/O error, quoted in the message.
        error: std::io::Error,
    },
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
    let mut builder = tempfile::Builder::new();
    builder.prefix(".aarbf-partial-").suffix(&suffix);
    // An output is an ordinary file: the mode `File::create` gives (0666 less the umask), not
    // the private 0600 of a temporary file.
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        builder.permissions(std::fs::Permissions::from_mode(0o666));
    }
    let tmp = builder.tempfile_in(dir).map_err(io)?;
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
    write_image(
        path,
        image.to_srgb8().into(),
        image::ImageFormat::Png,
        force,
    )
}

/// Writes `image` in `format`, atomically; an existing file only with `force`.
pub fn write_image(
    path: &Path,
    image: image::DynamicImage,
    format: image::ImageFormat,
    force: bool,
) -> Result<(), OutputError> {
    write_atomically(path, force, |tmp| {
        image
            .save_with_format(tmp, format)
            .map_err(std::io::Error::other)
    })
}

/// Writes `image` as a 16-bit sRGB PNG with straight alpha (the background taken out, so it
/// composites over anything), atomically; an existing file only with `force`.
pub fn write_png16_alpha(
    path: &Path,
    image: &crate::values::Image,
    background: [f64; 3],
    force: bool,
) -> Result<(), OutputError> {
    use crate::values::color_space::linear_to_srgb;
    let quantise = |v: f64| (linear_to_srgb(v.clamp(0.0, 1.0)) * 65535.0).round() as u16;
    let data: Vec<u16> = image
        .premultiplied(background)
        .iter()
        .flat_map(|&[r, g, b, a]| {
            let straight = |c: f64| if a > 0.0 { c / a } else { 0.0 };
            [
                quantise(straight(r)),
                quantise(straight(g)),
                quantise(straight(b)),
                (a.clamp(0.0, 1.0) * 65535.0).round() as u16,
            ]
        })
        .collect();
    let buffer =
        image::ImageBuffer::<image::Rgba<u16>, _>::from_raw(image.width, image.height, data)
            .expect("one RGBA value per pixel");
    write_image(path, buffer.into(), image::ImageFormat::Png, force)
}

/// Writes `image` as OpenEXR: linear 32-bit float RGBA, premultiplied alpha (EXR's
/// convention), the background taken out; atomically, an existing file only with `force`.
pub fn write_exr(
    path: &Path,
    image: &crate::values::Image,
    background: [f64; 3],
    force: bool,
) -> Result<(), OutputError> {
    let data: Vec<f32> = image
        .premultiplied(background)
        .iter()
        .flat_map(|p| p.map(|c| c as f32))
        .collect();
    let buffer = image::Rgba32FImage::from_raw(image.width, image.height, data)
        .expect("one RGBA value per pixel");
    write_image(path, buffer.into(), image::ImageFormat::OpenExr, force)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[cfg(unix)]
    #[test]
    fn outputs_get_the_mode_of_an_ordinary_new_file() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().unwrap();
        let ordinary = dir.path().join("ordinary");
        std::fs::write(&ordinary, "x").unwrap();
        let written = dir.path().join("written");
        write_atomically(&written, false, |p| std::fs::write(p, "x")).unwrap();
        let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode(&written), mode(&ordinary));
    }

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
