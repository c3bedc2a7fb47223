//! Multi-component arrays (VTK's, HDF5 snapshots') as attributes: one a component, and the
//! magnitude of three.

use crate::values::Attribute;

/// Names for the components of a multi-component array, as ParaView shows them.
fn component_names(name: &str, components: usize) -> Vec<String> {
    match components {
        1 => vec![name.to_owned()],
        3 => ["x", "y", "z"]
            .iter()
            .map(|c| format!("{name}_{c}"))
            .collect(),
        n => (0..n).map(|i| format!("{name}_{i}")).collect(),
    }
}

/// Every attribute an array of `components` per particle becomes (see [`split_components`]).
pub(crate) fn array_attribute_names(name: &str, components: usize) -> Vec<String> {
    let mut names = component_names(name, components);
    if components == 3 {
        names.push(magnitude_name(name));
    }
    names
}

fn magnitude_name(name: &str) -> String {
    format!("{name}_magnitude")
}

/// Splits an interleaved array of `components` per particle into named attributes; three
/// components also give their magnitude (`<name>_magnitude`), what users colour by most.
pub(crate) fn split_components(name: &str, data: &[f64], components: usize) -> Vec<Attribute> {
    let n = data.len() / components.max(1);
    let mut out: Vec<Attribute> = component_names(name, components)
        .into_iter()
        .enumerate()
        .map(|(c, name)| Attribute {
            name,
            values: (0..n).map(|i| data[i * components + c]).collect(),
        })
        .collect();
    if components == 3 {
        out.push(Attribute {
            name: magnitude_name(name),
            values: (0..n)
                .map(|i| {
                    let v = &data[i * 3..i * 3 + 3];
                    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
                })
                .collect(),
        });
    }
    out
}
