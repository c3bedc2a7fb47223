//! How precisely a backend computes the field, and what that costs in error: one model of every
//! source of error of f32 arithmetic, and one rule (`auto`) that picks, per scene, the cheapest
//! representation whose *whole* bound meets the tolerance asked for.
//!
//! # The model
//! Every term `w exp(-4.5 d²/r²)` of Phi is positive, so a relative error of each term (ε_term)
//! and of their sum (ε_sum) bound the relative error of Phi by `ε_term + ε_sum` (to first
//! order; the product is added too). u is f32's unit roundoff, 2^-24.
//! - **positions**: rounding local coordinates to f32 moves a distance by up to δ (see
//!   [`position_error`]); the term then changes by up to `9 δ / r_min`. Double-single positions
//!   make δ 2^-24 times smaller.
//! - **kernel**: the exponent `a = 4.5 d²/r²` (at most 4.5 within the radius) carries the
//!   rounding of the offsets, of d², of the radius and of the division or of the host's f32
//!   `k = 4.5/r²`; an absolute error `a η` of it is a relative error `a η` of the term. The
//!   exponential itself adds its own relative error: the CPU's polynomial as measured for the
//!   build in use (`field::f32_kernel::exp_error_in_use`), GLSL's `exp` as the Vulkan
//!   specification bounds it for every driver (3 + 2|x| ulp).
//! - **terms**: the weight in f32 (a table lookup on the GPU, whose attribute t is f32 too: the
//!   map's steepest relative slope times t's rounding) and the product.
//! - **summation**: adding n positive terms one after another in f32 errs by at most
//!   (n - 1) u / (1 - (n - 1) u) of the sum, whatever their order (Higham, *Accuracy and
//!   Stability of Numerical Algorithms*, §4.2). n is bounded by how many particles can reach
//!   one point ([`crate::accel::max_reach_count`]): a bound, not the mean overlap. The CPU's f32
//!   kernel adds at most eight terms a lane in f32 and those blocks in f64, so n barely
//!   matters there; the GPUs add a cluster's terms in f32 and, where n asks for it, the
//!   clusters' sums compensated (Neumaier: 2u plus a term in n u²).
//! - **Theta** is a ratio of two such sums of positive terms (the numerator's terms carry t or
//!   its colour, in [0, 1], rounded once more): its error over the attribute's range is at most
//!   the two relative errors added, plus the division's and t's roundings. Phi's size does not
//!   enter, as long as no term underflows f32's normal range: a scene whose smallest term could
//!   is not given f32 at all ([`SceneNumbers::f32_range_ok`]).
//!
//! Not covered, as for any truncated kernel: a point whose distance to a particle equals its
//! radius to within the rounding of positions, where the term jumps by `w exp(-4.5)` and which
//! side the point falls on is that rounding's choice.

use std::fmt;

use crate::values::Kernel;

/// f32's unit roundoff: the largest relative error of one rounding to nearest.
pub const U: f64 = f32::EPSILON as f64 / 2.0;

/// The exponent of a term at the edge of its radius: `4.5 d²/r²` is at most this.
const A_MAX: f64 = 4.5;

/// How precisely a backend holds positions and computes the field (one rule decides for every
/// backend: [`choose`]).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Precision {
    /// The cheapest representation whose whole error bound ([`ErrorBound::phi`]) keeps the
    /// relative error of Phi below `tolerance` in this scene: f32 positions and plain sums where
    /// they do, compensated sums or double-single positions where the scene needs them
    /// (GPU backends), the f64 reference where f32 cannot (the CPU).
    Auto {
        /// The largest relative error of Phi allowed.
        tolerance: f64,
    },
    /// f32 positions in local coordinates and plain f32 sums (on the CPU, the f32 kernel),
    /// whatever the error.
    F32,
    /// f32 positions and compensated sums on the GPU backends (on the CPU, the f32 kernel,
    /// whose sums are blocked in f64 anyway): what `auto` takes where many terms overlap.
    F32Compensated,
    /// Double-single positions (f32 hi + lo pairs, about 48 bits) and compensated sums: the
    /// most a GPU backend has, whatever the scene. The CPU computes in f64.
    DoubleSingle,
    /// f64 throughout: the CPU backend's reference field, exactly what the tests compare
    /// against. The GPU backends use their most precise representation for it, as for `ds`.
    F64,
}

impl Precision {
    /// For field values users read as numbers (`aarbf field`): 1e-5 relative.
    pub const FIELD: Precision = Precision::Auto { tolerance: 1e-5 };
    /// For images: 1e-3 relative, a quarter of an 8-bit step where density maps to colour
    /// one to one, and well below the noise of a converging frame.
    pub const RENDER: Precision = Precision::Auto { tolerance: 1e-3 };
}

/// The CLI spelling: `auto` (with the default tolerance of the command), `f32`, `f32c`, `ds`,
/// `f64`, or `auto:TOLERANCE`.
pub fn parse_precision(text: &str, auto: Precision) -> Result<Precision, String> {
    match text {
        "auto" => Ok(auto),
        "f32" => Ok(Precision::F32),
        "f32c" | "f32-compensated" => Ok(Precision::F32Compensated),
        "ds" | "double-single" => Ok(Precision::DoubleSingle),
        "f64" => Ok(Precision::F64),
        t => match t.strip_prefix("auto:").map(str::parse::<f64>) {
            Some(Ok(tolerance)) if tolerance > 0.0 => Ok(Precision::Auto { tolerance }),
            _ => Err(format!(
                "precision '{text}': expected auto, auto:TOLERANCE (e.g. auto:1e-4), f32, f32c, ds or f64"
            )),
        },
    }
}

/// How positions are held.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PositionKind {
    /// f64 in data coordinates (the CPU reference).
    F64,
    /// f32 local coordinates.
    F32,
    /// Double-single local coordinates (f32 hi + lo pairs).
    DoubleSingle,
}

/// How a point's terms are added up.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Summation {
    /// f64 (the CPU reference).
    F64,
    /// f32 blocks of at most `lane_terms` terms per SIMD lane, the blocks added in f64 (the
    /// CPU's f32 kernel).
    Blocked {
        /// The most terms one lane adds in f32 before its block goes to f64.
        lane_terms: u32,
    },
    /// One f32 sum per point, term after term (a cluster's in the intersection shader, then
    /// the clusters'): the GPU backends' plain sums.
    F32,
    /// A cluster's terms in f32, the clusters' sums compensated (Neumaier): the GPU backends'
    /// `COMPENSATED_SUM`.
    Compensated {
        /// Particles per cluster (the terms summed in plain f32).
        cluster: u32,
    },
}

/// Whose f32 arithmetic computes the terms.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Arithmetic {
    /// The CPU's f32 kernel: `k = 4.5/r²` and the weight rounded from f64 on the host; `exp` its
    /// polynomial, with this relative error (per build).
    Cpu {
        /// The relative error of the kernel's `exp` polynomial in this build (with or without
        /// FMA).
        exp_error: f64,
    },
    /// The shared GLSL: the radius and weight from f32 parameters or tables, `exp` as GLSL's.
    Glsl,
}

/// GLSL's `exp` on any Vulkan driver: 3 + 2|x| ulp (Vulkan specification, "Precision and
/// Operation of SPIR-V Instructions"), |x| ≤ 4.5 within a radius; an ulp is 2u relative.
const GLSL_EXP_ULP: f64 = 3.0 + 2.0 * A_MAX;
/// GLSL's division: 2.5 ulp.
const GLSL_DIV_ULP: f64 = 2.5;

/// What the bound needs to know of a scene (all in local coordinates).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SceneNumbers {
    /// The largest magnitude of a local coordinate.
    pub largest: f64,
    /// The smallest positive and the largest radius.
    pub r_min: f64,
    /// The largest radius.
    pub r_max: f64,
    /// At most this many terms at one point ([`crate::accel::max_reach_count`]).
    pub max_terms: usize,
    /// The smallest positive and the largest weight.
    pub w_min: f64,
    /// The largest weight.
    pub w_max: f64,
    /// Whether radii come from a radius map that varies or a radius attribute (the GPU then
    /// computes `4.5 d²/r²` with a division instead of the host's `k`).
    pub radius_varies: bool,
    /// The steepest relative slope, per unit of t, of the density map's and the radius map's
    /// tables (0 for constant maps): what an f32 t costs a weight or radius looked up on the
    /// GPU.
    pub density_slope: f64,
    /// The same for the radius map.
    pub radius_slope: f64,
    /// The kernel the terms are computed with.
    pub kernel: Kernel,
}

impl SceneNumbers {
    /// A scene without particles.
    pub const EMPTY: SceneNumbers = SceneNumbers {
        largest: 0.0,
        r_min: f64::INFINITY,
        r_max: 0.0,
        max_terms: 0,
        w_min: 0.0,
        w_max: 0.0,
        radius_varies: false,
        density_slope: 0.0,
        radius_slope: 0.0,
        kernel: Kernel::GaussianRbf,
    };

    /// Whether every term and sum lies in f32's normal range: the smallest term (at the edge of
    /// a radius) well above the smallest normal f32, so rounding stays relative, and the largest
    /// sum below f32's largest value.
    pub fn f32_range_ok(&self) -> bool {
        let smallest = self.w_min * smallest_profile(self.kernel);
        let largest = self.w_max * self.max_terms.max(1) as f64;
        smallest.is_nan()
            || smallest <= 0.0
            || (smallest >= 2f64.powi(-100) && largest <= 2f64.powi(120))
    }
}

/// A bound on the relative error of Phi, by source, and of Theta over the attribute's range.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ErrorBound {
    /// From the positions' rounding (the offset to each particle).
    pub positions: f64,
    /// From computing the kernel's argument and the kernel itself.
    pub kernel: f64,
    /// From the weight and its product with the kernel.
    pub terms: f64,
    /// From adding the terms up.
    pub summation: f64,
    /// The most terms at one point the summation bound assumed.
    pub max_terms: usize,
}

impl ErrorBound {
    /// No error (the f64 reference: its own rounding is some 1e-15).
    pub const NONE: ErrorBound = ErrorBound {
        positions: 0.0,
        kernel: 0.0,
        terms: 0.0,
        summation: 0.0,
        max_terms: 0,
    };

    /// The bound for a representation of a scene: positions `positions` (F32 or DoubleSingle),
    /// sums `summation`, terms by `arithmetic`. Infinite where f32's range cannot hold the
    /// scene's terms.
    pub fn of(
        scene: &SceneNumbers,
        positions: PositionKind,
        summation: Summation,
        arithmetic: Arithmetic,
    ) -> ErrorBound {
        if positions == PositionKind::F64 {
            return ErrorBound::NONE;
        }
        let n = scene.max_terms;
        if !scene.f32_range_ok() {
            return ErrorBound {
                positions: f64::INFINITY,
                kernel: f64::INFINITY,
                terms: f64::INFINITY,
                summation: f64::INFINITY,
                max_terms: n,
            };
        }
        let ds = positions == PositionKind::DoubleSingle;
        let position = position_error(scene.largest, scene.r_min, scene.r_max);
        let positions_term = if ds { position * U } else { position };
        // A component of the offset: one rounding (f32), two (double-single: hi and lo parts'
        // differences added). d²: each square doubles it and adds one, the two additions one
        // each.
        let offset = if ds { 2.0 } else { 1.0 };
        let d2 = 2.0 * offset + 3.0;
        let (argument, exp, weight) = match arithmetic {
            // k rounded from f64, and the product k d².
            Arithmetic::Cpu { exp_error } => ((d2 + 2.0) * U, exp_error, U),
            Arithmetic::Glsl => {
                let t_rounding = 1.5 * U; // t normalised in f64, rounded, and scaled to the table.
                let weight = U + if scene.density_slope > 0.0 {
                    3.0 * U + scene.density_slope * t_rounding
                } else {
                    0.0
                };
                let argument = if scene.radius_varies {
                    // r = R m(t) h: R and h rounded to f32 and two products (m is the table's
                    // f32 value, the reference's too), plus a varying map's lookup arithmetic
                    // and slope; then r², the product 4.5 d², and the division.
                    let map = if scene.radius_slope > 0.0 {
                        3.0 * U + scene.radius_slope * t_rounding
                    } else {
                        0.0
                    };
                    let r = 4.0 * U + map;
                    (d2 + 1.0 + 1.0 + 2.0 * GLSL_DIV_ULP) * U + 2.0 * r
                } else {
                    // k = 4.5/(R m)² from the host (rounded once) and the product.
                    (d2 + 2.0) * U
                };
                (argument, 2.0 * GLSL_EXP_ULP * U, weight)
            }
        };
        let kernel = if scene.kernel.is_sph() {
            sph_kernel_error(
                scene.kernel,
                argument,
                matches!(arithmetic, Arithmetic::Glsl),
            )
        } else {
            A_MAX * argument + exp
        };
        // The weight and the product w e.
        let terms = weight + U;
        let summation = match summation {
            Summation::F64 => n as f64 * f64::EPSILON,
            Summation::Blocked { lane_terms } => {
                gamma(lane_terms as usize) + n as f64 * f64::EPSILON
            }
            Summation::F32 => gamma(n.saturating_sub(1)),
            Summation::Compensated { cluster } => {
                gamma(cluster.saturating_sub(1) as usize) + 2.0 * U + 4.0 * n as f64 * U * U
            }
        };
        ErrorBound {
            positions: positions_term,
            kernel,
            terms,
            summation,
            max_terms: n,
        }
    }

    /// The relative error of Phi: every part, and their products (each factor `1 + ε`).
    pub fn phi(&self) -> f64 {
        [self.positions, self.kernel, self.terms, self.summation]
            .iter()
            .fold(1.0, |acc, e| acc * (1.0 + e))
            - 1.0
    }

    /// The error of Theta as a fraction of the attribute's range: the numerator's relative
    /// error (Phi's, with t or its colour rounded and multiplied in) and Phi's, through the
    /// ratio, plus the division; never more than the whole range (Theta is a weighted mean of
    /// values within it).
    pub fn theta(&self) -> f64 {
        let phi = self.phi();
        if phi >= 1.0 {
            return 1.0;
        }
        let numerator = phi + 2.0 * U;
        ((phi + numerator) / (1.0 - phi) + U).min(1.0)
    }
}

/// Below this fraction of its peak, an SPH kernel's term is not bounded relative to itself
/// (see [`sph_kernel_error`]).
pub const SPH_TERM_FLOOR: f64 = 1e-3;

/// The smallest profile value whose rounding the bound keeps relative: the Gaussian's at its
/// radius, an SPH kernel's at [`SPH_TERM_FLOOR`] of its peak.
fn smallest_profile(kernel: Kernel) -> f64 {
    if kernel.is_sph() {
        SPH_TERM_FLOOR * kernel.of_q(0.0)
    } else {
        (-A_MAX).exp()
    }
}

/// The relative error of an SPH kernel's term whose value is at least [`SPH_TERM_FLOOR`] of
/// its peak, when `d²/r²` carries the relative error `argument`: `q = support √(d²/r²)` takes
/// half of it, the square root (GLSL: 2.5 ulp through `inversesqrt`, the CPU: correctly
/// rounded) and the product with the support one rounding each; the term moves by its
/// condition number `|q f'(q) / f(q)|` times that, at most [`sph_condition`] over the terms
/// above the floor; the polynomial's own evaluation adds [`sph_evaluation`]. A term below the
/// floor (the last few percent of the support, where `f` falls to 0 as a power of the distance
/// to the edge) can err by more relative to itself: its absolute error is at most `κ ε_q` of
/// the floor, which the bound leaves out, as it leaves out the truncation edge.
pub fn sph_kernel_error(kernel: Kernel, argument: f64, glsl: bool) -> f64 {
    let sqrt = if glsl { 2.0 * 2.5 * U } else { U };
    let q_error = 0.5 * argument + sqrt + U;
    sph_condition(kernel) * q_error + sph_evaluation(kernel) * U
}

/// The largest condition number `|q f'(q) / f(q)|` of an SPH kernel over the q where
/// `f(q) >= SPH_TERM_FLOOR f(0)` (by a fine scan: f is smooth and the number grows towards the
/// edge, so the scan's last point above the floor is its largest). Scanned once per kernel:
/// every upload's bound asks for it.
pub fn sph_condition(kernel: Kernel) -> f64 {
    static SCANNED: std::sync::OnceLock<[f64; Kernel::ALL.len()]> = std::sync::OnceLock::new();
    SCANNED.get_or_init(|| Kernel::ALL.map(scan_condition))[kernel as usize]
}

fn scan_condition(kernel: Kernel) -> f64 {
    let floor = SPH_TERM_FLOOR * kernel.of_q(0.0);
    let s = kernel.support();
    let n = 100_000;
    (1..n)
        .map(|i| s * i as f64 / n as f64)
        .filter(|&q| kernel.of_q(q) >= floor)
        .map(|q| {
            let h = 1e-7 * s;
            let slope = (kernel.of_q(q + h) - kernel.of_q(q - h)) / (2.0 * h);
            (q * slope / kernel.of_q(q)).abs()
        })
        .fold(0.0, f64::max)
}

/// The relative rounding error, in units of u, of evaluating an SPH kernel's polynomial as
/// `values::kernel` and `rbf.glsl` write it: the roundings of its powers and sums, times how
/// much the sum of its pieces cancels (the sum of their magnitudes over the result, at most 3
/// for the cubic spline and 7 for the quintic at q = 0).
fn sph_evaluation(kernel: Kernel) -> f64 {
    match kernel {
        Kernel::GaussianRbf => 0.0,
        Kernel::SphCubic => 3.0 * 6.0,
        Kernel::SphQuintic => 7.0 * 10.0,
        Kernel::SphWendlandC2 => 8.0,
        Kernel::SphWendlandC4 => 12.0,
    }
}

/// γ_n = n u / (1 - n u): the relative error of n roundings in a row (infinite where n u ≥ 1).
fn gamma(n: usize) -> f64 {
    let nu = n as f64 * U;
    if nu < 1.0 {
        nu / (1.0 - nu)
    } else {
        f64::INFINITY
    }
}

/// A bound on the relative error of Phi that rounding local positions to f32 causes, for
/// particles with local coordinates up to `largest` (in magnitude) and radii `r_min` ..
/// `r_max` (the positive ones). A query point within reach of a particle has coordinates up to
/// `largest + r_max`; each coordinate of it and of the particle is rounded by up to u of its
/// magnitude, so their distance d by up to `δ = √3 · u · (2 largest + r_max)`. The term
/// `w exp(-4.5 d² / r²)` then changes by a factor of up to `exp(9 d δ / r²)`, at most
/// `9 δ / r_min` relative for d ≤ r.
pub fn position_error(largest: f64, r_min: f64, r_max: f64) -> f64 {
    if !(r_min.is_finite() && r_min > 0.0) {
        return 0.0;
    }
    let delta = 3f64.sqrt() * U * (2.0 * largest + r_max);
    9.0 * delta / r_min
}

/// How a backend holds and sums the uploaded step, and the error bound that follows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Representation {
    /// How positions are held.
    pub positions: PositionKind,
    /// How a point's terms are added up.
    pub summation: Summation,
    /// The bound on Phi's relative error that follows.
    pub bound: ErrorBound,
    /// The tolerance `auto` was asked to meet, and whether the bound meets it (a GPU backend
    /// whose most precise representation cannot says so: the CPU's f64 can).
    pub tolerance: Option<f64>,
}

impl Representation {
    /// Whether the bound meets the tolerance asked for (always, when none was).
    pub fn meets_tolerance(&self) -> bool {
        self.tolerance.is_none_or(|t| self.bound.phi() <= t)
    }
}

impl fmt::Display for Representation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let positions = match self.positions {
            PositionKind::F64 => "f64 data coordinates",
            PositionKind::F32 => "f32 local coordinates",
            PositionKind::DoubleSingle => "double-single local coordinates",
        };
        let sums = match self.summation {
            Summation::F64 => "f64 sums".to_string(),
            Summation::Blocked { lane_terms } => {
                format!("f32 sums of {lane_terms} terms a lane added in f64")
            }
            Summation::F32 => "f32 sums".to_string(),
            Summation::Compensated { cluster } => {
                format!("compensated sums (clusters of {cluster} in f32)")
            }
        };
        let b = &self.bound;
        if self.positions == PositionKind::F64 {
            return write!(f, "{positions}, {sums} (the f64 reference)");
        }
        write!(
            f,
            "{positions}, {sums}: relative Phi error at most {:.1e} (positions {:.1e}, kernel {:.1e}, terms {:.1e}, summation {:.1e} over at most {} terms), Theta at most {:.1e} of its range",
            b.phi(),
            b.positions,
            b.kernel,
            b.terms,
            b.summation,
            b.max_terms,
            b.theta()
        )?;
        if let Some(t) = self.tolerance
            && !self.meets_tolerance()
        {
            write!(f, "; ABOVE the tolerance {t:.0e}")?;
        }
        Ok(())
    }
}

/// The representation a GPU backend uses for `precision` in `scene` (clusters of `cluster`
/// particles): `auto` tries, cheapest first, f32 positions with plain sums, then with
/// compensated sums, then double-single positions with each, and takes the first whose whole
/// bound meets the tolerance, or the most precise when none does.
pub fn choose_gpu(precision: Precision, scene: &SceneNumbers, cluster: u32) -> Representation {
    let make = |positions, summation, tolerance| Representation {
        positions,
        summation,
        bound: ErrorBound::of(scene, positions, summation, Arithmetic::Glsl),
        tolerance,
    };
    let compensated = Summation::Compensated { cluster };
    match precision {
        Precision::F32 => make(PositionKind::F32, Summation::F32, None),
        Precision::F32Compensated => make(PositionKind::F32, compensated, None),
        Precision::DoubleSingle | Precision::F64 => {
            make(PositionKind::DoubleSingle, compensated, None)
        }
        Precision::Auto { tolerance } => {
            let candidates = [
                (PositionKind::F32, Summation::F32),
                (PositionKind::F32, compensated),
                (PositionKind::DoubleSingle, Summation::F32),
                (PositionKind::DoubleSingle, compensated),
            ];
            candidates
                .iter()
                .map(|&(p, s)| make(p, s, Some(tolerance)))
                .find(Representation::meets_tolerance)
                .unwrap_or_else(|| make(PositionKind::DoubleSingle, compensated, Some(tolerance)))
        }
    }
}

/// The representation the CPU backend uses: its f32 kernel (blocked sums of `lane_terms`, the
/// exponential of the build in use) where `precision` allows it, the f64 reference otherwise.
pub fn choose_cpu(
    precision: Precision,
    scene: &SceneNumbers,
    lane_terms: u32,
    exp_error: f64,
) -> Representation {
    let f32_kernel = |tolerance| {
        let summation = Summation::Blocked { lane_terms };
        Representation {
            positions: PositionKind::F32,
            summation,
            bound: ErrorBound::of(
                scene,
                PositionKind::F32,
                summation,
                Arithmetic::Cpu { exp_error },
            ),
            tolerance,
        }
    };
    let reference = |tolerance| Representation {
        positions: PositionKind::F64,
        summation: Summation::F64,
        bound: ErrorBound::NONE,
        tolerance,
    };
    // The f32 kernel computes the Gaussian only: an SPH kernel takes the reference.
    if scene.kernel.is_sph() {
        return reference(match precision {
            Precision::Auto { tolerance } => Some(tolerance),
            _ => None,
        });
    }
    match precision {
        Precision::F32 | Precision::F32Compensated => f32_kernel(None),
        Precision::DoubleSingle | Precision::F64 => reference(None),
        Precision::Auto { tolerance } => {
            let fast = f32_kernel(Some(tolerance));
            if fast.meets_tolerance() {
                fast
            } else {
                reference(Some(tolerance))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scene(max_terms: usize) -> SceneNumbers {
        SceneNumbers {
            largest: 0.5,
            r_min: 0.5,
            r_max: 0.5,
            max_terms,
            w_min: 1.0,
            w_max: 1.0,
            radius_varies: false,
            density_slope: 0.0,
            radius_slope: 0.0,
            kernel: Kernel::GaussianRbf,
        }
    }

    /// `auto` takes the cheapest representation that meets the tolerance: plain f32 sums where
    /// few terms overlap, compensated ones where many do, double-single positions where radii
    /// are small against the coordinates; and says so when nothing meets it.
    #[test]
    fn auto_takes_the_cheapest_representation_that_meets_the_tolerance() {
        let auto = Precision::FIELD;
        let few = choose_gpu(auto, &scene(30), 1);
        assert_eq!(
            (few.positions, few.summation),
            (PositionKind::F32, Summation::F32)
        );
        assert!(few.meets_tolerance());
        let many = choose_gpu(auto, &scene(2000), 4);
        assert_eq!(
            (many.positions, many.summation),
            (PositionKind::F32, Summation::Compensated { cluster: 4 })
        );
        let small_radii = SceneNumbers {
            r_min: 1e-6,
            ..scene(30)
        };
        let ds = choose_gpu(auto, &small_radii, 1);
        assert_eq!(ds.positions, PositionKind::DoubleSingle);
        assert!(ds.meets_tolerance());
        // A render's tolerance lets a thousand terms through plainly.
        let render = choose_gpu(Precision::RENDER, &scene(2000), 4);
        assert_eq!(render.summation, Summation::F32);
        // The CPU: f32 with its blocked sums whatever the overlap, f64 for tiny radii.
        let cpu = choose_cpu(auto, &scene(100_000), 8, 2.5e-7);
        assert_eq!(cpu.positions, PositionKind::F32);
        assert_eq!(
            choose_cpu(auto, &small_radii, 8, 2.5e-7).positions,
            PositionKind::F64
        );
        // Terms that would underflow f32: no f32 bound at all.
        let tiny = SceneNumbers {
            w_min: 1e-40,
            ..scene(30)
        };
        assert!(!choose_gpu(auto, &tiny, 1).meets_tolerance());
        assert_eq!(
            choose_cpu(auto, &tiny, 8, 2.5e-7).positions,
            PositionKind::F64
        );
    }

    #[test]
    fn the_printed_line_states_the_whole_bound_and_its_parts() {
        let r = choose_gpu(Precision::FIELD, &scene(2000), 4);
        let line = r.to_string();
        for part in [
            "positions",
            "kernel",
            "terms",
            "summation",
            "2000 terms",
            "Theta",
        ] {
            assert!(line.contains(part), "{line}");
        }
        let b = r.bound;
        assert!(b.phi() >= b.positions + b.kernel + b.terms + b.summation);
        assert!(b.theta() > 2.0 * b.phi());
    }
}
