//! Colour-space conversions: sRGB and linear light, CIELAB and Moreland's Msh (for colour-map
//! interpolation as ParaView does it).

/// An sRGB-encoded channel in [0, 1] as linear light.
pub fn srgb_to_linear(c: f64) -> f64 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// A linear-light channel in [0, 1] as sRGB-encoded.
pub fn linear_to_srgb(c: f64) -> f64 {
    if c <= 0.0031308 {
        c * 12.92
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

const WHITE: [f64; 3] = [0.95047, 1.0, 1.08883];

fn srgb_to_lab(rgb: [f64; 3]) -> [f64; 3] {
    let [r, g, b] = rgb.map(srgb_to_linear);
    let xyz = [
        0.4124 * r + 0.3576 * g + 0.1805 * b,
        0.2126 * r + 0.7152 * g + 0.0722 * b,
        0.0193 * r + 0.1192 * g + 0.9505 * b,
    ];
    let f = |t: f64| {
        if t > 0.008856 {
            t.cbrt()
        } else {
            7.787 * t + 16.0 / 116.0
        }
    };
    let [fx, fy, fz] = [0, 1, 2].map(|i| f(xyz[i] / WHITE[i]));
    [116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz)]
}

fn lab_to_srgb(lab: [f64; 3]) -> [f64; 3] {
    let fy = (lab[0] + 16.0) / 116.0;
    let fx = fy + lab[1] / 500.0;
    let fz = fy - lab[2] / 200.0;
    let finv = |t: f64| {
        if t.powi(3) > 0.008856 {
            t.powi(3)
        } else {
            (t - 16.0 / 116.0) / 7.787
        }
    };
    let [x, y, z] = [fx, fy, fz].map(finv);
    let (x, y, z) = (x * WHITE[0], y * WHITE[1], z * WHITE[2]);
    let r = 3.2406 * x - 1.5372 * y - 0.4986 * z;
    let g = -0.9689 * x + 1.8758 * y + 0.0415 * z;
    let b = 0.0557 * x - 0.2040 * y + 1.0570 * z;
    [r, g, b].map(|c| linear_to_srgb(c.clamp(0.0, 1.0)))
}

/// The sRGB colour a fraction `u` of the way from `a` to `b`, interpolated in CIELAB.
pub fn lab_mix(a: [f64; 3], b: [f64; 3], u: f64) -> [f64; 3] {
    let (la, lb) = (srgb_to_lab(a), srgb_to_lab(b));
    lab_to_srgb(std::array::from_fn(|i| la[i] + u * (lb[i] - la[i])))
}

fn lab_to_msh(lab: [f64; 3]) -> [f64; 3] {
    let m = (lab[0] * lab[0] + lab[1] * lab[1] + lab[2] * lab[2]).sqrt();
    let s = if m > 0.001 {
        (lab[0] / m).clamp(-1.0, 1.0).acos()
    } else {
        0.0
    };
    let h = if s > 0.001 { lab[2].atan2(lab[1]) } else { 0.0 };
    [m, s, h]
}

fn msh_to_lab(msh: [f64; 3]) -> [f64; 3] {
    let [m, s, h] = msh;
    [m * s.cos(), m * s.sin() * h.cos(), m * s.sin() * h.sin()]
}

fn adjust_hue(msh: [f64; 3], unsaturated_m: f64) -> f64 {
    let [m, s, h] = msh;
    if m >= unsaturated_m - 0.1 {
        h
    } else {
        let spin = s * (unsaturated_m * unsaturated_m - m * m).sqrt() / (m * s.sin());
        if h > -std::f64::consts::FRAC_PI_3 {
            h + spin
        } else {
            h - spin
        }
    }
}

/// Moreland's diverging interpolation ("Diverging Color Maps for Scientific Visualization",
/// 2009) in Msh space, as ParaView's "Diverging" colour space.
pub fn diverging(a: [f64; 3], b: [f64; 3], u: f64) -> [f64; 3] {
    let mut ma = lab_to_msh(srgb_to_lab(a));
    let mut mb = lab_to_msh(srgb_to_lab(b));
    let mut u = u;
    // Two saturated, distinct colours pass through an unsaturated white in the middle.
    if ma[1] > 0.05 && mb[1] > 0.05 && (ma[2] - mb[2]).abs() > std::f64::consts::FRAC_PI_3 {
        let mid = ma[0].max(mb[0]).max(88.0);
        if u < 0.5 {
            mb = [mid, 0.0, 0.0];
            u *= 2.0;
        } else {
            ma = [mid, 0.0, 0.0];
            u = 2.0 * u - 1.0;
        }
    }
    if ma[1] < 0.05 && mb[1] > 0.05 {
        ma[2] = adjust_hue(mb, ma[0]);
    } else if mb[1] < 0.05 && ma[1] > 0.05 {
        mb[2] = adjust_hue(ma, mb[0]);
    }
    let msh = std::array::from_fn(|i| (1.0 - u) * ma[i] + u * mb[i]);
    lab_to_srgb(msh_to_lab(msh))
}
