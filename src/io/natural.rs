//! Natural ordering of file names: digit runs compare as numbers, so `step2` < `step10`.

use std::cmp::Ordering;

/// Compares names in natural order: runs of digits compare as numbers (`step2` < `step10`),
/// everything else byte by byte.
pub fn compare(a: &str, b: &str) -> Ordering {
    let (mut a, mut b) = (a.as_bytes(), b.as_bytes());
    loop {
        match (a.first(), b.first()) {
            (None, None) => return Ordering::Equal,
            (None, Some(_)) => return Ordering::Less,
            (Some(_), None) => return Ordering::Greater,
            (Some(x), Some(y)) if x.is_ascii_digit() && y.is_ascii_digit() => {
                let da = a.iter().take_while(|c| c.is_ascii_digit()).count();
                let db = b.iter().take_while(|c| c.is_ascii_digit()).count();
                let (na, nb) = (trim_zeros(&a[..da]), trim_zeros(&b[..db]));
                // Longer digit runs (without leading zeros) are larger numbers; equal lengths
                // compare digit by digit, and ties fall back to the run with fewer leading zeros.
                let ord = na
                    .len()
                    .cmp(&nb.len())
                    .then_with(|| na.cmp(nb))
                    .then_with(|| da.cmp(&db));
                if ord != Ordering::Equal {
                    return ord;
                }
                a = &a[da..];
                b = &b[db..];
            }
            (Some(x), Some(y)) => {
                if x != y {
                    return x.cmp(y);
                }
                a = &a[1..];
                b = &b[1..];
            }
        }
    }
}

fn trim_zeros(digits: &[u8]) -> &[u8] {
    let z = digits.iter().take_while(|&&c| c == b'0').count();
    &digits[z..]
}

#[cfg(test)]
mod tests {
    use super::compare;

    #[test]
    fn numbers_sort_by_value() {
        let mut names = vec![
            "step10.vtp",
            "step2.vtp",
            "step1.vtp",
            "step002.vtp",
            "a.vtp",
        ];
        names.sort_by(|a, b| compare(a, b));
        assert_eq!(
            names,
            [
                "a.vtp",
                "step1.vtp",
                "step2.vtp",
                "step002.vtp",
                "step10.vtp"
            ]
        );
        let mut huge = vec![
            "t99999999999999999999999",
            "t100000000000000000000000",
            "t3",
        ];
        huge.sort_by(|a, b| compare(a, b));
        assert_eq!(
            huge,
            [
                "t3",
                "t99999999999999999999999",
                "t100000000000000000000000"
            ]
        );
    }
}
