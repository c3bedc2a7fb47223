//! Ascii values as VTK writes them (inline ascii XML arrays, legacy ascii files): numbers
//! separated by any whitespace, any number of them a line, so a record's values are found only
//! by counting the values before them. Counting looks at each byte once (is it whitespace,
//! does a value start here), in parallel over chunks, and parses nothing: a part counts its
//! way to its first value and parses only its own values.

use rayon::prelude::*;

use crate::io::scalar::Scalar;

/// Bytes counted by one task.
const CHUNK: usize = 1 << 20;
/// Chunks counted at once while looking for a value whose place is not yet known.
const BATCH: usize = 32;

/// Whitespace as Rust's `split_ascii_whitespace` (and so vtkio) splits values.
fn space(b: u8) -> bool {
    matches!(b, b' ' | b'\t' | b'\n' | b'\x0C' | b'\r')
}

/// Whether a value may start with this byte in a legacy file (vtkio's legacy grammar: a sign,
/// a digit or a point; words such as `nan` or a section's keyword may not).
fn numeric(b: u8) -> bool {
    b.is_ascii_digit() || matches!(b, b'+' | b'-' | b'.')
}

/// Why the values asked for are not there.
#[derive(Debug, PartialEq, Eq)]
pub(super) enum Short {
    /// The text ends after `found` values.
    Ends { found: usize },
    /// A word that is not a number starts at this byte (legacy files: the next section's
    /// keyword where values were expected).
    Word { at: usize },
}

/// A value that does not parse: where it starts in the text, and the value.
#[derive(Debug)]
pub(super) struct Bad {
    pub(super) at: usize,
    pub(super) token: String,
}

/// Values starting in `text[from..to]` (a value starts where a byte that is not whitespace
/// follows whitespace or the text's start), and where the first that is not `numeric` starts.
fn count_range(text: &[u8], from: usize, to: usize, numbers_only: bool) -> (usize, Option<usize>) {
    let mut previous_space = from == 0 || space(text[from - 1]);
    let mut count = 0;
    let mut word = None;
    for (i, &b) in text[from..to].iter().enumerate() {
        let is_space = space(b);
        if previous_space && !is_space {
            count += 1;
            if numbers_only && word.is_none() && !numeric(b) {
                word = Some(from + i);
            }
        }
        previous_space = is_space;
    }
    (count, word)
}

/// How many values `text` holds.
pub(super) fn count(text: &[u8]) -> usize {
    let chunks = text.len().div_ceil(CHUNK);
    (0..chunks)
        .into_par_iter()
        .map(|c| count_range(text, c * CHUNK, ((c + 1) * CHUNK).min(text.len()), false).0)
        .sum()
}

/// Where the `k`-th value (from 0) of `text[from..to]` starts, which the caller knows lies
/// there; a word before it or it (with `numbers_only`) is refused.
fn nth_in(
    text: &[u8],
    from: usize,
    to: usize,
    k: usize,
    numbers_only: bool,
) -> Result<usize, Short> {
    let mut previous_space = from == 0 || space(text[from - 1]);
    let mut seen = 0;
    for (i, &b) in text[from..to].iter().enumerate() {
        let is_space = space(b);
        if previous_space && !is_space {
            if numbers_only && !numeric(b) {
                return Err(Short::Word { at: from + i });
            }
            if seen == k {
                return Ok(from + i);
            }
            seen += 1;
        }
        previous_space = is_space;
    }
    unreachable!("the chunk's count said value {k} starts in it")
}

/// Where the `k` values at the start of `text` end (just after the last one's last byte; 0
/// for none): the values are counted, not parsed. With `numbers_only`, a value that does not
/// start as a number (legacy files: the next section's keyword) is refused.
pub(super) fn skip(text: &[u8], k: usize, numbers_only: bool) -> Result<usize, Short> {
    if k == 0 {
        return Ok(0);
    }
    let target = k - 1;
    let chunks = text.len().div_ceil(CHUNK);
    let mut seen = 0;
    let mut first = 0;
    while first < chunks {
        let last = (first + BATCH).min(chunks);
        let counts: Vec<(usize, Option<usize>)> = (first..last)
            .into_par_iter()
            .map(|c| {
                count_range(
                    text,
                    c * CHUNK,
                    ((c + 1) * CHUNK).min(text.len()),
                    numbers_only,
                )
            })
            .collect();
        for (c, (n, word)) in (first..last).zip(counts) {
            if seen + n > target {
                let (from, to) = (c * CHUNK, ((c + 1) * CHUNK).min(text.len()));
                let start = nth_in(text, from, to, target - seen, numbers_only)?;
                let length = text[start..].iter().position(|&b| space(b));
                return Ok(start + length.unwrap_or(text.len() - start));
            }
            if let Some(at) = word {
                return Err(Short::Word { at });
            }
            seen += n;
        }
        first = last;
    }
    Err(Short::Ends { found: seen })
}

/// A value of `scalar` written as text, as vtkio parses it (Rust's parser of that type).
fn parse_value(token: &str, scalar: Scalar) -> Option<f64> {
    Some(match scalar {
        Scalar::I8 => token.parse::<i8>().ok()?.into(),
        Scalar::U8 => token.parse::<u8>().ok()?.into(),
        Scalar::I16 => token.parse::<i16>().ok()?.into(),
        Scalar::U16 => token.parse::<u16>().ok()?.into(),
        Scalar::I32 => token.parse::<i32>().ok()?.into(),
        Scalar::U32 => token.parse::<u32>().ok()?.into(),
        Scalar::I64 => token.parse::<i64>().ok()? as f64,
        Scalar::U64 => token.parse::<u64>().ok()? as f64,
        Scalar::F32 => token.parse::<f32>().ok()?.into(),
        Scalar::F64 => token.parse::<f64>().ok()?,
    })
}

/// The first `n` values of `text` (which holds at least `n`, after [`skip`]) parsed as
/// `scalar`, in parallel over pieces cut at whitespace. With `numbers_only`, a value must
/// start as a number (legacy files: vtkio's grammar has no `nan` or `inf`).
pub(super) fn parse(
    text: &[u8],
    n: usize,
    scalar: Scalar,
    numbers_only: bool,
) -> Result<Vec<f64>, Bad> {
    let end = skip(text, n, false).map_err(|_| Bad {
        at: text.len(),
        token: "(the end of the values)".into(),
    })?;
    let body = &text[..end];
    // Pieces of about CHUNK bytes, each cut just after a whitespace byte.
    let mut cuts = vec![0];
    let mut at = CHUNK;
    while at < body.len() {
        match body[at..].iter().position(|&b| space(b)) {
            Some(p) => {
                cuts.push(at + p);
                at += p + CHUNK;
            }
            None => break,
        }
    }
    cuts.push(body.len());
    let pieces: Vec<Vec<f64>> = cuts
        .par_windows(2)
        .map(|w| {
            let piece = &body[w[0]..w[1]];
            let mut values = Vec::with_capacity(piece.len() / 8);
            let mut i = 0;
            while i < piece.len() {
                if space(piece[i]) {
                    i += 1;
                    continue;
                }
                let start = i;
                while i < piece.len() && !space(piece[i]) {
                    i += 1;
                }
                let token = &piece[start..i];
                let value = std::str::from_utf8(token)
                    .ok()
                    .filter(|_| !numbers_only || numeric(token[0]))
                    .and_then(|t| parse_value(t, scalar));
                match value {
                    Some(v) => values.push(v),
                    None => {
                        return Err(Bad {
                            at: w[0] + start,
                            token: String::from_utf8_lossy(&token[..token.len().min(40)])
                                .into_owned(),
                        });
                    }
                }
            }
            Ok(values)
        })
        .collect::<Result<_, _>>()?;
    Ok(pieces.concat())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_are_counted_across_any_layout() {
        let text = b"  1 2\n3\r\n\t4   5 ";
        assert_eq!(count(text), 5);
        assert_eq!(skip(text, 0, true), Ok(0));
        assert_eq!(skip(text, 1, true), Ok(3));
        assert_eq!(skip(text, 3, true), Ok(7));
        assert_eq!(skip(text, 5, true), Ok(15));
        assert_eq!(skip(text, 6, true), Err(Short::Ends { found: 5 }));
        let legacy = b"1 2 3\nPOINT_DATA 3\n";
        assert_eq!(skip(legacy, 3, true), Ok(5));
        assert_eq!(skip(legacy, 4, true), Err(Short::Word { at: 6 }));
        assert_eq!(skip(legacy, 4, false), Ok(16));
        let parsed = parse(b" 1.5\n-2 3e2 7", 3, Scalar::F64, true).unwrap();
        assert_eq!(parsed, [1.5, -2.0, 300.0]);
        let bad = parse(b"1 2.5.1 3", 3, Scalar::F32, true).unwrap_err();
        assert_eq!((bad.at, bad.token.as_str()), (2, "2.5.1"));
        assert!(parse(b"1 nan", 2, Scalar::F64, true).is_err());
        assert!(parse(b"1 NaN", 2, Scalar::F64, false).unwrap()[1].is_nan());
        assert!(parse(b"1 2.5", 2, Scalar::I32, false).is_err());
    }

    #[test]
    fn values_are_found_across_chunks() {
        // Values straddling chunk boundaries, and runs of whitespace across them.
        let mut text = Vec::new();
        let mut k = 0u64;
        while text.len() < 3 * CHUNK + 100 {
            text.extend(format!("{k}").into_bytes());
            text.extend(std::iter::repeat_n(b' ', (k % 7) as usize + 1));
            if k.is_multiple_of(13) {
                text.extend(b"\r\n");
            }
            k += 1;
        }
        assert_eq!(count(&text), k as usize);
        for j in [1, 2, 1000, k as usize / 2, k as usize - 1, k as usize] {
            let end = skip(&text, j, true).unwrap();
            let values = parse(&text[end..], k as usize - j, Scalar::I64, true).unwrap();
            assert_eq!(
                values.first().copied(),
                (j < k as usize).then_some(j as f64)
            );
            assert_eq!(values.len(), k as usize - j);
        }
        let all = parse(&text, k as usize, Scalar::F64, true).unwrap();
        assert!(all.iter().enumerate().all(|(i, &v)| v == i as f64));
    }
}
