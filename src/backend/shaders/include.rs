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

/// The storage-buffer layout a kernel is compiled for: `SPLIT_PARTS` = 1 binds each splittable
/// array as one buffer (the usual case, and within WebGPU's default of 8 storage buffers per
/// stage); 4 binds each in 4 parts, for steps or images that outgrow one binding.
pub const SPLIT_PARTS_VARIANTS: [u32; 2] = [1, 4];

/// WGSL `source` (includes resolved) for `SPLIT_PARTS` = `parts`: keeps the lines between
/// `#if SPLIT_PARTS > 1` and `#else` (or `#endif`) when `parts > 1`, those between `#else` and
/// `#endif` otherwise. WGSL has no preprocessor; this is the one conditional the shared GLSL
/// gets from its own (naga's GLSL front end, with `SPLIT_PARTS` defined), written the same way
/// in both languages. Blocks do not nest.
pub fn select_split_parts(source: &str, parts: u32) -> Result<String, String> {
    #[derive(PartialEq)]
    enum State {
        Outside,
        Then,
        Else,
    }
    let mut state = State::Outside;
    let mut out = String::with_capacity(source.len());
    for (number, line) in source.lines().enumerate() {
        let directive = line.trim();
        let keep = match (directive, &state) {
            ("#if SPLIT_PARTS > 1", State::Outside) => {
                state = State::Then;
                false
            }
            ("#else", State::Then) => {
                state = State::Else;
                false
            }
            ("#endif", State::Then | State::Else) => {
                state = State::Outside;
                false
            }
            (d, _) if d.starts_with("#if") || d.starts_with("#else") || d.starts_with("#endif") => {
                return Err(format!(
                    "line {}: '{d}' is not supported here (only non-nested \
                     '#if SPLIT_PARTS > 1' / '#else' / '#endif')",
                    number + 1
                ));
            }
            _ => match state {
                State::Outside => true,
                State::Then => parts > 1,
                State::Else => parts <= 1,
            },
        };
        // Dropped lines become empty ones, so naga's line numbers match the resolved source.
        if keep {
            out.push_str(line);
        }
        out.push('\n');
    }
    if state != State::Outside {
        return Err("'#if SPLIT_PARTS > 1' without '#endif'".into());
    }
    Ok(out)
}
