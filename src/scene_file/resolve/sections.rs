//! A resolved field written back as a scene file's sections, to reproduce it.

use crate::accel::ClusterSize;
use crate::field::FieldSettings;
use crate::io::{Format, ParticleType, ReadOptions};
use crate::scene_file::{DataSection, FieldSection, MapSpec, RadiusSpec, RangeSpec};

/// The data and field sections of a scene file that reproduces a field of the data at
/// `data_path`: the path absolute, the radius in data units, the maps as their control points.
#[allow(clippy::too_many_arguments)] // one per section entry; a struct would only rename them
pub fn scene_sections(
    data_path: &std::path::Path,
    format: Option<Format>,
    read: ReadOptions,
    step: usize,
    f: &FieldSettings,
    cluster: ClusterSize,
    colormap: Option<&str>,
    periodic: Option<crate::field::PeriodicBox>,
) -> (DataSection, FieldSection) {
    let absolute = |p: &std::path::Path| std::path::absolute(p).unwrap_or(p.to_path_buf());
    (
        DataSection {
            path: Some(absolute(data_path)),
            format,
            step: Some(step),
            attribute: f.attribute.clone(),
            attribute_range: f.attribute_range.map(|(a, b)| RangeSpec::Fixed(a, b)),
            radius_attribute: f.radius_attribute.clone(),
            particle_type: (read.particle_type != ParticleType::GAS).then_some(read.particle_type),
            physical: read.physical.then_some(true),
            smoothing: f
                .radius_attribute
                .as_deref()
                .and_then(crate::scene::smoothing::Smoothing::of_attribute),
            periodic: Some(crate::scene_file::periodic::PeriodicSetting::of(periodic)),
        },
        FieldSection {
            radius: Some(RadiusSpec::Absolute(f.radius)),
            radius_map: Some(MapSpec::Points(f.radius_map.0.points().to_vec())),
            density_map: Some(MapSpec::Points(f.density_map.0.points().to_vec())),
            colormap: colormap.map(|c| {
                if c.ends_with(".json") {
                    absolute(std::path::Path::new(c))
                        .to_string_lossy()
                        .into_owned()
                } else {
                    c.to_owned()
                }
            }),
            classification: Some(f.classification),
            cluster: Some(cluster),
            kernel: f.kernel.is_sph().then_some(f.kernel),
            mass: f.mass.clone(),
            density: f.density.clone(),
        },
    )
}
