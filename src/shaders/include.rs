// Resolves `#include "name"` lines in GLSL: shared by build.rs (which `include!`s this file)
// and the library, so the source the build validates is the source the backends run.
// naga's GLSL front end has no #include; glslc's would work, but one resolver for both keeps
// the two backends' sources identical.

/// Replaces every line `#include "name"` with the text `lookup(name)` returns (itself
/// resolved), each file at most once (later includes of the same file are dropped).
pub fn resolve_includes(
    source: &str,
    lookup: &dyn Fn(&str) -> Option<String>,
) -> Result<String, String> {
    fn go(
        source: &str,
        lookup: &dyn Fn(&str) -> Option<String>,
        seen: &mut Vec<String>,
        out: &mut String,
        depth: usize,
    ) -> Result<(), String> {
        if depth > 16 {
            return Err("includes nest deeper than 16 levels".into());
        }
        for line in source.lines() {
            let trimmed = line.trim();
            if let Some(rest) = trimmed.strip_prefix("#include") {
                let name = rest.trim().trim_matches('"');
                if seen.iter().any(|s| s == name) {
                    continue;
                }
                seen.push(name.to_owned());
                let text = lookup(name).ok_or_else(|| format!("#include \"{name}\": no such shader file"))?;
                out.push_str(&format!("// ---- begin {name}\n"));
                go(&text, lookup, seen, out, depth + 1)?;
                out.push_str(&format!("// ---- end {name}\n"));
            } else if trimmed.starts_with("#extension GL_GOOGLE_include_directive") {
                // Only glslc needs it, and the includes are resolved already.
            } else {
                out.push_str(line);
                out.push('\n');
            }
        }
        Ok(())
    }
    let mut out = String::new();
    go(source, lookup, &mut Vec::new(), &mut out, 0)?;
    Ok(out)
}
