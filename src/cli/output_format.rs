//! The kind of image file `aarbf render` writes, and writing it.

use std::path::Path;

use anyhow::bail;

use crate::render::legend::Legend;

/// The kind of image file a render writes, from its extension and --bit-depth (the Python
/// package's `Image.save` writes through it too).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OutputFormat {
    /// An 8-bit sRGB PNG, background composited (opaque); the only format the colour legend is
    /// drawn on.
    Png8,
    /// A 16-bit sRGB PNG with straight alpha, the background taken out.
    Png16,
    /// An OpenEXR file: linear 32-bit float RGBA, premultiplied alpha, the background taken out.
    Exr,
}

impl OutputFormat {
    /// The format of `path`'s extension at `bit_depth` bits per channel.
    pub fn of(path: &Path, bit_depth: u8) -> anyhow::Result<OutputFormat> {
        let ext = path
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase())
            .unwrap_or_default();
        Ok(match (ext.as_str(), bit_depth) {
            ("png", 8) => OutputFormat::Png8,
            ("png", 16) => OutputFormat::Png16,
            ("png", d) => bail!("--bit-depth {d}: a PNG has 8 or 16 bits per channel"),
            ("exr", 8) => OutputFormat::Exr,
            ("exr", d) => bail!("--bit-depth {d}: an .exr output is always 32-bit float"),
            (e, _) => bail!(
                "--out {}: unknown image type '.{e}' (write .png or .exr)",
                path.display()
            ),
        })
    }

    pub(super) fn extension(self) -> &'static str {
        match self {
            OutputFormat::Png8 | OutputFormat::Png16 => "png",
            OutputFormat::Exr => "exr",
        }
    }

    /// Writes `image` to `path` in this format, atomically, replacing an existing file;
    /// `background` is the colour taken out again for the formats with alpha, `legend` is drawn on
    /// 8-bit PNGs only.
    pub fn write(
        self,
        path: &Path,
        image: &crate::values::Image,
        background: [f64; 3],
        legend: Option<&Legend>,
    ) -> anyhow::Result<()> {
        use crate::io::output;
        match self {
            OutputFormat::Png8 => {
                let mut rgb = image.to_srgb8();
                if let Some(legend) = legend {
                    legend.draw(&mut rgb)?;
                }
                output::write_image(path, rgb.into(), image::ImageFormat::Png, true)?;
            }
            OutputFormat::Png16 => output::write_png16_alpha(path, image, background, true)?,
            OutputFormat::Exr => output::write_exr(path, image, background, true)?,
        }
        Ok(())
    }
}
