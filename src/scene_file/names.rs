//! An attribute asked for by a name the data spells another way: the singular or plural, or
//! another case, of one of its names (SWIFT writes `Temperatures`, `SmoothingLengths`,
//! `Densities` where GADGET writes `Temperature`, `SmoothingLength`, `Density`; the issue's own
//! example asks for `Temperature` of a SWIFT run).

/// The one name in `names` that is `wanted` in the other number or another case, if exactly
/// one is (two would leave the choice to the user, whom the error then shows both).
pub fn other_spelling(wanted: &str, names: &[String]) -> Option<String> {
    let stem = singular(&wanted.to_ascii_lowercase());
    let mut matches = names
        .iter()
        .filter(|n| n.as_str() != wanted && singular(&n.to_ascii_lowercase()) == stem);
    let found = matches.next()?;
    matches.next().is_none().then(|| found.clone())
}

/// English singular of a lower-case word, as attribute names are plural: `densities` ->
/// `density`, `masses` -> `mass`, `temperatures` -> `temperature`; others unchanged.
fn singular(word: &str) -> String {
    if let Some(stem) = word.strip_suffix("ies") {
        format!("{stem}y")
    } else if let Some(stem) = ["sses", "xes", "ches", "shes"]
        .iter()
        .find_map(|s| word.strip_suffix(s).map(|stem| (stem, &s[..s.len() - 2])))
        .map(|(stem, end)| format!("{stem}{end}"))
    {
        stem
    } else if let Some(stem) = word.strip_suffix('s')
        && !word.ends_with("ss")
    {
        stem.to_owned()
    } else {
        word.to_owned()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(list: &[&str]) -> Vec<String> {
        list.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn singular_and_plural_find_each_other() {
        let swift = names(&["Densities", "Masses", "SmoothingLengths", "Temperatures"]);
        assert_eq!(
            other_spelling("Temperature", &swift).as_deref(),
            Some("Temperatures")
        );
        assert_eq!(
            other_spelling("Density", &swift).as_deref(),
            Some("Densities")
        );
        assert_eq!(other_spelling("Mass", &swift).as_deref(), Some("Masses"));
        assert_eq!(
            other_spelling("smoothinglength", &swift).as_deref(),
            Some("SmoothingLengths")
        );
        let gadget = names(&["Density", "Masses", "SmoothingLength", "Temperature"]);
        assert_eq!(
            other_spelling("Temperatures", &gadget).as_deref(),
            Some("Temperature")
        );
        assert_eq!(
            other_spelling("Densities", &gadget).as_deref(),
            Some("Density")
        );
        assert_eq!(
            other_spelling("SmoothingLengths", &gadget).as_deref(),
            Some("SmoothingLength")
        );
        // Nothing close, or two close: no guess.
        assert_eq!(other_spelling("Pressure", &swift), None);
        assert_eq!(
            other_spelling("Density", &names(&["density", "Densities"])),
            None
        );
        // "Mass" is no plural of "Ma".
        assert_eq!(other_spelling("Ma", &swift), None);
    }
}
