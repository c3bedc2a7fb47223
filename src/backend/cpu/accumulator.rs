//! Progressive accumulation on the CPU: f64 sums per pixel, the image their mean.

use crate::values::Image;

/// Sums frames per pixel; the image is their mean. Reset on any change.
#[derive(Clone, Debug)]
pub(super) struct Accumulator {
    pub width: u32,
    pub height: u32,
    pub frames: u32,
    sum: Vec<[f64; 4]>,
}

impl Accumulator {
    pub(super) fn new(width: u32, height: u32) -> Accumulator {
        Accumulator {
            width,
            height,
            frames: 0,
            sum: vec![[0.0; 4]; (width as usize) * (height as usize)],
        }
    }

    pub(super) fn reset(&mut self) {
        self.frames = 0;
        self.sum.fill([0.0; 4]);
    }

    /// Adds one frame's pixels (row-major).
    pub(super) fn add(&mut self, frame: &[[f64; 4]]) {
        assert_eq!(frame.len(), self.sum.len());
        for (s, f) in self.sum.iter_mut().zip(frame) {
            for c in 0..4 {
                s[c] += f[c];
            }
        }
        self.frames += 1;
    }

    /// The mean per pixel, in f64.
    pub(super) fn mean(&self) -> Vec<[f64; 4]> {
        let n = f64::from(self.frames.max(1));
        self.sum.iter().map(|s| s.map(|v| v / n)).collect()
    }

    pub(super) fn image(&self) -> Image {
        let n = f64::from(self.frames.max(1));
        Image {
            width: self.width,
            height: self.height,
            pixels: self.sum.iter().map(|s| s.map(|v| (v / n) as f32)).collect(),
        }
    }

    pub(super) fn bytes(&self) -> usize {
        self.sum.len() * std::mem::size_of::<[f64; 4]>()
    }
}
