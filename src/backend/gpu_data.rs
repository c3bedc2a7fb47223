//! A step prepared for a GPU backend: Hilbert-sorted particles in local coordinates, packed
//! the way `shaders_glsl/shared/rbf.glsl` reads them. Both GPU backends upload exactly this.
//!
//! # Where the work happens
//! The CPU makes one pass over a step ([`StepStaging::write`]), in the step's own order,
//! straight into the memory the device copies from: each position minus the series' centre in
//! f64, rounded to f32 (the local coordinates of [`HilbertQuantizer::local`]), the attribute
//! normalised to t, the radius attribute rounded to f32, and on the way what the precision rule
//! below needs (the largest coordinate, the smallest and largest radius). The Hilbert keys of
//! those f32 local coordinates, their sort and the gather into Hilbert order then run on the
//! device (`wgpu_lbvh::prepare`, `ash_rt::prepare`), or on the CPU ([`GpuStepData::prepare`]:
//! the reference the devices are tested against), with the same results bit for bit.
//!
//! t is normalised in the pass, in f64, not on the device: beside the conversion it costs
//! nothing, and an attribute rounded to f32 before the subtraction would lose the digits that
//! tell its values apart when its range is narrow against its magnitude (values 1e6 + [0, 1]
//! would keep steps of 1/16).
//!
//! # Precision of positions
//! Local coordinates are the data's minus the series' centre, subtracted in f64, so offsets
//! from the origin cost nothing. Rounded to f32 they still carry an absolute error of up to
//! 2^-24 of the largest local coordinate, which a particle's radius may not tolerate: a
//! radius of 1e-6 of the domain makes it a 6% error of the distance. `backend::precision` bounds
//! the relative Phi error of every source (positions, kernel, terms, sums) for a scene; where
//! f32 positions would exceed the tolerance asked for (see [`Precision`]), positions go to the
//! GPU as double-single pairs, hi
//! the f32 rounding and lo the f32 remainder (about 48 bits), and the shaders compute
//! distances from both (`POSITION_DS`, `shaders_glsl/shared/rbf.glsl`). A scene that does not
//! need it uploads no lo parts and runs kernels without the extra arithmetic. The lo parts are
//! a second pass over the positions ([`GpuStepData::write_lo`]), made only when the first
//! pass's bound asks for them.

use glam::DVec3;
use rayon::prelude::*;

use super::precision::{PositionKind, Representation, SceneNumbers, Summation, choose_gpu};
use super::shaders::GpuField;
use super::shaders::cpu::gather::gather;
use super::{Precision, StepInput};
use crate::accel::{ClusterSize, HilbertQuantizer, hilbert_order, max_reach_count};
use crate::field::{
    FieldError, FieldInputs, FieldSettings, FieldTables, normalise, particle_radius,
};
use crate::values::tables::{lookup, steepest_relative_slope, value_extremes};
use crate::values::{Kernel, Step};

mod slots;

use slots::{CHUNK, for_each_particle};
pub use slots::{Slots, Slots4, Slots16, slots4, slots16};

/// One step, ready to upload: everything a backend needs beside the particle arrays, which
/// live on the device.
#[derive(Clone, Debug, PartialEq)]
pub struct GpuStepData {
    /// Local coordinates are data coordinates minus this (the series' bounding-box centre), so
    /// f32 keeps its digits for data far from the origin.
    pub origin: DVec3,
    /// The Hilbert grid over the series' bounds (its origin is `origin`).
    pub quantizer: HilbertQuantizer,
    /// Particles in the step.
    pub count: usize,
    /// The precision asked for, and what it chose for this scene: positions, sums and the
    /// error bound that follows (`double_single` and `compensated` follow it).
    pub precision: Precision,
    /// How it holds positions and sums terms, and the error bound that follows.
    pub representation: Representation,
    /// The largest |local coordinate| (of the f32 positions), which the bound needs again when
    /// the radii change.
    pub largest_coordinate: f64,
    /// Positions as double-single pairs: the device holds their lo parts.
    pub double_single: bool,
    /// The scene has a per-particle radius attribute (the device holds it, in Hilbert order).
    pub has_radius_attribute: bool,
    /// The kernel; an SPH kernel's per-particle volumes `m/ρ` follow the radius attribute in
    /// the same buffer ([`Self::volume_offset`]).
    pub kernel: Kernel,
    /// The smallest positive and the largest volume (an SPH kernel's; (1, 1) otherwise).
    pub volume_range: (f64, f64),
    /// Particles per cluster box K.
    pub cluster: ClusterSize,
    /// The field's uniform: the global radius, constant map values and `k`.
    pub field: GpuField,
    /// Whether the radius map varies (looked up per particle).
    pub radius_map_varies: bool,
    /// Whether the density map varies (looked up per particle).
    pub density_map_varies: bool,
    /// The density, radius and colour maps' tables.
    pub tables: FieldTables,
}

/// A step's particles in Hilbert order, on the host: what the devices' preparation computes
/// (tests read it back to compare with [`GpuStepData::prepare`]).
#[derive(Clone, Debug, PartialEq)]
pub struct SortedParticles {
    /// Per particle: xyz local position (the hi part with double-single positions), w the
    /// normalised attribute t (0 without an attribute).
    pub points: Vec<[f32; 4]>,
    /// With double-single positions, per particle: xyz the lo part (local position minus hi),
    /// w 0.
    pub points_lo: Option<Vec<[f32; 4]>>,
    /// The radius attribute h, only when the scene uses one.
    pub radius_attribute: Option<Vec<f32>>,
    /// An SPH kernel's volumes m/ρ, only with an SPH kernel.
    pub volume: Option<Vec<f32>>,
    /// `order[k]` is the step's index of sorted particle k.
    pub order: Vec<u32>,
}

/// What the precision rule needs of a step's particles: the largest |local coordinate| and
/// the smallest and largest positive radius.
#[derive(Clone, Copy, Debug)]
struct Extremes {
    largest: f64,
    r_min: f64,
    r_max: f64,
}

impl Extremes {
    const NONE: Extremes = Extremes {
        largest: 0.0,
        r_min: f64::INFINITY,
        r_max: 0.0,
    };

    fn add_radius(&mut self, r: f64) {
        if r > 0.0 {
            self.r_min = self.r_min.min(r);
            self.r_max = self.r_max.max(r);
        }
    }

    fn merge(a: Extremes, b: Extremes) -> Extremes {
        Extremes {
            largest: a.largest.max(b.largest),
            r_min: a.r_min.min(b.r_min),
            r_max: a.r_max.max(b.r_max),
        }
    }
}

/// What a particle contributes to the arrays, as the pass and the radius rule see it.
struct ParticleValues<'a> {
    inputs: FieldInputs<'a>,
    settings: &'a FieldSettings,
    tables: FieldTables,
}

impl ParticleValues<'_> {
    /// Particle i's normalised attribute t (0 without an attribute).
    #[inline]
    fn t(&self, i: usize) -> f32 {
        self.inputs
            .attribute
            .map_or(0.0, |a| normalise(a.values[i], self.inputs.range) as f32)
    }

    #[inline]
    fn h(&self, i: usize) -> Option<f32> {
        self.inputs.radius.map(|h| h.values[i] as f32)
    }

    /// The radius the shaders give a particle with this t and h (`particle_radius`, from the
    /// f32 values they hold).
    #[inline]
    fn radius(&self, t: f32, h: Option<f32>) -> f64 {
        let m = lookup(&self.tables.radius, f64::from(t));
        particle_radius(self.settings.radius, m, h.map(f64::from))
    }

    /// The radius every particle has, when the radius map is constant and there is no radius
    /// attribute (the table then holds one value, which the lookup returns exactly).
    fn constant_radius(&self) -> Option<f64> {
        (self.settings.radius_map.0.is_constant() && self.inputs.radius.is_none())
            .then(|| self.radius(0.0, None))
    }

    /// The radius extremes over `n` particles.
    fn radius_extremes(&self, n: usize) -> Extremes {
        if let Some(r) = self.constant_radius() {
            let mut e = Extremes::NONE;
            if n > 0 {
                e.add_radius(r);
            }
            return e;
        }
        (0..n)
            .into_par_iter()
            .with_min_len(CHUNK)
            .fold(
                || Extremes::NONE,
                |mut e, i| {
                    e.add_radius(self.radius(self.t(i), self.h(i)));
                    e
                },
            )
            .reduce(|| Extremes::NONE, Extremes::merge)
    }
}

/// A step that passed the one check ([`FieldInputs::check`]), ready for the staging pass.
pub struct StepStaging<'a> {
    input: &'a StepInput<'a>,
    values: ParticleValues<'a>,
    quantizer: HilbertQuantizer,
}

impl StepStaging<'_> {
    /// Particles in the step.
    pub fn len(&self) -> usize {
        self.input.step.len()
    }

    /// Whether the step has no particles.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Whether the pass writes a radius attribute ([`Self::write`] needs its slots).
    pub fn has_radius_attribute(&self) -> bool {
        self.values.inputs.radius.is_some()
    }

    /// Whether the step needs the radius-attribute buffer (as [`GpuStepData::has_factors`]).
    pub fn has_factors(&self) -> bool {
        self.has_radius_attribute() || self.input.field.kernel.is_sph()
    }

    /// Floats of the radius-attribute buffer the pass writes: the radius attribute, then an
    /// SPH kernel's volumes ([`factor_layout`]); 0 when neither.
    pub fn factor_words(&self) -> usize {
        factor_layout(
            self.len(),
            self.has_radius_attribute(),
            self.input.field.kernel.is_sph(),
        )
        .1
    }

    /// The staging pass: writes every particle, in the step's order, into `points` (slots for
    /// particles `first ..`, the parts in order and covering the step: xyz the f32 local
    /// position, w t) and, when the scene has one, its radius attribute into `radius`; and
    /// decides the positions' precision from what it saw. The caller writes the lo parts
    /// ([`GpuStepData::write_lo`]) when the result is double-single.
    pub fn write(
        self,
        points: Vec<(usize, Slots16<'_>)>,
        factors: Option<Slots4<'_>>,
    ) -> GpuStepData {
        let step = self.input.step;
        let origin = self.quantizer.origin();
        let (second, volume) = split_factors(
            factors,
            step.len(),
            self.has_radius_attribute(),
            self.input.field.kernel.is_sph(),
        );
        let volume_range = match volume {
            Some(slots) => write_volume(&self.values.inputs, slots),
            None => (1.0, 1.0),
        };
        // A scene whose radii are all equal (the common case) needs no radius per particle.
        let constant_radius = self.values.constant_radius();
        let mut extremes = for_each_particle(points, second, |i, e| {
            let p = self.quantizer.local(step.positions[i]);
            let t = self.values.t(i);
            let h = self.values.h(i);
            let largest = p[0].abs().max(p[1].abs()).max(p[2].abs());
            e.largest = e.largest.max(f64::from(largest));
            if constant_radius.is_none() {
                e.add_radius(self.values.radius(t, h));
            }
            (
                bytemuck::cast([p[0], p[1], p[2], t]),
                h.map(bytemuck::cast::<f32, [u8; 4]>),
            )
        });
        if let Some(r) = constant_radius
            && !self.is_empty()
        {
            extremes.add_radius(r);
        }
        let mut data = GpuStepData {
            origin,
            quantizer: self.quantizer,
            count: step.len(),
            precision: self.input.precision,
            representation: choose_gpu(Precision::F32, &SceneNumbers::EMPTY, 1),
            largest_coordinate: extremes.largest,
            double_single: false,
            has_radius_attribute: self.has_radius_attribute(),
            kernel: self.input.field.kernel,
            volume_range,
            cluster: self.input.cluster,
            field: GpuField::default(),
            radius_map_varies: false,
            density_map_varies: false,
            tables: self.values.tables,
        };
        data.set_maps(self.values.settings);
        data.choose_precision(step, extremes);
        data
    }
}

impl GpuStepData {
    /// The one check every backend makes ([`FieldInputs::check`]: every backend refuses the
    /// same input, and normalises over the same range), and what the staging pass needs.
    pub fn check<'a>(input: &'a StepInput<'a>) -> Result<StepStaging<'a>, FieldError> {
        let inputs = FieldInputs::check(input.step, input.field, input.series_range)?;
        Ok(StepStaging {
            input,
            values: ParticleValues {
                inputs,
                settings: input.field,
                tables: FieldTables::of(input.field),
            },
            quantizer: HilbertQuantizer::new(input.series_bounds),
        })
    }

    /// Prepares a step on the CPU: the staging pass into host arrays, then the Hilbert order
    /// ([`hilbert_order`], the keys `hilbert_keys.wgsl` and `hilbert_keys.comp` compute on the
    /// devices) and the gather into it: the GPU backends' twin.
    pub fn prepare(input: &StepInput<'_>) -> Result<(GpuStepData, SortedParticles), FieldError> {
        let staging = GpuStepData::check(input)?;
        let n = staging.len();
        let mut points = vec![[0.0f32; 4]; n];
        let words = staging.factor_words();
        let mut factors = staging.has_factors().then(|| vec![0.0f32; words]);
        let data = staging.write(
            vec![(0, slots16(&mut points))],
            factors.as_deref_mut().map(slots4),
        );
        let order = hilbert_order(&input.step.positions, input.series_bounds);
        let points_lo = data.double_single.then(|| {
            let mut lo = vec![[0.0f32; 4]; n];
            data.write_lo(input.step, vec![(0, slots16(&mut lo))]);
            gather(&lo, &order)
        });
        let sorted = SortedParticles {
            points: gather(&points, &order),
            points_lo,
            radius_attribute: factors
                .as_ref()
                .filter(|_| data.has_radius_attribute)
                .map(|f| gather(&f[..n], &order)),
            volume: factors
                .as_ref()
                .filter(|_| data.kernel.is_sph())
                .map(|f| gather(&f[data.volume_offset()..][..n], &order)),
            order,
        };
        Ok((data, sorted))
    }

    /// Particle p's lo part: its local position minus the f32 rounding of it (the hi part),
    /// rounded to f32.
    #[inline]
    fn lo_of(&self, p: DVec3) -> [f32; 4] {
        let l = p - self.origin;
        let lo = |c: f64| (c - f64::from(c as f32)) as f32;
        [lo(l.x), lo(l.y), lo(l.z), 0.0]
    }

    /// The lo parts of double-single positions, in the step's order, into `parts` (as
    /// [`StepStaging::write`] writes the points).
    pub fn write_lo(&self, step: &Step, parts: Vec<(usize, Slots16<'_>)>) {
        for_each_particle::<_, [u8; 4], _>(parts, None, |i, _| {
            (bytemuck::cast(self.lo_of(step.positions[i])), None)
        });
    }

    /// The radius attribute `settings` names and an SPH kernel's volumes, in the step's order,
    /// as f32, laid out as [`Self::factor_words`] says (after a change of [`Self::apply_field`]
    /// says they changed); nothing when there are neither.
    pub fn write_factors(
        &self,
        step: &Step,
        settings: &FieldSettings,
        slots: Slots4<'_>,
    ) -> Result<(), FieldError> {
        let inputs = FieldInputs::check(step, settings, None)?;
        let (radius, volume) = split_factors(
            Some(slots),
            step.len(),
            self.has_radius_attribute,
            self.kernel.is_sph(),
        );
        if let (Some(h), Some(slots)) = (inputs.radius, radius) {
            for_each_particle::<_, [u8; 4], _>(vec![(0, slots)], None, |i, _| {
                (bytemuck::cast(h.values[i] as f32), None)
            });
        }
        if let Some(slots) = volume {
            write_volume(&inputs, slots);
        }
        Ok(())
    }

    /// Where an SPH kernel's volumes start in the radius-attribute buffer (floats): after the
    /// radius attribute's section, rounded up to 64 floats (256 bytes, the offset alignment
    /// a storage binding needs), or at 0 without one.
    pub fn volume_offset(&self) -> usize {
        factor_layout(self.count, self.has_radius_attribute, self.kernel.is_sph()).0
    }

    /// Floats the radius-attribute buffer holds for this step (0: none is needed).
    pub fn factor_words(&self) -> usize {
        factor_layout(self.count, self.has_radius_attribute, self.kernel.is_sph()).1
    }

    /// Whether the step needs the radius-attribute buffer: a radius attribute, or an SPH
    /// kernel's volumes.
    pub fn has_factors(&self) -> bool {
        self.has_radius_attribute || self.kernel.is_sph()
    }

    /// Where each section of the radius-attribute buffer starts (floats), each `count` long:
    /// what a backend gathers into the sorted order, one section at a time.
    pub fn factor_sections(&self) -> Vec<usize> {
        let mut sections = Vec::new();
        if self.has_radius_attribute {
            sections.push(0);
        }
        if self.kernel.is_sph() {
            sections.push(self.volume_offset());
        }
        sections
    }

    /// Applies field settings that keep the particles (the same attribute and range): checks
    /// them with the one check every backend makes ([`FieldInputs::check`]), updates the maps,
    /// and chooses the positions' precision again from the new radii (new radii may need
    /// double-single positions, or no longer need them). Says what a backend must write and
    /// upload again: the radius attribute ([`Self::write_radius_attribute`]) and the lo parts
    /// ([`Self::write_lo`]).
    pub fn apply_field(
        &mut self,
        step: &Step,
        old: &FieldSettings,
        new: &FieldSettings,
        series_range: Option<(f64, f64)>,
    ) -> Result<Changed, FieldError> {
        let inputs = FieldInputs::check(step, new, series_range)?;
        let factors_changed = new.radius_attribute != old.radius_attribute
            || new.kernel != old.kernel
            || new.mass != old.mass
            || new.density != old.density;
        if factors_changed {
            self.volume_range = match &inputs.volume {
                Some(_) => volume_range(&inputs, step.len()),
                None => (1.0, 1.0),
            };
        }
        let values = ParticleValues {
            inputs,
            settings: new,
            tables: FieldTables::of(new),
        };
        let extremes = Extremes {
            largest: self.largest_coordinate,
            ..values.radius_extremes(step.len())
        };
        self.has_radius_attribute = values.inputs.radius.is_some();
        self.kernel = new.kernel;
        self.tables = values.tables;
        self.set_maps(new);
        let had_lo = self.double_single;
        self.choose_precision(step, extremes);
        Ok(Changed {
            factors: factors_changed,
            positions_lo: self.double_single && !had_lo,
        })
    }

    /// Bounds the error of every representation of this scene ([`choose_gpu`]) and takes the
    /// one the precision asked for: positions (`double_single`) and sums (`compensated`).
    fn choose_precision(&mut self, step: &Step, extremes: Extremes) {
        let (mut w_min, mut w_max) = if self.density_map_varies {
            value_extremes(&self.tables.density)
        } else {
            let w = f64::from(self.field.radius[2]);
            (w, w)
        };
        if self.kernel.is_sph() {
            // A term's weight is w V σ s³ / r³ (`particle_weight`).
            let (v_min, v_max) = self.volume_range;
            w_min *= self.kernel.weight_factor(extremes.r_max, v_min);
            w_max *= self.kernel.weight_factor(extremes.r_min, v_max);
        }
        let slope = |varies: bool, table: &[f32]| {
            if varies {
                steepest_relative_slope(table)
            } else {
                0.0
            }
        };
        let mut scene = SceneNumbers {
            largest: extremes.largest,
            r_min: extremes.r_min,
            r_max: extremes.r_max,
            // Every particle first: where even that meets the tolerance with plain sums (small
            // steps, images), the count below is not needed.
            max_terms: step.len(),
            w_min,
            w_max,
            radius_varies: self.radius_map_varies || self.has_radius_attribute,
            density_slope: slope(self.density_map_varies, &self.tables.density),
            radius_slope: slope(self.radius_map_varies, &self.tables.radius),
            kernel: self.kernel,
        };
        let cluster = self.cluster.get() as u32;
        self.representation = choose_gpu(self.precision, &scene, cluster);
        // A forced precision states its bound over the count too (no choice rides on it).
        let forced = !matches!(self.precision, Precision::Auto { .. });
        if forced
            || self.representation.summation != Summation::F32
            || !self.representation.meets_tolerance()
        {
            scene.max_terms = max_reach_count(&step.positions, extremes.r_max);
            self.representation = choose_gpu(self.precision, &scene, cluster);
        }
        self.double_single = self.representation.positions == PositionKind::DoubleSingle;
    }

    /// Whether a point's clusters' sums are added compensated (`COMPENSATED_SUM`).
    pub fn compensated(&self) -> bool {
        matches!(self.representation.summation, Summation::Compensated { .. })
    }

    /// Whether positions are double-single pairs (`POSITION_DS`).
    pub fn double_single(&self) -> bool {
        self.double_single
    }

    /// How the positions are held and the terms summed, for
    /// [`super::Backend::representation`].
    pub fn representation(&self) -> Representation {
        self.representation
    }

    /// A query point as the query kernels read it: one vec4 (local coordinates, f32), or with
    /// double-single positions two (hi, then lo).
    pub fn push_query(&self, x: DVec3, out: &mut Vec<[f32; 4]>) {
        let [x0, x1, x2] = self.quantizer.local(x);
        out.push([x0, x1, x2, 0.0]);
        if self.double_single() {
            out.push(self.lo_of(x));
        }
    }

    /// Updates everything that depends on the maps and the global radius (not the particles),
    /// from `settings` and the maps' tables (`self.tables`, baked from them).
    fn set_maps(&mut self, settings: &FieldSettings) {
        let n = self.count;
        self.radius_map_varies = !settings.radius_map.0.is_constant();
        self.density_map_varies = !settings.density_map.0.is_constant();
        let one_radius = settings.radius * f64::from(self.tables.radius[0]);
        self.field = GpuField {
            radius: [
                settings.radius as f32,
                self.tables.radius[0],
                self.tables.density[0],
                (4.5 / (one_radius * one_radius)) as f32,
            ],
            counts: [n as u32, self.cluster.clusters_for(n) as u32, 0, 0],
            factors: [self.volume_offset() as u32, 0, 0, 0],
        };
    }

    /// Bytes of particle data a GPU holds (positions with attribute, their lo parts and radii
    /// when used).
    pub fn particle_bytes(&self) -> usize {
        self.count
            * (16
                + 16 * usize::from(self.double_single)
                + 4 * usize::from(self.has_radius_attribute)
                + 4 * usize::from(self.kernel.is_sph()))
    }
}

/// The radius-attribute buffer's layout for `n` particles: where the volumes start and the
/// floats in all. The radius attribute takes floats `0..n`; an SPH kernel's volumes follow
/// from the next multiple of 64 (a storage binding's offset must be a multiple of 256 bytes).
pub fn factor_layout(n: usize, radius_attribute: bool, sph: bool) -> (usize, usize) {
    let offset = if radius_attribute {
        n.div_ceil(64) * 64
    } else {
        0
    };
    let words = match (radius_attribute, sph) {
        (_, true) => offset + n,
        (true, false) => n,
        (false, false) => 0,
    };
    (offset, words)
}

/// The radius-attribute buffer's slots split into the radius attribute's section and the
/// volumes' (each `None` where the scene has none).
fn split_factors(
    slots: Option<Slots4<'_>>,
    n: usize,
    radius_attribute: bool,
    sph: bool,
) -> (Option<Slots4<'_>>, Option<Slots4<'_>>) {
    let Some(slots) = slots else {
        return (None, None);
    };
    let (offset, words) = factor_layout(n, radius_attribute, sph);
    assert!(
        slots.len() >= words,
        "the radius-attribute slots hold {words} floats"
    );
    let len = slots.len();
    let (head, rest) = slots.split_at(offset.min(len));
    let radius = radius_attribute.then(|| head.split_at(n).0);
    let volume = sph.then(|| rest.split_at(n).0);
    (radius, volume)
}

/// Writes every particle's volume `m/ρ` as f32 into `slots`, in the step's order, and returns
/// the smallest positive and the largest.
fn write_volume(inputs: &FieldInputs<'_>, slots: Slots4<'_>) -> (f64, f64) {
    let n = slots.len();
    for_each_particle::<_, [u8; 4], _>(vec![(0, slots)], None, |i, _| {
        (bytemuck::cast(inputs.volume(i) as f32), None)
    });
    volume_range(inputs, n)
}

/// The smallest positive and the largest volume over `n` particles ((1, 1) where there are
/// none).
fn volume_range(inputs: &FieldInputs<'_>, n: usize) -> (f64, f64) {
    let (lo, hi) = (0..n)
        .into_par_iter()
        .with_min_len(CHUNK)
        .map(|i| inputs.volume(i))
        .filter(|&v| v > 0.0)
        .fold(
            || (f64::INFINITY, 0.0f64),
            |(lo, hi), v| (lo.min(v), hi.max(v)),
        )
        .reduce(|| (f64::INFINITY, 0.0), |a, b| (a.0.min(b.0), a.1.max(b.1)));
    if lo.is_finite() { (lo, hi) } else { (1.0, 1.0) }
}

/// What [`GpuStepData::apply_field`] changed that a backend must upload again.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Changed {
    /// The radius attribute or an SPH kernel's volumes ([`GpuStepData::write_factors`]).
    pub factors: bool,
    /// The precision now needs the lo parts of the positions, and they were not held (when it
    /// no longer needs them, the kernels stop reading them: nothing to upload).
    pub positions_lo: bool,
}

#[cfg(test)]
mod tests;
