//! `params.glsl`'s `Brick`, and the one buffer a brick kernel (`lbvh_owned.comp`) reads and
//! writes: what [`crate::backend::Backend::render_owned`] and
//! [`crate::backend::Backend::owned_depth`] ask of a GPU backend, in the local coordinates of
//! the frame's [`GpuFrame`], made once here for both GPU backends.

use bytemuck::{Pod, Zeroable};
use glam::DVec3;

use super::GpuFrame;
use crate::backend::{BackendError, BrickShare, DepthRays};
use crate::values::shader_constants::{
    OWNED_TASK_LIGHT_DEPTH, OWNED_TASK_OCCLUDING_DEPTH, OWNED_TASK_PRIMARY_DEPTH, OWNED_TASK_RENDER,
};
use crate::values::{Bounds, FrameParams, HalfOpenBox, PixelRect};

/// `params.glsl`'s `Brick` (its comments say what each field holds).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuBrick {
    /// The half-open box's least corner, local (may be -inf); w unused.
    pub owned_lo: [f32; 4],
    /// Its largest corner (may be +inf); w unused.
    pub owned_hi: [f32; 4],
    /// The closed box within the march box: shadow rays' exit and delta tracking's segment.
    pub clip_lo: [f32; 4],
    /// See [`GpuBrick::clip_lo`].
    pub clip_hi: [f32; 4],
    /// The clipped box grown by a step: the part of a ray that is marched.
    pub march_lo: [f32; 4],
    /// See [`GpuBrick::march_lo`].
    pub march_hi: [f32; 4],
    /// x0, y0, x1, y1 of the pixels (texels) written.
    pub rect: [u32; 4],
    /// The task (`OWNED_TASK_*`), whether a depth in front is given, where the inputs start
    /// (vec4s into the output array), unused.
    pub task: [u32; 4],
    /// x0, y0, x1, y1 of the light prefix's texels (empty: local shadows).
    pub prefix: [u32; 4],
    /// The prefix's first float in the inputs; yzw unused.
    pub prefix_at: [u32; 4],
    /// The light map's centre (local), w how far behind it its rays start.
    pub light_centre: [f32; 4],
    /// The map's u axis, w its least u.
    pub light_u: [f32; 4],
    /// The map's v axis, w its least v.
    pub light_v: [f32; 4],
    /// Towards the light; w unused.
    pub light_dir: [f32; 4],
    /// A texel's width along u and v; zw unused.
    pub light_texel: [f32; 4],
    /// The depth past which an occluding depth pass's rays stop; yzw unused.
    pub depth_stop: [f32; 4],
}

fn v4(v: DVec3) -> [f32; 4] {
    [v.x as f32, v.y as f32, v.z as f32, 0.0]
}

fn rect4(r: PixelRect) -> [u32; 4] {
    [r.x0, r.y0, r.x1, r.y1]
}

/// One brick kernel launch: the frame it renders, and the bytes of its buffer (the brick,
/// then the output poisoned with NaN, so a pixel the kernel misses shows, then the inputs).
#[derive(Clone, Debug)]
pub struct BrickLaunch {
    /// The frame constants: the share's own frame (delta tracking's brick seed).
    pub frame: GpuFrame,
    /// The kernel's one buffer, as uploaded.
    pub io: Vec<u8>,
    /// The pixels (texels) written, row-major from [`BrickLaunch::OUTPUT_OFFSET`].
    pub rect: PixelRect,
}

impl BrickLaunch {
    /// Where the output starts in the buffer (bytes).
    pub const OUTPUT_OFFSET: u64 = std::mem::size_of::<GpuBrick>() as u64;

    /// A brick's share of `frame` ([`crate::backend::Backend::render_owned`]), positions
    /// relative to `origin`; refuses a depth in front that is not one per pixel.
    pub fn render(
        backend: &'static str,
        frame: &FrameParams,
        share: &BrickShare<'_>,
        origin: DVec3,
    ) -> Result<BrickLaunch, BackendError> {
        let own_frame = share.own_frame(frame);
        let frame = own_frame.as_ref().unwrap_or(frame);
        let mut inputs: Vec<f32> = Vec::new();
        if let Some(d) = share.depth_in_front {
            if d.len() != share.rect.len() {
                return Err(BackendError::Device {
                    backend,
                    message: format!(
                        "a brick's depth in front holds {} values for {} pixels",
                        d.len(),
                        share.rect.len()
                    ),
                });
            }
            inputs.extend(d.iter().map(|&x| x as f32));
        }
        let mut brick = GpuBrick::new(frame, share.owned, origin, share.rect, OWNED_TASK_RENDER);
        brick.task[1] = u32::from(share.depth_in_front.is_some());
        if let Some(light) = share.light {
            if light.depth.len() != light.rect.len() {
                return Err(BackendError::Device {
                    backend,
                    message: format!(
                        "a light prefix holds {} depths for {} texels",
                        light.depth.len(),
                        light.rect.len()
                    ),
                });
            }
            brick.set_light_map(&light.map, origin);
            brick.prefix = rect4(light.rect);
            brick.prefix_at[0] = inputs.len() as u32;
            inputs.extend(light.depth.iter().map(|&x| x as f32));
        }
        Ok(BrickLaunch::new(frame, origin, brick, &inputs))
    }

    /// The optical depth of the samples `owned` holds along `rays`
    /// ([`crate::backend::Backend::owned_depth`]), positions relative to `origin`.
    pub fn depth(
        frame: &FrameParams,
        owned: &HalfOpenBox,
        rays: DepthRays<'_>,
        origin: DVec3,
    ) -> BrickLaunch {
        let brick = match rays {
            DepthRays::Primary(rect) => {
                GpuBrick::new(frame, owned, origin, rect, OWNED_TASK_PRIMARY_DEPTH)
            }
            DepthRays::Occluding { rect, stop_past } => {
                let mut b = GpuBrick::new(frame, owned, origin, rect, OWNED_TASK_OCCLUDING_DEPTH);
                // An f32 stop past the largest f32 is infinite: the ray is marched whole.
                b.depth_stop[0] = stop_past as f32;
                b
            }
            DepthRays::Light(map, rect) => {
                let mut b = GpuBrick::new(frame, owned, origin, rect, OWNED_TASK_LIGHT_DEPTH);
                b.set_light_map(map, origin);
                b
            }
        };
        BrickLaunch::new(frame, origin, brick, &[])
    }

    fn new(frame: &FrameParams, origin: DVec3, mut brick: GpuBrick, inputs: &[f32]) -> Self {
        let rect = PixelRect {
            x0: brick.rect[0],
            y0: brick.rect[1],
            x1: brick.rect[2],
            y1: brick.rect[3],
        };
        brick.task[2] = rect.len() as u32;
        let mut io = bytemuck::bytes_of(&brick).to_vec();
        io.extend(std::iter::repeat_n(f32::NAN, 4 * rect.len()).flat_map(f32::to_le_bytes));
        io.extend(inputs.iter().flat_map(|x| x.to_le_bytes()));
        // Whole vec4s (and never an empty array).
        io.resize((io.len() + 16).next_multiple_of(16), 0);
        BrickLaunch {
            frame: GpuFrame::new(frame, origin),
            io,
            rect,
        }
    }

    /// The output's bytes.
    pub fn output_bytes(&self) -> u64 {
        self.rect.len() as u64 * 16
    }

    /// The output read back (from [`BrickLaunch::OUTPUT_OFFSET`]) as pixels.
    pub fn pixels(bytes: &[u8]) -> Vec<[f64; 4]> {
        bytemuck::pod_collect_to_vec::<u8, f32>(bytes)
            .chunks_exact(4)
            .map(|v| [0, 1, 2, 3].map(|c| f64::from(v[c])))
            .collect()
    }

    /// The output read back as depths (the first of each vec4).
    pub fn depths(bytes: &[u8]) -> Vec<f64> {
        Self::pixels(bytes).into_iter().map(|p| p[0]).collect()
    }
}

impl GpuBrick {
    fn new(
        frame: &FrameParams,
        owned: &HalfOpenBox,
        origin: DVec3,
        rect: PixelRect,
        task: u32,
    ) -> GpuBrick {
        let clipped = owned.clipped_to(frame.march_box());
        let marched: Bounds = clipped.grown(frame.dt);
        GpuBrick {
            owned_lo: v4(owned.lo - origin),
            owned_hi: v4(owned.hi - origin),
            clip_lo: v4(clipped.min - origin),
            clip_hi: v4(clipped.max - origin),
            march_lo: v4(marched.min - origin),
            march_hi: v4(marched.max - origin),
            rect: rect4(rect),
            task: [task, 0, 0, 0],
            ..GpuBrick::default()
        }
    }

    fn set_light_map(&mut self, map: &crate::backend::LightMap, origin: DVec3) {
        let w = |v: DVec3, w: f64| [v.x as f32, v.y as f32, v.z as f32, w as f32];
        self.light_centre = w(map.centre - origin, map.behind);
        self.light_u = w(map.u, map.origin[0]);
        self.light_v = w(map.v, map.origin[1]);
        self.light_dir = w(map.toward_light, 0.0);
        self.light_texel = [map.texel[0] as f32, map.texel[1] as f32, 0.0, 0.0];
    }
}
