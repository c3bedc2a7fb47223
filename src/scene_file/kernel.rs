//! What an SPH kernel needs of the data, found as a user of SPH codes expects: the smoothing
//! length, the masses and the densities under the names the codes write (SWIFT's
//! `SmoothingLengths`, `Masses`, `Densities`; GADGET's `SmoothingLength`, `Density`; PySPH's
//! `h`, `m`, `rho`), each said in the log with the flag that overrides it.

use anyhow::bail;

use crate::field::{Kernel, PerParticle};

/// Names masses go by in SPH codes' output (compared ignoring case), in order of preference.
const MASS_NAMES: [&str; 4] = ["masses", "mass", "m", "pmass"];
/// Names densities go by.
const DENSITY_NAMES: [&str; 5] = ["densities", "density", "rho", "rhos", "dens"];

/// An SPH kernel's inputs after defaults.
#[derive(Debug)]
pub(super) struct SphInputs {
    pub radius_attribute: Option<String>,
    pub mass: PerParticle,
    pub density: PerParticle,
}

fn find(names: &[String], candidates: &[&str]) -> Option<String> {
    candidates
        .iter()
        .find_map(|c| names.iter().find(|n| n.eq_ignore_ascii_case(c)).cloned())
}

/// The smoothing length, mass and density of an SPH kernel: those given, else the data's own
/// (`names`: the attributes of the first step). `smoothing_names` are the names a smoothing
/// length goes by; `radius_given` whether `--radius` was given (a kernel of one h for every
/// particle needs no attribute, but then h must be said).
pub(super) fn resolve(
    kernel: Kernel,
    radius_attribute: Option<String>,
    mass: Option<PerParticle>,
    density: Option<PerParticle>,
    names: &[String],
    smoothing_names: &[&str],
    radius_given: bool,
) -> anyhow::Result<SphInputs> {
    let listed = || {
        if names.is_empty() {
            "none".to_owned()
        } else {
            names.join(", ")
        }
    };
    let radius_attribute = match radius_attribute {
        Some(h) => Some(h),
        None => match find(names, smoothing_names) {
            Some(h) => {
                tracing::info!(
                    "{kernel}: smoothing length '{h}' (--radius-attribute sets another)"
                );
                Some(h)
            }
            None if radius_given => None,
            None => bail!(
                "the {kernel} kernel needs a smoothing length per particle, and the data has \
                 none by a known name (its attributes: {}): pass --radius-attribute NAME, \
                 --smoothing knn:32 to derive one from the 32 nearest neighbours, or --radius \
                 for one support radius for all",
                listed()
            ),
        },
    };
    // A mass or a density: as given, else the data's by one of `candidates`.
    let per_particle = |given: Option<PerParticle>,
                        candidates: &[&str],
                        what: &str,
                        flag: &str,
                        otherwise: &str|
     -> anyhow::Result<PerParticle> {
        if let Some(q) = given {
            return Ok(q);
        }
        match find(names, candidates) {
            Some(name) => {
                tracing::info!("{kernel}: {what} '{name}' ({flag} NAME or VALUE sets them)");
                Ok(PerParticle::Attribute(name))
            }
            None => bail!(
                "the {kernel} kernel weights each particle by its volume m/rho, and the data \
                 has no {what} by a known name (its attributes: {}): pass {flag} NAME, or \
                 {otherwise}",
                listed()
            ),
        }
    };
    let mass = per_particle(
        mass,
        &MASS_NAMES,
        "masses",
        "--mass",
        "--mass VALUE for equal masses",
    )?;
    let density = per_particle(
        density,
        &DENSITY_NAMES,
        "densities",
        "--density",
        "--density 1 for the SPH density estimate itself",
    )?;
    Ok(SphInputs {
        radius_attribute,
        mass,
        density,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(v: &[&str]) -> Vec<String> {
        v.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn the_codes_names_are_found() {
        let h = ["h", "smoothinglengths", "smoothinglength"];
        let swift = names(&["Coordinates", "Densities", "Masses", "SmoothingLengths"]);
        let s = resolve(Kernel::SphCubic, None, None, None, &swift, &h, false).unwrap();
        assert_eq!(s.radius_attribute.as_deref(), Some("SmoothingLengths"));
        assert_eq!(s.mass, PerParticle::Attribute("Masses".into()));
        assert_eq!(s.density, PerParticle::Attribute("Densities".into()));
        let pysph = names(&["x", "m", "rho", "h", "p"]);
        let s = resolve(Kernel::SphQuintic, None, None, None, &pysph, &h, false).unwrap();
        assert_eq!(
            (s.radius_attribute.as_deref(), &s.density),
            (Some("h"), &PerParticle::Attribute("rho".into()))
        );
        assert_eq!(s.mass, PerParticle::Attribute("m".into()));
    }

    #[test]
    fn what_is_missing_is_named_with_the_flag_that_gives_it() {
        let h = ["h"];
        let e = resolve(
            Kernel::SphCubic,
            None,
            None,
            None,
            &names(&["rho", "m"]),
            &h,
            false,
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("--smoothing knn:32") && e.contains("rho, m"),
            "{e}"
        );
        // Data with only radii: the mass is asked for first, then the density.
        let only_h = |mass: Option<PerParticle>| {
            resolve(
                Kernel::SphCubic,
                Some("h".into()),
                mass,
                None,
                &names(&["h"]),
                &h,
                false,
            )
            .unwrap_err()
            .to_string()
        };
        let e = only_h(None);
        assert!(e.contains("--mass"), "{e}");
        let e = only_h(Some(PerParticle::Constant(1.0)));
        assert!(e.contains("--density"), "{e}");
    }
}
