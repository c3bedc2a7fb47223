//! Direct-send compositing, as OSPRay's distributed frame buffer does it: the image is cut
//! into 64 x 64 tiles owned round-robin; each rank sends the parts of its layer that fall in
//! each tile its brick's screen rectangle touches to that tile's owner, all in one
//! all-to-all-v; each owner blends what it received front to back in the k-d order of the
//! leaves for the camera, finishes the pixels over the background and accumulates them; one
//! gather-v brings the accumulated tiles to the root. One collective a frame works for any P,
//! and a rank's traffic is its brick's footprint on the screen.
//!
//! A layer's pixel is `[r, g, b, T]`: premultiplied colour and transmittance
//! (`Backend::render_owned`). Blending a layer behind what is in front is
//! `C += T_front C_b`, `T_front *= T_b`, the integrator's own recurrence applied per brick, so
//! the composited pixel is the single-rank pixel up to rounding (and, for one rank, exactly).

use glam::{DMat3, DVec3};

use super::DistError;
use super::comm::Comm;
use crate::values::{Bounds, FrameParams, PixelRect};

/// A compositing tile's side, in pixels.
pub const TILE: u32 = 64;

/// The image's tiles, row-major, tile t owned by rank `t mod P`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TileGrid {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Ranks the tiles are dealt among.
    pub ranks: usize,
}

impl TileGrid {
    fn tiles_x(&self) -> u32 {
        self.width.div_ceil(TILE)
    }

    /// How many tiles cover the image.
    pub fn count(&self) -> usize {
        (self.tiles_x() * self.height.div_ceil(TILE)) as usize
    }

    /// Tile `tile`'s pixels (the last row and column of tiles cut at the image's edge).
    pub fn rect(&self, tile: usize) -> PixelRect {
        let (tx, ty) = (tile as u32 % self.tiles_x(), tile as u32 / self.tiles_x());
        PixelRect {
            x0: tx * TILE,
            y0: ty * TILE,
            x1: ((tx + 1) * TILE).min(self.width),
            y1: ((ty + 1) * TILE).min(self.height),
        }
    }

    /// The rank that owns tile `tile`.
    pub fn owner(&self, tile: usize) -> usize {
        tile % self.ranks
    }

    /// The tiles `rank` owns, increasing.
    pub fn owned_by(&self, rank: usize) -> impl Iterator<Item = usize> + use<> {
        (rank..self.count()).step_by(self.ranks)
    }

    /// The tiles `rect` touches, increasing.
    pub fn touching(&self, rect: PixelRect) -> Vec<usize> {
        if rect.is_empty() {
            return Vec::new();
        }
        let tx = (rect.x0 / TILE)..(rect.x1.div_ceil(TILE));
        let ty = (rect.y0 / TILE)..(rect.y1.div_ceil(TILE));
        ty.flat_map(|y| tx.clone().map(move |x| (y * self.tiles_x() + x) as usize))
            .collect()
    }
}

/// The pixels whose rays can meet `b` (a brick's part of the march box): the rectangle
/// around its corners' projections, a pixel wider on each side for rounding; the whole image
/// when a corner lies behind the eye's plane.
pub fn screen_rect(frame: &FrameParams, b: Bounds) -> PixelRect {
    let full = PixelRect::full(frame.width, frame.height);
    if b.is_empty() {
        return PixelRect::default();
    }
    let c = &frame.camera;
    // A pixel at (sx, sy) looks along forward + sx right + sy up: a point at eye + v is on
    // that ray where (lambda, lambda sx, lambda sy) solves [forward right up] u = v.
    let basis = DMat3::from_cols(c.forward, c.right, c.up);
    if basis.determinant().abs() < 1e-300 {
        return full;
    }
    let to_screen = basis.inverse();
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for k in 0..8 {
        let corner = DVec3::new(
            if k & 1 == 0 { b.min.x } else { b.max.x },
            if k & 2 == 0 { b.min.y } else { b.max.y },
            if k & 4 == 0 { b.min.z } else { b.max.z },
        );
        let u = to_screen * (corner - c.eye);
        if u.x.is_nan() || u.x <= 0.0 {
            return full;
        }
        for (axis, s) in [u.y / u.x, u.z / u.x].into_iter().enumerate() {
            lo[axis] = lo[axis].min(s);
            hi[axis] = hi[axis].max(s);
        }
    }
    let (w, h) = (f64::from(frame.width), f64::from(frame.height));
    // Pixel x's ray has sx = 2 (x + 0.5) / w - 1; pixel y's has sy = 1 - 2 (y + 0.5) / h.
    let x_of = |sx: f64| (sx + 1.0) * 0.5 * w - 0.5;
    let y_of = |sy: f64| (1.0 - sy) * 0.5 * h - 0.5;
    let clamp = |v: f64, limit: f64| v.clamp(0.0, limit) as u32;
    let rect = PixelRect {
        x0: clamp(x_of(lo[0]).floor() - 1.0, w),
        x1: clamp(x_of(hi[0]).ceil() + 2.0, w),
        y0: clamp(y_of(hi[1]).floor() - 1.0, h),
        y1: clamp(y_of(lo[1]).ceil() + 2.0, h),
    };
    rect.intersection(&full)
}

/// Bytes of a piece's header: tile, x0, y0, x1, y1.
const HEADER: usize = 5 * 4;

/// The smallest rectangle within `piece` (a part of the layer's rectangle `rect`) that holds
/// every pixel of `layer` other than the identity `[0, 0, 0, 1]` (empty where none is).
fn changed_part(layer: &[[f64; 4]], rect: PixelRect, piece: PixelRect) -> PixelRect {
    let (mut x0, mut y0, mut x1, mut y1) = (u32::MAX, u32::MAX, 0, 0);
    for y in piece.y0..piece.y1 {
        let row = rect.index(piece.x0, y);
        let pixels = &layer[row..row + piece.width() as usize];
        let changed = |p: &[f64; 4]| *p != [0.0, 0.0, 0.0, 1.0];
        if let Some(first) = pixels.iter().position(changed) {
            let last = pixels.iter().rposition(changed).unwrap_or(first);
            x0 = x0.min(piece.x0 + first as u32);
            x1 = x1.max(piece.x0 + last as u32 + 1);
            y0 = y0.min(y);
            y1 = y + 1;
        }
    }
    if x0 >= x1 {
        return PixelRect::default();
    }
    PixelRect { x0, y0, x1, y1 }
}

/// A rank's tiles after one frame's direct send.
pub struct Blended {
    /// This rank's tiles ([`TileGrid::owned_by`] order), each row-major `[r, g, b, T]`.
    pub tiles: Vec<Vec<[f64; 4]>>,
    /// Bytes this rank sent to the others.
    pub bytes_sent: usize,
}

/// Sends the parts of `layer` (the pixels of `rect`, row-major) to the tiles' owners, and
/// returns this rank's tiles: every rank's pieces blended in `order` (front to back; a rank
/// that sent nothing for a pixel is transparent there).
pub fn direct_send(
    comm: &dyn Comm,
    grid: &TileGrid,
    rect: PixelRect,
    layer: &[[f64; 4]],
    order: &[usize],
) -> Result<Blended, DistError> {
    assert_eq!(
        layer.len(),
        rect.len(),
        "one layer pixel per pixel of its rectangle"
    );
    // The pieces for each owner in rank order, written once into the buffer the collective
    // sends (`Parts`: rank r's bytes, then r + 1's).
    let me = comm.rank();
    let touching = grid.touching(rect);
    let mut parts = super::comm::Parts::default();
    let mut bytes_sent = 0;
    let mut message = Vec::new();
    for to in 0..comm.size() {
        message.clear();
        for &tile in touching.iter().filter(|&&t| grid.owner(t) == to) {
            // Only the part of the piece whose pixels the brick changed: a pixel whose rays
            // met no density in the brick is exactly [0, 0, 0, 1], which blends as the
            // identity.
            let piece = changed_part(layer, rect, grid.rect(tile).intersection(&rect));
            if piece.is_empty() {
                continue;
            }
            let header = [tile as u32, piece.x0, piece.y0, piece.x1, piece.y1];
            message.extend_from_slice(bytemuck::cast_slice(&header));
            for y in piece.y0..piece.y1 {
                let row = rect.index(piece.x0, y);
                let pixels = &layer[row..row + piece.width() as usize];
                message.extend_from_slice(bytemuck::cast_slice(pixels));
            }
        }
        if to != me {
            bytes_sent += message.len();
        }
        parts.push(&message);
    }
    let received = comm.all_to_all_v(&parts)?;
    drop(parts);

    let owned: Vec<usize> = grid.owned_by(me).collect();
    let mut blended: Vec<Vec<[f64; 4]>> = owned
        .iter()
        .map(|&t| vec![[0.0, 0.0, 0.0, 1.0]; grid.rect(t).len()])
        .collect();
    let slot = |tile: usize| (tile - me) / grid.ranks;
    for &from in order {
        let mut bytes = received.part(from);
        while !bytes.is_empty() {
            let malformed =
                || DistError::Malformed(format!("rank {from} sent a tile piece cut short"));
            if bytes.len() < HEADER {
                return Err(malformed());
            }
            let [tile, x0, y0, x1, y1]: [u32; 5] = bytemuck::pod_read_unaligned(&bytes[..HEADER]);
            let piece = PixelRect { x0, y0, x1, y1 };
            let tile = tile as usize;
            let pixel_bytes = piece.len() * 32;
            if bytes.len() < HEADER + pixel_bytes
                || tile >= grid.count()
                || grid.owner(tile) != me
                || grid.rect(tile).intersection(&piece) != piece
            {
                return Err(malformed());
            }
            let tile_rect = grid.rect(tile);
            let target = &mut blended[slot(tile)];
            // Read in place (the pieces are not 8-byte aligned in the buffer).
            let mut next = bytes[HEADER..HEADER + pixel_bytes]
                .chunks_exact(32)
                .map(bytemuck::pod_read_unaligned::<[f64; 4]>);
            for y in piece.y0..piece.y1 {
                for x in piece.x0..piece.x1 {
                    let behind = next.next().expect("sized above");
                    let acc = &mut target[tile_rect.index(x, y)];
                    let t_front = acc[3];
                    for c in 0..3 {
                        acc[c] += t_front * behind[c];
                    }
                    acc[3] = t_front * behind[3];
                }
            }
            bytes = &bytes[HEADER + pixel_bytes..];
        }
    }
    Ok(Blended {
        tiles: blended,
        bytes_sent,
    })
}

/// A rank's tiles' sums of finished frames (the accumulation a single-rank backend keeps,
/// split by tile owner).
pub struct TileSums {
    /// The image's tiles.
    pub grid: TileGrid,
    /// The rank whose tiles these are.
    pub rank: usize,
    /// Frames accumulated so far.
    pub frames: u32,
    sums: Vec<Vec<[f64; 4]>>,
}

impl TileSums {
    /// Zero sums for the tiles `rank` owns.
    pub fn new(grid: TileGrid, rank: usize) -> TileSums {
        TileSums {
            grid,
            rank,
            frames: 0,
            sums: grid
                .owned_by(rank)
                .map(|t| vec![[0.0; 4]; grid.rect(t).len()])
                .collect(),
        }
    }

    /// Adds a frame's blended tiles ([`direct_send`]) finished over `background`: colour
    /// `C + T bg`, opacity `1 - T`, the integrator's own finish.
    pub fn add(&mut self, blended: &[Vec<[f64; 4]>], background: [f64; 3]) {
        for (sum, tile) in self.sums.iter_mut().zip(blended) {
            for (s, p) in sum.iter_mut().zip(tile) {
                let tr = p[3];
                let finished = [
                    p[0] + tr * background[0],
                    p[1] + tr * background[1],
                    p[2] + tr * background[2],
                    1.0 - tr,
                ];
                for c in 0..4 {
                    s[c] += finished[c];
                }
            }
        }
        self.frames += 1;
    }

    /// The sums end to end, in the order of the rank's tiles.
    pub fn flat(&self) -> Vec<[f64; 4]> {
        self.sums.concat()
    }
}

/// The image's pixels (row-major sums) from every rank's [`TileSums::flat`], rank order.
pub fn assemble(grid: &TileGrid, per_rank: &[Vec<[f64; 4]>]) -> Result<Vec<[f64; 4]>, DistError> {
    let mut image = vec![[0.0; 4]; grid.width as usize * grid.height as usize];
    for (rank, flat) in per_rank.iter().enumerate() {
        let mut next = flat.iter();
        for tile in grid.owned_by(rank) {
            let r = grid.rect(tile);
            for y in r.y0..r.y1 {
                for x in r.x0..r.x1 {
                    image[(y * grid.width + x) as usize] = *next.next().ok_or_else(|| {
                        DistError::Malformed(format!("rank {rank} sent too few tile pixels"))
                    })?;
                }
            }
        }
        if next.next().is_some() {
            return Err(DistError::Malformed(format!(
                "rank {rank} sent too many tile pixels"
            )));
        }
    }
    Ok(image)
}
