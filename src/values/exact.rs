//! Sums and order statistics that do not depend on how the values are split or ordered: the
//! series' statistics are the same, bit for bit, whether one process reads a step whole, a
//! background scan reads the steps in any order, or P ranks each read a part of it.
//!
//! A sum is the exactly rounded sum of its terms ([`ExactSum`]): every double is an integer
//! times a power of two, so adding integers, each into the bucket of its power, is exact and
//! the same in any order; buckets of parts add the same way, and the total is rounded once.
//! (Two crates were tried first and rejected: `accurate`'s OnlineExactSum indexes past its
//! slice when every term leaves a rounding error, and `xsum` 0.1.6 sums three -1.0 to
//! -3.0000000000000004.) An order statistic is a value's rank in [`order_key`]'s order, the
//! order of `f64::total_cmp`.

use num_bigint::{BigInt, Sign};

/// Buckets: a finite double is `m 2^(j - 1074)` with `|m| < 2^53` and `j` its biased exponent
/// less one (0 for subnormals), 0..=2045.
const BUCKETS: usize = 2046;

/// An exact sum of doubles: each finite term's significand added into the i128 bucket of its
/// exponent (room for 2^74 terms a bucket), rounded to nearest, ties to even, by
/// [`ExactSum::value`]. Non-finite terms are summed apart and win (as in any sum).
#[derive(Clone, Debug)]
pub struct ExactSum {
    buckets: Vec<i128>,
    non_finite: Option<f64>,
}

impl Default for ExactSum {
    fn default() -> Self {
        ExactSum {
            buckets: vec![0; BUCKETS],
            non_finite: None,
        }
    }
}

impl ExactSum {
    /// The sum of `values`.
    pub fn of(values: &[f64]) -> ExactSum {
        let mut s = ExactSum::default();
        for &v in values {
            s.add(v);
        }
        s
    }

    /// Adds `v`.
    pub fn add(&mut self, v: f64) {
        if !v.is_finite() {
            self.non_finite = Some(self.non_finite.map_or(v, |s| s + v));
            return;
        }
        let bits = v.to_bits();
        let biased = ((bits >> 52) & 0x7ff) as usize;
        let fraction = (bits & ((1 << 52) - 1)) as i128;
        let (bucket, m) = if biased == 0 {
            (0, fraction)
        } else {
            (biased - 1, fraction | 1 << 52)
        };
        self.buckets[bucket] += if bits >> 63 == 1 { -m } else { m };
    }

    /// Adds another sum's terms.
    pub fn merge(&mut self, other: &ExactSum) {
        for (a, b) in self.buckets.iter_mut().zip(&other.buckets) {
            *a += b;
        }
        if let Some(v) = other.non_finite {
            self.non_finite = Some(self.non_finite.map_or(v, |s| s + v));
        }
    }

    /// The sum as words to send: each non-zero bucket as its index and the i128's two halves,
    /// then the non-finite terms' sum if any.
    pub fn to_words(&self) -> Vec<u64> {
        let mut words = Vec::new();
        for (j, &b) in self.buckets.iter().enumerate() {
            if b != 0 {
                words.extend([j as u64, b as u64, ((b as u128) >> 64) as u64]);
            }
        }
        if let Some(v) = self.non_finite {
            words.extend([u64::MAX, v.to_bits()]);
        }
        words
    }

    /// The sum [`ExactSum::to_words`] wrote (`None` for words it cannot have written).
    pub fn from_words(words: &[u64]) -> Option<ExactSum> {
        let mut s = ExactSum::default();
        let mut rest = words;
        while let Some(&j) = rest.first() {
            if j == u64::MAX {
                s.non_finite = Some(f64::from_bits(*rest.get(1)?));
                rest = &rest[2..];
                continue;
            }
            let (lo, hi) = (*rest.get(1)?, *rest.get(2)?);
            *s.buckets.get_mut(j as usize)? += ((u128::from(hi) << 64) | u128::from(lo)) as i128;
            rest = &rest[3..];
        }
        Some(s)
    }

    /// The sum rounded to the nearest double, ties to even (+0.0 for a zero sum, whatever the
    /// zeros' signs: how the terms were split must not show).
    pub fn value(&self) -> f64 {
        if let Some(v) = self.non_finite {
            return v;
        }
        // The exact sum times 2^1074, an integer.
        let mut total = BigInt::from(0);
        for (j, &b) in self.buckets.iter().enumerate().rev() {
            if b != 0 {
                total += BigInt::from(b) << j;
            }
        }
        let (sign, magnitude) = total.into_parts();
        let bits = magnitude.bits();
        let value = if bits <= 53 {
            // Exact: every multiple of 2^-1074 below 2^-1021 is a double.
            let m = magnitude.iter_u64_digits().next().unwrap_or(0);
            m as f64 * f64::from_bits(1)
        } else {
            let shift = bits - 53;
            let mut q = (&magnitude >> shift).iter_u64_digits().next().unwrap_or(0);
            let rest = &magnitude - (num_bigint::BigUint::from(q) << shift);
            let half = num_bigint::BigUint::from(1u8) << (shift - 1);
            if rest > half || (rest == half && q & 1 == 1) {
                q += 1;
            }
            // q 2^(shift - 1074) is normal (q >= 2^52, shift >= 1), or overflows: scaled in
            // one exact step, or two where 2^k alone would be subnormal.
            let k = shift as i64 - 1074;
            if k > 1023 {
                f64::INFINITY
            } else if k >= -1022 {
                q as f64 * power_of_two(k)
            } else {
                q as f64 * power_of_two(k + 64) * power_of_two(-64)
            }
        };
        match sign {
            Sign::Minus => -value,
            _ => value,
        }
    }
}

/// 2^k for `k` in -1022..=1023.
fn power_of_two(k: i64) -> f64 {
    f64::from_bits(((k + 1023) as u64) << 52)
}

/// The exactly rounded sum of `values`, whatever their order ([`ExactSum`]).
pub fn exact_sum(values: &[f64]) -> f64 {
    ExactSum::of(values).value()
}

/// `v`'s key in `f64::total_cmp`'s order: `order_key(a) < order_key(b)` exactly where
/// `a.total_cmp(&b)` is `Less` (-0.0 before +0.0).
pub fn order_key(v: f64) -> u64 {
    let bits = v.to_bits();
    if bits >> 63 == 1 {
        !bits
    } else {
        bits | 1 << 63
    }
}

/// The value whose key [`order_key`] gives.
pub fn from_order_key(key: u64) -> f64 {
    f64::from_bits(if key >> 63 == 1 {
        key & !(1 << 63)
    } else {
        !key
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn awkward() -> Vec<f64> {
        vec![
            1e16,
            1.0,
            -1e16,
            0.1,
            0.2,
            -0.0,
            0.0,
            5e-324,
            -3.7e-310,
            1e300,
            -1e300,
            123.456_789_012_345_68,
            -2.5,
            f64::MIN_POSITIVE,
            -1.0,
            -1.0,
            -1.0,
        ]
    }

    /// The exact sum of values on a common grid, as an integer multiple of 2^-60 (i128), and
    /// its nearest double: an independent reference.
    fn on_a_grid(values: &[f64]) -> f64 {
        let scale = 2f64.powi(60);
        let total: i128 = values
            .iter()
            .map(|&v| {
                let scaled = v * scale;
                assert_eq!(scaled.fract(), 0.0, "{v} is not on the grid");
                scaled as i128
            })
            .sum();
        // i128 to f64 rounds to nearest, ties to even; the scale is a power of two.
        total as f64 / scale
    }

    #[test]
    fn the_exact_sum_is_the_rounded_sum_of_exact_values() {
        assert_eq!(exact_sum(&[1e16, 1.0, -1e16]), 1.0);
        assert_eq!(exact_sum(&[-1.0, -1.0, -1.0]), -3.0);
        // The doubles nearest 0.1, 0.2 and 0.3 differ by 2^-55 exactly (naively 2^-54).
        assert_eq!(exact_sum(&[0.1, 0.2, -0.3]), 2f64.powi(-55));
        assert_eq!(exact_sum(&[5e-324, 5e-324, 5e-324]), 1.5e-323);
        assert_eq!(exact_sum(&[f64::MAX, f64::MAX]), f64::INFINITY);
        assert_eq!(exact_sum(&[f64::MAX, f64::MAX, -f64::MAX]), f64::MAX);
        assert_eq!(exact_sum(&[f64::MAX, -1e300, 1e300]), f64::MAX);
        assert_eq!(
            exact_sum(&[-f64::MIN_POSITIVE, 5e-324]),
            -f64::MIN_POSITIVE + 5e-324
        );
        // Ties to even: 2^53 + 1 is halfway between 2^53 and 2^53 + 2.
        assert_eq!(exact_sum(&[2f64.powi(53), 1.0]), 2f64.powi(53));
        assert_eq!(exact_sum(&[2f64.powi(53), 1.0, 2.0]), 2f64.powi(53) + 4.0);
        // Against an independent integer sum, on values that need many roundings naively.
        let mut state = 0x1234_5678_9abc_def1u64;
        for n in [3usize, 10, 1000, 4097] {
            let values: Vec<f64> = (0..n)
                .map(|_| {
                    state ^= state << 13;
                    state ^= state >> 7;
                    state ^= state << 17;
                    let int = (state >> 20) as i64 - (1 << 43);
                    int as f64 * 2f64.powi(-((state % 17) as i32) - 3)
                })
                .collect();
            assert_eq!(
                exact_sum(&values).to_bits(),
                on_a_grid(&values).to_bits(),
                "n = {n}"
            );
        }
    }

    #[test]
    fn every_split_and_order_gives_the_same_bits() {
        let values = awkward();
        let whole = exact_sum(&values);
        let mut reversed = values.clone();
        reversed.reverse();
        assert_eq!(exact_sum(&reversed).to_bits(), whole.to_bits());
        for split in 0..=values.len() {
            let (a, b) = values.split_at(split);
            let mut sent = ExactSum::from_words(&ExactSum::of(b).to_words()).unwrap();
            sent.merge(&ExactSum::of(a));
            assert_eq!(sent.value().to_bits(), whole.to_bits(), "split at {split}");
        }
        // Zero sums are +0.0 however the zeros were split.
        assert_eq!(exact_sum(&[-0.0, -0.0]).to_bits(), 0.0f64.to_bits());
        assert_eq!(exact_sum(&[]).to_bits(), 0.0f64.to_bits());
        assert!(ExactSum::from_words(&[5, 1]).is_none());
        assert!(ExactSum::from_words(&[5000, 1, 0]).is_none());
    }

    #[test]
    fn order_keys_sort_as_total_cmp() {
        let mut values = awkward();
        values.extend([f64::INFINITY, f64::NEG_INFINITY, -1.0, 1.0, -5e-324]);
        for &a in &values {
            assert_eq!(from_order_key(order_key(a)).to_bits(), a.to_bits());
            for &b in &values {
                assert_eq!(order_key(a).cmp(&order_key(b)), a.total_cmp(&b), "{a} {b}");
            }
        }
    }
}
