//! Images: the linear-light RGBA mean of accumulated frames, and the measures the tests and
//! benchmarks compare them by.

use crate::values::color_space::linear_to_srgb;

/// A linear-light RGBA image (the mean over accumulated frames).
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Row-major linear RGBA, `width * height` of them, the top row first.
    pub pixels: Vec<[f32; 4]>,
}

impl Image {
    /// 8-bit sRGB, opaque (the background is already composited).
    pub fn to_srgb8(&self) -> image::RgbImage {
        let mut out = image::RgbImage::new(self.width, self.height);
        for (o, p) in out.pixels_mut().zip(&self.pixels) {
            *o = image::Rgb(std::array::from_fn(|c| {
                let v = f64::from(p[c]);
                let v = if v.is_finite() {
                    v.clamp(0.0, 1.0)
                } else {
                    0.0
                };
                (linear_to_srgb(v) * 255.0).round() as u8
            }));
        }
        out
    }

    /// Premultiplied linear RGBA without the background: a pixel's colour is the data's
    /// composited over `background` (c = c_data + (1 - a) bg, the integrators' rule), so the
    /// data's own is c - (1 - a) bg, the colour for compositing over anything else.
    pub fn premultiplied(&self, background: [f64; 3]) -> Vec<[f64; 4]> {
        self.pixels
            .iter()
            .map(|p| {
                let a = f64::from(p[3]);
                let c = |k: usize| (f64::from(p[k]) - (1.0 - a) * background[k]).max(0.0);
                [c(0), c(1), c(2), a]
            })
            .collect()
    }

    /// The image blurred by a normalised Gaussian of standard deviation `sigma` pixels
    /// (separable, clamped at the borders): how error looks to a viewer, whose eye low-pass
    /// filters; blue noise pushes error to frequencies this removes.
    pub fn blurred(&self, sigma: f64) -> Image {
        let radius = (3.0 * sigma).ceil() as i64;
        let kernel: Vec<f64> = (-radius..=radius)
            .map(|i| (-(i * i) as f64 / (2.0 * sigma * sigma)).exp())
            .collect();
        let norm: f64 = kernel.iter().sum();
        let (w, h) = (i64::from(self.width), i64::from(self.height));
        let pass = |src: &[[f32; 4]], horizontal: bool| -> Vec<[f32; 4]> {
            (0..w * h)
                .map(|i| {
                    let (x, y) = (i % w, i / w);
                    let mut acc = [0.0f64; 4];
                    for (k, kv) in kernel.iter().enumerate() {
                        let o = k as i64 - radius;
                        let (sx, sy) = if horizontal {
                            ((x + o).clamp(0, w - 1), y)
                        } else {
                            (x, (y + o).clamp(0, h - 1))
                        };
                        let p = src[(sy * w + sx) as usize];
                        for c in 0..4 {
                            acc[c] += kv * f64::from(p[c]);
                        }
                    }
                    acc.map(|v| (v / norm) as f32)
                })
                .collect()
        };
        let pixels = pass(&pass(&self.pixels, true), false);
        Image {
            width: self.width,
            height: self.height,
            pixels,
        }
    }

    /// An opaque image of one grey `value` (unit tests).
    #[cfg(test)]
    pub(crate) fn flat(width: u32, height: u32, value: f32) -> Image {
        Image {
            width,
            height,
            pixels: vec![[value, value, value, 1.0]; (width * height) as usize],
        }
    }

    /// The pixels of the half-resolution lattice (every other pixel in x and in y, from the
    /// first: what [`crate::values::FrameParams::on_half_lattice`] renders).
    pub fn half_lattice(&self) -> Image {
        let (w, h) = crate::values::frame::half_lattice_size(self.width, self.height);
        let pixels = (0..h)
            .flat_map(|j| (0..w).map(move |i| self.pixels[(2 * j * self.width + 2 * i) as usize]))
            .collect();
        Image {
            width: w,
            height: h,
            pixels,
        }
    }

    /// Root-mean-square difference over RGB.
    pub fn rmse(&self, other: &Image) -> f64 {
        assert_eq!((self.width, self.height), (other.width, other.height));
        let sum: f64 = self
            .pixels
            .iter()
            .zip(&other.pixels)
            .map(|(a, b)| {
                (0..3)
                    .map(|c| (f64::from(a[c]) - f64::from(b[c])).powi(2))
                    .sum::<f64>()
            })
            .sum();
        (sum / (3 * self.pixels.len().max(1)) as f64).sqrt()
    }
    /// Mean FLIP (NVIDIA's perceptual difference, 0 = identical, 1 = as different as black
    /// and white) of this image against `reference`, both shown as 8-bit sRGB at FLIP's
    /// default viewing distance (67 pixels per degree): what an observer sees of the error.
    pub fn flip(&self, reference: &Image) -> f64 {
        assert_eq!(
            (self.width, self.height),
            (reference.width, reference.height)
        );
        let srgb = |i: &Image| {
            nv_flip::FlipImageRgb8::with_data(i.width, i.height, &i.to_srgb8().into_raw())
        };
        let error = nv_flip::flip(
            srgb(reference),
            srgb(self),
            nv_flip::DEFAULT_PIXELS_PER_DEGREE,
        );
        f64::from(nv_flip::FlipPool::from_image(&error).mean())
    }

    /// This image plus `scale` times (`a` - `b`), per channel: an image whose difference from
    /// this one has the statistics of a measured difference (the error estimates use it).
    pub fn offset_by(&self, a: &Image, b: &Image, scale: f64) -> Image {
        assert_eq!((self.width, self.height), (a.width, a.height));
        assert_eq!((a.width, a.height), (b.width, b.height));
        let pixels = self
            .pixels
            .iter()
            .zip(a.pixels.iter().zip(&b.pixels))
            .map(|(p, (x, y))| {
                std::array::from_fn(|c| {
                    (f64::from(p[c]) + scale * (f64::from(x[c]) - f64::from(y[c]))) as f32
                })
            })
            .collect();
        Image {
            width: self.width,
            height: self.height,
            pixels,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_half_lattice_is_every_other_pixel_from_the_first() {
        for (w, h) in [(5u32, 3u32), (4, 4), (1, 1), (2, 7)] {
            let image = Image {
                width: w,
                height: h,
                pixels: (0..w * h)
                    .map(|k| [(k % w) as f32, (k / w) as f32, 0.0, 1.0])
                    .collect(),
            };
            let lattice = image.half_lattice();
            assert_eq!(
                (lattice.width, lattice.height),
                (w.div_ceil(2), h.div_ceil(2))
            );
            for (k, p) in lattice.pixels.iter().enumerate() {
                let (i, j) = (k as u32 % lattice.width, k as u32 / lattice.width);
                assert_eq!(p[..2], [(2 * i) as f32, (2 * j) as f32], "{w}x{h}");
            }
        }
    }
}
