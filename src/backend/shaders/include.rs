// Resolves `#include "name"` and `#split_array` lines in GLSL and WGSL: shared by build.rs
// (which `include!`s this file) and the library, so the source the build validates is the
// source the backends run. naga's GLSL front end has no #include (and WGSL none at all);
// glslc's would work, but one resolver for both keeps the two backends' sources identical.

/// The shading language a source is in (what `#split_array` writes).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ShaderLanguage {
    /// GLSL 4.60 (compiled by naga for wgpu, by glslc for ash).
    Glsl,
    /// WGSL (wgpu only: the stages that need its atomics).
    Wgsl,
}

/// Replaces every line `#include "name"` with the text `lookup(name)` returns (itself
/// resolved), each file at most once (later includes of the same file are dropped), and every
/// `#split_array` line with the declarations and accessors [`split_array`] writes.
pub fn resolve_includes(
    source: &str,
    lookup: &dyn Fn(&str) -> Option<String>,
    language: ShaderLanguage,
) -> Result<String, String> {
    fn go(
        source: &str,
        lookup: &dyn Fn(&str) -> Option<String>,
        language: ShaderLanguage,
        seen: &mut Vec<String>,
        out: &mut String,
        depth: usize,
    ) -> Result<(), String> {
        if depth > 16 {
            return Err("includes nest deeper than 16 levels".into());
        }
        for line in source.lines() {
            let trimmed = line.trim();
            if let Some(rest) = trimmed.strip_prefix("#split_array") {
                out.push_str(&split_array(rest, language)?);
            } else if let Some(rest) = trimmed.strip_prefix("#include") {
                let name = rest.trim().trim_matches('"');
                if seen.iter().any(|s| s == name) {
                    continue;
                }
                seen.push(name.to_owned());
                let text = lookup(name).ok_or_else(|| format!("#include \"{name}\": no such shader file"))?;
                out.push_str(&format!("// ---- begin {name}\n"));
                go(&text, lookup, language, seen, out, depth + 1)?;
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
    go(source, lookup, language, &mut Vec::new(), &mut out, 0)?;
    Ok(out)
}

/// Parts an array that outgrows one storage binding is split over (the 4-part layout).
pub const SPLIT_PARTS_MAX: u32 = 4;

/// Expands `#split_array NAME BINDING TYPE ACCESS LENGTH OP:FUNCTION...`: an array of `TYPE`
/// in up to [`SPLIT_PARTS_MAX`] storage buffers `NAME0..NAME3` at bindings `BINDING..` (the
/// parts past the first only where `SPLIT_PARTS > 1`), and one accessor function per op that
/// finds element `i`'s part from the part length `LENGTH` (an expression, elements per part;
/// 0xffffffff when one part holds the whole array, so every access takes the first branch).
///
/// - `ACCESS`: GLSL `readonly` / `writeonly` / `readwrite`; WGSL `read` / `read_write`.
/// - ops: `get` (`T FUNCTION(uint i)`), `set` (`void FUNCTION(uint i, T value)`), `add`
///   (GLSL: `+=`), and in WGSL over `atomic<u32>` `store` and `exchange` (atomicStore and
///   atomicExchange, with u32 values).
///
/// Every wgpu kernel's splittable arrays are declared this way, so the part selection is
/// written once, here, for both languages.
pub fn split_array(spec: &str, language: ShaderLanguage) -> Result<String, String> {
    let words: Vec<&str> = spec.split_whitespace().collect();
    let [name, binding, ty, access, length, ops @ ..] = &words[..] else {
        return Err(format!(
            "#split_array{spec}: expected NAME BINDING TYPE ACCESS LENGTH OP:FUNCTION..."
        ));
    };
    if ops.is_empty() {
        return Err(format!("#split_array {name}: no accessor (OP:FUNCTION) given"));
    }
    let binding: u32 = binding
        .parse()
        .map_err(|_| format!("#split_array {name}: binding '{binding}' is not a number"))?;
    let mut out = split_declarations(name, binding, ty, access, language);
    for op in ops.iter() {
        out.push_str(&split_accessor(name, ty, length, op, language)?);
    }
    Ok(out)
}

/// The storage buffers of a `#split_array`: part 0, and where `SPLIT_PARTS > 1` the others.
fn split_declarations(
    name: &str,
    binding: u32,
    ty: &str,
    access: &str,
    language: ShaderLanguage,
) -> String {
    let part = |k: u32| format!("{name}{k}");
    let declare = |k: u32| match language {
        ShaderLanguage::Glsl => {
            let block: String = name
                .split('_')
                .map(|w| {
                    let mut c = w.chars();
                    c.next()
                        .map(|f| f.to_ascii_uppercase().to_string() + c.as_str())
                        .unwrap_or_default()
                })
                .collect();
            let qualifier = match access {
                "readwrite" => String::new(),
                a => format!("{a} "),
            };
            format!(
                "layout(std430, set = 0, binding = {}) {qualifier}buffer {block}{k} {{ {ty} {}[]; }};\n",
                binding + k,
                part(k)
            )
        }
        ShaderLanguage::Wgsl => format!(
            "@group(0) @binding({}) var<storage, {access}> {}: array<{ty}>;\n",
            binding + k,
            part(k)
        ),
    };
    let mut out = declare(0);
    out.push_str("#if SPLIT_PARTS > 1\n");
    for k in 1..SPLIT_PARTS_MAX {
        out.push_str(&declare(k));
    }
    out.push_str("#endif\n");
    out
}

/// One accessor of a `#split_array` (`op` is `OP:FUNCTION`): the part holding element `i`
/// found from the part length `length`, and the op done on it.
fn split_accessor(
    name: &str,
    ty: &str,
    length: &str,
    op: &str,
    language: ShaderLanguage,
) -> Result<String, String> {
    let part = |k: u32| format!("{name}{k}");
    let (op, function) = op
        .split_once(':')
        .ok_or_else(|| format!("#split_array {name}: '{op}' is not OP:FUNCTION"))?;
    let value_ty = match (language, ty) {
        (ShaderLanguage::Wgsl, "atomic<u32>") => "u32",
        _ => ty,
    };
    // The signature, and the statement that does the op on element `i` of array `a`.
    let (signature, statement): (String, fn(&str) -> String) = match (language, op) {
        (ShaderLanguage::Glsl, "get") => (format!("{ty} {function}(uint i)"), |a| {
            format!("return {a}[i];")
        }),
        (ShaderLanguage::Glsl, "set") => (
            format!("void {function}(uint i, {ty} value)"),
            |a| format!("{a}[i] = value;"),
        ),
        (ShaderLanguage::Glsl, "add") => (
            format!("void {function}(uint i, {ty} value)"),
            |a| format!("{a}[i] += value;"),
        ),
        (ShaderLanguage::Wgsl, "get") => (format!("fn {function}(index: u32) -> {ty}"), |a| {
            format!("return {a}[i];")
        }),
        (ShaderLanguage::Wgsl, "set") => (
            format!("fn {function}(index: u32, value: {value_ty})"),
            |a| format!("{a}[i] = value;"),
        ),
        (ShaderLanguage::Wgsl, "store") => (
            format!("fn {function}(index: u32, value: {value_ty})"),
            |a| format!("atomicStore(&{a}[i], value);"),
        ),
        (ShaderLanguage::Wgsl, "exchange") => (
            format!("fn {function}(index: u32, value: {value_ty}) -> u32"),
            |a| format!("return atomicExchange(&{a}[i], value);"),
        ),
        (l, other) => {
            return Err(format!(
                "#split_array {name}: no op '{other}' in {l:?} (get, set, add; WGSL also store, exchange)"
            ));
        }
    };
    let returns = statement("a").starts_with("return");
    let open_index = match language {
        ShaderLanguage::Glsl => "",
        ShaderLanguage::Wgsl => "    var i = index;\n",
    };
    let (if_open, if_close) = match language {
        ShaderLanguage::Glsl => ("if (i < len) {", "}"),
        ShaderLanguage::Wgsl => ("if i < len {", "}"),
    };
    let len_decl = match language {
        ShaderLanguage::Glsl => format!("    uint len = {length};\n"),
        ShaderLanguage::Wgsl => format!("    let len = {length};\n"),
    };
    let mut out = format!("{signature} {{\n#if SPLIT_PARTS > 1\n{len_decl}{open_index}");
    for k in 0..SPLIT_PARTS_MAX - 1 {
        out.push_str(&format!("    {if_open}\n        {}\n", statement(&part(k))));
        if !returns {
            out.push_str("        return;\n");
        }
        out.push_str(&format!("    {if_close}\n    i -= len;\n"));
    }
    out.push_str(&format!(
        "    {}\n#else\n",
        statement(&part(SPLIT_PARTS_MAX - 1))
    ));
    if language == ShaderLanguage::Wgsl {
        out.push_str("    let i = index;\n");
    }
    out.push_str(&format!("    {}\n#endif\n}}\n", statement(&part(0))));
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
