//! The GPU-built LBVH: its buffers and the passes that build and refit it. Layout and stages:
//! `src/backend/shaders/cpu/` (the CPU twins).

use bytemuck::{Pod, Zeroable};

use super::context::{GpuContext, Layout, Variant, device_error};
use super::sort::RadixSort;
use super::util::PARTS;
use super::util::{SplitBuffer, encode_pass, grid, poison, read_u32, storage, write};
use crate::accel::lbvh::{GpuBox, KeyGrid, Lbvh, NODE_WORDS};
use crate::backend::BackendError;
use crate::backend::shaders::on_wgpu;

/// How far a build goes (tests stop early to compare a stage with its twin).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum BuildStage {
    /// The cluster boxes only.
    Bounds,
    /// And the clusters' Morton keys.
    Keys,
    /// And the keys sorted.
    Sort,
    /// And the hierarchy (Karras's radix tree) over the sorted keys.
    Hierarchy,
    /// And the nodes' bounds fitted bottom up: the whole build.
    Fit,
}

/// `TreeParams` of the WGSL passes.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct TreeParams {
    /// The key grid's origin: a cell is `(centre - key_lo) * key_scale` on the 1024³ Morton grid.
    pub key_lo: [f32; 4],
    /// The key grid's cells per unit length.
    pub key_scale: [f32; 4],
    /// Clusters to build over.
    pub clusters: u32,
    /// What the bottom-up pass computes: 7, bounds and heights (a build); 6, bounds only (a refit).
    pub components: u32,
    /// Per part of the split boxes and nodes: vec4s and words (u32::MAX unsplit).
    pub part_vec4s: u32,
    /// Words per part of the split nodes (u32::MAX unsplit).
    pub part_words: u32,
}

/// What a build or refit reports back (the counters buffer).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TreeReport {
    /// Non-empty clusters: the tree's leaves.
    pub leaves: u32,
    /// The root's height in edges.
    pub depth: u32,
    /// A refit found a cluster outside the tree holding particles: rebuild.
    pub needs_rebuild: bool,
    /// The device's time on the build or refit, where it writes timestamps.
    pub device_time: Option<std::time::Duration>,
}

/// The scene's buffers a tree pass reads.
pub struct SceneBindings<'a> {
    /// The field's uniform.
    pub field: &'a wgpu::Buffer,
    /// The particles, in Hilbert order.
    pub particles: &'a SplitBuffer,
    /// The maps' baked tables.
    pub maps: &'a wgpu::Buffer,
    /// The per-particle radius attribute (and an SPH kernel's volumes).
    pub radius_attribute: &'a wgpu::Buffer,
    /// The bounds kernel's specialisation constants.
    pub variant: Variant,
}

/// The tree's buffers, for up to `capacity` clusters.
pub struct GpuTree {
    /// Clusters its buffers hold.
    pub capacity: usize,
    params: wgpu::Buffer,
    /// Cluster boxes and nodes (32 bytes per cluster each): the largest per-cluster arrays,
    /// split over up to `PARTS` buffers; their parts have equal lengths.
    pub boxes: SplitBuffer,
    /// The clusters' Morton keys (sorted after the sort).
    pub keys: wgpu::Buffer,
    /// Cluster indices, sorted with the keys.
    pub values: wgpu::Buffer,
    /// Sort scratch; after the sort, the bottom-up pass's height words.
    pub keys_tmp: wgpu::Buffer,
    /// Sort scratch for the values.
    pub values_tmp: wgpu::Buffer,
    /// The nodes (node 0 the header, then the internal nodes), split over up to `PARTS` buffers.
    pub nodes: SplitBuffer,
    /// Each internal node's parent.
    pub node_parents: wgpu::Buffer,
    /// Each leaf's (cluster's) parent.
    pub leaf_parents: wgpu::Buffer,
    /// The passes' counters: leaves, depth, a refit's rebuild flag, one word unused.
    pub counters: wgpu::Buffer,
    sort: RadixSort,
}

impl GpuTree {
    /// Buffers for `capacity` clusters with no binding larger than `max_binding` bytes. The
    /// caller has checked that the boxes and nodes fit in `PARTS` parts and the 4-byte arrays
    /// in one binding.
    pub fn new(
        ctx: &GpuContext,
        capacity: usize,
        max_binding: u64,
    ) -> Result<GpuTree, BackendError> {
        let c = capacity.max(1) as u64;
        let split = |label: &str| {
            SplitBuffer::new(ctx, label, c, 32, max_binding).ok_or_else(|| {
                device_error(format!(
                    "{c} clusters need {} bytes of {label}, more than {PARTS} storage bindings \
                     of {max_binding} bytes",
                    c * 32
                ))
            })
        };
        let need = c * (32 * 2 + 4 * 6);
        let tree = ctx.scoped(&format!("tree buffers ({need} bytes)"), || {
            Ok::<_, BackendError>(GpuTree {
                capacity,
                params: super::util::uniform(ctx, "tree params", 48),
                boxes: split("cluster boxes")?,
                keys: storage(ctx, "keys", c * 4),
                values: storage(ctx, "values", c * 4),
                keys_tmp: storage(ctx, "keys scratch / heights", c * 4),
                values_tmp: storage(ctx, "values scratch", c * 4),
                nodes: split("nodes")?,
                node_parents: storage(ctx, "node parents", c * 4),
                leaf_parents: storage(ctx, "leaf parents", c * 4),
                counters: storage(ctx, "counters", 16),
                sort: RadixSort::new(ctx, capacity),
            })
        })??;
        Ok(tree)
    }

    /// How the build passes bind the boxes and nodes (whose parts have equal lengths).
    pub fn layout(&self) -> Layout {
        Layout::of(&[&self.boxes, &self.nodes])
    }

    /// Bytes of scratch (sort buffers), beside the structure proper.
    pub fn scratch_bytes(&self) -> usize {
        (self.keys.size() + self.values.size() + self.keys_tmp.size() + self.values_tmp.size())
            as usize
            + self.sort.bytes()
    }

    /// Fills every tree buffer with 0xFF (tests: unwritten elements show).
    pub fn poison(&self, ctx: &GpuContext) {
        self.boxes.poison(ctx);
        self.nodes.poison(ctx);
        for b in [
            &self.keys,
            &self.values,
            &self.keys_tmp,
            &self.values_tmp,
            &self.node_parents,
            &self.leaf_parents,
            &self.counters,
        ] {
            poison(ctx, b);
        }
    }

    /// The nodes' bind-group entries for the hierarchy and reset passes, with the params
    /// only where the part selection reads them (the leaf count is in the counters; a binding
    /// a kernel does not use is not in its layout).
    fn node_entries<'a>(
        &'a self,
        layout: Layout,
        entries: &mut Vec<(u32, wgpu::BindingResource<'a>)>,
    ) {
        entries.extend(self.nodes.entries(14, layout));
        if layout == Layout::Split {
            entries.push((0, self.params.as_entire_binding()));
        }
    }

    fn write_params(&self, ctx: &GpuContext, grid_: &KeyGrid, clusters: u32, components: u32) {
        let p = TreeParams {
            key_lo: [grid_.lo[0], grid_.lo[1], grid_.lo[2], 0.0],
            key_scale: [grid_.scale[0], grid_.scale[1], grid_.scale[2], 0.0],
            clusters,
            components,
            part_vec4s: self.boxes.part_len(16),
            part_words: self.boxes.part_len(4),
        };
        write(ctx, &self.params, bytemuck::bytes_of(&p));
    }

    fn encode_bounds(
        &self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        scene: &SceneBindings<'_>,
        clusters: u32,
    ) -> Result<(), BackendError> {
        let layout = Layout::of(&[scene.particles, &self.boxes]);
        let mut entries = vec![
            (0, scene.field.as_entire_binding()),
            (2, scene.maps.as_entire_binding()),
            (3, scene.radius_attribute.as_entire_binding()),
        ];
        entries.extend(scene.particles.entries(10, layout));
        entries.extend(self.boxes.entries(18, layout));
        encode_pass(
            ctx,
            encoder,
            "lbvh bounds",
            on_wgpu::LBVH_BOXES,
            scene.variant,
            layout,
            &entries,
            grid(u64::from(clusters), on_wgpu::LBVH_BOXES.point().threads()),
        )
    }

    fn encode_climb(
        &self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        clusters: u32,
    ) -> Result<(), BackendError> {
        let layout = self.layout();
        let mut entries = vec![
            (0, self.params.as_entire_binding()),
            (3, self.node_parents.as_entire_binding()),
            (4, self.leaf_parents.as_entire_binding()),
            (5, self.keys_tmp.as_entire_binding()),
            (6, self.counters.as_entire_binding()),
        ];
        entries.extend(self.boxes.entries(18, layout));
        entries.extend(self.nodes.entries(14, layout));
        encode_pass(
            ctx,
            encoder,
            "lbvh climb",
            on_wgpu::LBVH_FIT_CLIMB,
            None,
            layout,
            &entries,
            grid(
                u64::from(clusters),
                on_wgpu::LBVH_FIT_CLIMB.point().threads(),
            ),
        )
    }

    /// Encodes a build over `clusters` clusters up to `until`, and submits it; returns the
    /// counters (meaningful after [`BuildStage::Fit`]).
    pub fn build(
        &self,
        ctx: &GpuContext,
        scene: &SceneBindings<'_>,
        grid_: &KeyGrid,
        clusters: u32,
        until: BuildStage,
    ) -> Result<TreeReport, BackendError> {
        assert!(clusters as usize <= self.capacity);
        self.write_params(ctx, grid_, clusters, 7);
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        let span = super::util::DeviceSpan::begin(ctx, &mut encoder);
        ctx.scoped("lbvh build", || -> Result<(), BackendError> {
            encoder.clear_buffer(&self.counters, 0, None);
            self.encode_bounds(ctx, &mut encoder, scene, clusters)?;
            if until >= BuildStage::Keys {
                let layout = self.layout();
                let mut entries = vec![
                    (0, self.params.as_entire_binding()),
                    (2, self.keys.as_entire_binding()),
                    (3, self.values.as_entire_binding()),
                    (4, self.leaf_parents.as_entire_binding()),
                    (5, self.counters.as_entire_binding()),
                ];
                entries.extend(self.boxes.entries(18, layout));
                encode_pass(
                    ctx,
                    &mut encoder,
                    "lbvh keys",
                    on_wgpu::LBVH_KEYS,
                    None,
                    layout,
                    &entries,
                    grid(u64::from(clusters), on_wgpu::LBVH_KEYS.point().threads()),
                )?;
            }
            if until >= BuildStage::Sort {
                self.sort.encode(
                    ctx,
                    &mut encoder,
                    clusters,
                    &self.keys,
                    &self.values,
                    &self.keys_tmp,
                    &self.values_tmp,
                )?;
            }
            if until >= BuildStage::Hierarchy {
                let layout = self.layout();
                let mut entries = vec![
                    (1, self.keys.as_entire_binding()),
                    (2, self.values.as_entire_binding()),
                    (4, self.node_parents.as_entire_binding()),
                    (5, self.leaf_parents.as_entire_binding()),
                    (6, self.keys_tmp.as_entire_binding()),
                    (7, self.counters.as_entire_binding()),
                ];
                self.node_entries(layout, &mut entries);
                // Thread 0 writes the header even for zero or one leaf.
                encode_pass(
                    ctx,
                    &mut encoder,
                    "lbvh hierarchy",
                    on_wgpu::LBVH_HIERARCHY,
                    None,
                    layout,
                    &entries,
                    grid(
                        u64::from(clusters.max(1)),
                        on_wgpu::LBVH_HIERARCHY.point().threads(),
                    ),
                )?;
            }
            if until >= BuildStage::Fit {
                self.encode_climb(ctx, &mut encoder, clusters)?;
            }
            Ok(())
        })??;
        self.report(ctx, encoder, span)
    }

    /// Encodes a refit (bounds, reset, climb over the built topology) and submits it.
    pub fn refit(
        &self,
        ctx: &GpuContext,
        scene: &SceneBindings<'_>,
        grid_: &KeyGrid,
        clusters: u32,
    ) -> Result<TreeReport, BackendError> {
        self.write_params(ctx, grid_, clusters, 6);
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        let span = super::util::DeviceSpan::begin(ctx, &mut encoder);
        ctx.scoped("lbvh refit", || -> Result<(), BackendError> {
            self.encode_bounds(ctx, &mut encoder, scene, clusters)?;
            encoder.clear_buffer(&self.counters, 8, Some(4));
            let layout = self.layout();
            let mut entries = vec![(6, self.counters.as_entire_binding())];
            self.node_entries(layout, &mut entries);
            encode_pass(
                ctx,
                &mut encoder,
                "lbvh reset",
                on_wgpu::LBVH_FIT_RESET,
                None,
                layout,
                &entries,
                grid(
                    u64::from(clusters),
                    on_wgpu::LBVH_FIT_RESET.point().threads(),
                ),
            )?;
            self.encode_climb(ctx, &mut encoder, clusters)
        })??;
        self.report(ctx, encoder, span)
    }

    /// Submits the recorded build or refit with the readback of its counters.
    fn report(
        &self,
        ctx: &GpuContext,
        mut encoder: wgpu::CommandEncoder,
        span: Option<super::util::DeviceSpan<'_>>,
    ) -> Result<TreeReport, BackendError> {
        if let Some(span) = &span {
            span.end(&mut encoder);
        }
        let mut bytes = Vec::new();
        super::util::read_into(ctx, Some(encoder), &self.counters, 0, 16, &mut bytes)?;
        let c: Vec<u32> = bytemuck::pod_collect_to_vec(&bytes);
        Ok(TreeReport {
            leaves: c[0],
            depth: c[1],
            needs_rebuild: c[2] != 0,
            device_time: span.map(|s| s.read(ctx)).transpose()?,
        })
    }

    /// Reads the tree back (tests): cluster boxes, keys and values (sorted after the sort
    /// stage), the hierarchy as an [`Lbvh`] and the counters.
    pub fn snapshot(
        &self,
        ctx: &GpuContext,
        clusters: usize,
    ) -> Result<TreeSnapshot, BackendError> {
        let counters = read_u32(ctx, &self.counters, 4)?;
        let leaves = counters[0] as usize;
        let node_count = if leaves <= clusters { leaves.max(1) } else { 1 };
        let boxes_raw = self.boxes.read(ctx, clusters as u64 * 32)?;
        let boxes: Vec<GpuBox> = bytemuck::pod_collect_to_vec(&boxes_raw);
        let nodes_raw = self.nodes.read(ctx, (node_count * NODE_WORDS * 4) as u64)?;
        let nodes: Vec<[u32; NODE_WORDS]> = bytemuck::pod_collect_to_vec(&nodes_raw);
        Ok(TreeSnapshot {
            boxes,
            keys: read_u32(ctx, &self.keys, clusters)?,
            values: read_u32(ctx, &self.values, clusters)?,
            lbvh: Lbvh {
                nodes,
                node_parents: read_u32(ctx, &self.node_parents, node_count)?,
                leaf_parents: read_u32(ctx, &self.leaf_parents, clusters)?,
                leaves: counters[0],
                depth: counters[1],
            },
            counters: [counters[0], counters[1], counters[2], counters[3]],
        })
    }
}

/// A tree read back from the GPU.
#[derive(Clone, Debug)]
pub struct TreeSnapshot {
    /// The cluster boxes.
    pub boxes: Vec<GpuBox>,
    /// The Morton keys, sorted.
    pub keys: Vec<u32>,
    /// Cluster indices in key order.
    pub values: Vec<u32>,
    /// The hierarchy, as the CPU twin holds it.
    pub lbvh: Lbvh,
    /// The counters as read: leaves, depth, the rebuild flag, one word unused.
    pub counters: [u32; 4],
}
