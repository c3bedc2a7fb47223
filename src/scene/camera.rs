//! Pinhole cameras: look-at with a vertical field of view, orbits around a centre, and the
//! paper's benchmark orbit (50 positions on a Fibonacci hemisphere).

use glam::DVec3;
use serde::{Deserialize, Serialize};

use crate::values::Bounds;
use crate::values::frame::CameraFrame;

/// A pinhole camera looking from `eye` at `at`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Camera {
    /// The camera's position, data units.
    pub eye: DVec3,
    /// The point it looks at, data units.
    pub at: DVec3,
    /// The direction that is up in the image (any length, not parallel to the view).
    pub up: DVec3,
    /// Vertical field of view in degrees.
    pub fovy: f64,
}

/// A camera that cannot form an image.
#[derive(Debug, thiserror::Error)]
pub enum CameraError {
    /// `eye` and `at` are the same point.
    #[error("camera eye and target coincide ({0})")]
    EyeIsTarget(DVec3),
    /// `up` points along the view direction.
    #[error("camera up vector {0} is parallel to the view direction")]
    UpParallel(DVec3),
    /// The field of view, degrees, is not in (0, 180).
    #[error("field of view {0} degrees is outside (0, 180)")]
    Fov(f64),
    /// A value is NaN or infinite.
    #[error("camera values must be finite")]
    NotFinite,
    /// A camera string that does not parse as `ex,ey,ez,ax,ay,az,ux,uy,uz,fovy`.
    #[error("cannot read camera '{0}': expected ex,ey,ez,ax,ay,az,ux,uy,uz,fovy")]
    Syntax(String),
}

impl Camera {
    /// Checks the camera and returns its frame for an image of `width` x `height`.
    pub fn frame(&self, width: u32, height: u32) -> Result<CameraFrame, CameraError> {
        if !(self.eye.is_finite()
            && self.at.is_finite()
            && self.up.is_finite()
            && self.fovy.is_finite())
        {
            return Err(CameraError::NotFinite);
        }
        if !(self.fovy > 0.0 && self.fovy < 180.0) {
            return Err(CameraError::Fov(self.fovy));
        }
        let forward = self.at - self.eye;
        if forward.length() <= 1e-12 * self.eye.length().max(1.0) {
            return Err(CameraError::EyeIsTarget(self.eye));
        }
        let forward = forward.normalize();
        let right = forward.cross(self.up);
        if right.length() <= 1e-9 * self.up.length() {
            return Err(CameraError::UpParallel(self.up));
        }
        let right = right.normalize();
        let up = right.cross(forward);
        let tan = (self.fovy.to_radians() * 0.5).tan();
        let aspect = f64::from(width) / f64::from(height.max(1));
        Ok(CameraFrame {
            eye: self.eye,
            forward,
            right: right * tan * aspect,
            up: up * tan,
        })
    }

    /// A camera at azimuth/elevation (degrees) about the `up` axis around `bounds`, far enough
    /// back that the bounding sphere fills the view. Azimuth 0 looks along the axis the
    /// [`UpAxis::horizontal`] frame puts in front (from -y with z up, from +z with y up).
    pub fn orbit(bounds: Bounds, up: UpAxis, azimuth: f64, elevation: f64, fovy: f64) -> Camera {
        let radius = (bounds.diagonal() * 0.5).max(1e-9);
        // The bounding sphere just fits; its corners are rarely occupied, so crop them a little.
        let distance = radius / (fovy.to_radians() * 0.5).sin() * 0.9;
        Camera::from_angles(bounds, up, azimuth, elevation, distance, fovy)
    }

    /// A camera at azimuth/elevation (degrees) about the `up` axis, `distance` from the
    /// bounds' centre, looking at it.
    pub fn from_angles(
        bounds: Bounds,
        up: UpAxis,
        azimuth: f64,
        elevation: f64,
        distance: f64,
        fovy: f64,
    ) -> Camera {
        let (side, front) = up.horizontal();
        let (a, e) = (azimuth.to_radians(), elevation.to_radians());
        let dir = e.cos() * (a.sin() * side + a.cos() * front) + e.sin() * up.vector();
        let centre = bounds.center();
        Camera {
            eye: centre + dir * distance,
            at: centre,
            up: up.vector(),
            fovy,
        }
    }

    /// The default view of a data set: upright along [`UpAxis::of_bounds`], from the front
    /// right and slightly above; planar data (a 2D simulation) face on.
    pub fn default_for(bounds: Bounds) -> Camera {
        match planar_axis(bounds) {
            // Face on: along the flat axis, with y up (z when y is the flat one).
            Some(2) => Camera::orbit(bounds, UpAxis::Y, 0.0, 0.0, 40.0),
            Some(1) => Camera::orbit(bounds, UpAxis::Z, 0.0, 0.0, 40.0),
            Some(_) => Camera::orbit(bounds, UpAxis::Z, 90.0, 0.0, 40.0),
            None => Camera::default_upright(bounds, UpAxis::Z),
        }
    }

    /// The default view with `up` as the user gave it.
    pub fn default_upright(bounds: Bounds, up: UpAxis) -> Camera {
        Camera::orbit(bounds, up, 35.0, 25.0, 40.0)
    }

    /// Camera `index` of the paper's benchmark orbit: `count` points on a Fibonacci sphere
    /// (golden-angle increment pi (3 - sqrt 5), y = i (2/n) - 1 + 1/n) folded onto the upper
    /// hemisphere, looking at the data's centre from half its diagonal.
    pub fn benchmark_orbit(bounds: Bounds, index: usize, count: usize, fovy: f64) -> Camera {
        let n = count.max(1) as f64;
        let i = (index % count.max(1)) as f64;
        let y = i * (2.0 / n) - 1.0 + 1.0 / n;
        let r = (1.0 - y * y).max(0.0).sqrt();
        let phi = i * std::f64::consts::PI * (3.0 - 5f64.sqrt());
        let dir = DVec3::new(phi.cos() * r, y.abs(), phi.sin() * r);
        let centre = bounds.center();
        let distance = view_radius(bounds);
        // Straight overhead views need another up vector.
        let up = if dir.y > 0.999 { DVec3::Z } else { DVec3::Y };
        Camera {
            eye: centre + dir * distance,
            at: centre,
            up,
            fovy,
        }
    }
}

/// The axis along which the data has no extent (a 2D simulation written in 3D), if any.
fn planar_axis(bounds: Bounds) -> Option<usize> {
    if bounds.is_empty() {
        return None;
    }
    let e = bounds.extent().to_array();
    let largest = e.iter().copied().fold(0.0, f64::max);
    let flat: Vec<usize> = (0..3).filter(|&i| e[i] <= 1e-6 * largest).collect();
    match flat[..] {
        [axis] => Some(axis),
        _ => None,
    }
}

/// The axis a view stands upright along: simulation data is usually z-up (gravity along -z),
/// graphics data y-up.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(try_from = "String", into = "String")]
pub enum UpAxis {
    /// +x is up.
    X,
    /// +y is up.
    Y,
    /// +z is up.
    Z,
    /// -x is up.
    NegX,
    /// -y is up.
    NegY,
    /// -z is up.
    NegZ,
}

impl UpAxis {
    /// Every axis, positive then negative.
    pub const ALL: [UpAxis; 6] = [
        UpAxis::X,
        UpAxis::Y,
        UpAxis::Z,
        UpAxis::NegX,
        UpAxis::NegY,
        UpAxis::NegZ,
    ];

    /// The axis's unit vector.
    pub fn vector(self) -> DVec3 {
        match self {
            UpAxis::X => DVec3::X,
            UpAxis::Y => DVec3::Y,
            UpAxis::Z => DVec3::Z,
            UpAxis::NegX => DVec3::NEG_X,
            UpAxis::NegY => DVec3::NEG_Y,
            UpAxis::NegZ => DVec3::NEG_Z,
        }
    }

    /// The axis a vector points along, if it points along one.
    pub fn along(v: DVec3) -> Option<UpAxis> {
        let v = v.normalize_or_zero();
        UpAxis::ALL
            .into_iter()
            .find(|a| (a.vector() - v).length() < 1e-9)
    }

    /// The horizontal directions (side, front) of views upright along this axis, so that
    /// (side, up, front) is right-handed: azimuth 0 looks from `front` with `side` to the
    /// right. With y up: x and z (the graphics convention); with z up: x and -y (ParaView's
    /// "-Y" view: x to the right, z up); with x up: y and -z.
    pub fn horizontal(self) -> (DVec3, DVec3) {
        let (side, front) = match self {
            UpAxis::X | UpAxis::NegX => (DVec3::Y, DVec3::NEG_Z),
            UpAxis::Y | UpAxis::NegY => (DVec3::X, DVec3::Z),
            UpAxis::Z | UpAxis::NegZ => (DVec3::X, DVec3::NEG_Y),
        };
        // Upside down: the front turns round too, so the frame stays right-handed.
        if self.vector().element_sum() < 0.0 {
            (side, -front)
        } else {
            (side, front)
        }
    }

    /// The name the command line and the scene file use (`"z"`, `"-y"`, ...).
    pub fn name(self) -> &'static str {
        match self {
            UpAxis::X => "x",
            UpAxis::Y => "y",
            UpAxis::Z => "z",
            UpAxis::NegX => "-x",
            UpAxis::NegY => "-y",
            UpAxis::NegZ => "-z",
        }
    }
}

impl TryFrom<String> for UpAxis {
    type Error = String;
    fn try_from(s: String) -> Result<UpAxis, String> {
        s.parse()
    }
}

impl From<UpAxis> for String {
    fn from(a: UpAxis) -> String {
        a.name().to_owned()
    }
}

impl std::fmt::Display for UpAxis {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for UpAxis {
    type Err = String;
    fn from_str(s: &str) -> Result<UpAxis, String> {
        let text = s.trim().to_ascii_lowercase();
        let text = text.strip_prefix('+').unwrap_or(&text);
        UpAxis::ALL
            .into_iter()
            .find(|a| a.name() == text)
            .ok_or_else(|| format!("up axis '{s}': expected one of x, y, z, -x, -y, -z"))
    }
}

/// Half the bounds' diagonal; for a point or an empty box, a unit (or, far from the origin, a
/// size the coordinates can resolve), so a camera always has somewhere to stand.
fn view_radius(bounds: Bounds) -> f64 {
    let r = bounds.diagonal() * 0.5;
    let resolvable = bounds.center().abs().max_element() * 1e-5;
    if r > resolvable {
        r
    } else {
        resolvable.max(1.0)
    }
}

impl std::str::FromStr for Camera {
    type Err = CameraError;
    /// `ex,ey,ez,ax,ay,az,ux,uy,uz,fovy`.
    fn from_str(s: &str) -> Result<Camera, CameraError> {
        let v: Vec<f64> = s
            .split(',')
            .map(|x| x.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .map_err(|_| CameraError::Syntax(s.to_owned()))?;
        let [ex, ey, ez, ax, ay, az, ux, uy, uz, fovy] = v[..] else {
            return Err(CameraError::Syntax(s.to_owned()));
        };
        let camera = Camera {
            eye: DVec3::new(ex, ey, ez),
            at: DVec3::new(ax, ay, az),
            up: DVec3::new(ux, uy, uz),
            fovy,
        };
        camera.frame(1, 1)?;
        Ok(camera)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_is_orthogonal_and_scaled_by_the_field_of_view() {
        let c = Camera {
            eye: DVec3::new(0.0, 0.0, 5.0),
            at: DVec3::ZERO,
            up: DVec3::Y,
            fovy: 90.0,
        };
        let f = c.frame(200, 100).unwrap();
        assert!((f.forward - DVec3::NEG_Z).length() < 1e-12);
        assert!((f.up - DVec3::Y).length() < 1e-12, "tan(45°) = 1");
        assert!((f.right - DVec3::X * 2.0).length() < 1e-12, "aspect 2");
        assert!(Camera { at: c.eye, ..c }.frame(1, 1).is_err());
        assert!(Camera { up: DVec3::Z, ..c }.frame(1, 1).is_err());
        assert!(Camera { fovy: 180.0, ..c }.frame(1, 1).is_err());
        assert!("0,0,5,0,0,0,0,1,0,45".parse::<Camera>().is_ok());
        assert!("0,0,5,0,0,0".parse::<Camera>().is_err());
    }

    #[test]
    fn views_stand_upright_along_their_axis() {
        let b = Bounds {
            min: DVec3::new(1e3, -2.0, 0.5),
            max: DVec3::new(1e3 + 1.2, 0.4, 0.9),
        };
        for up in UpAxis::ALL {
            let (side, front) = up.horizontal();
            assert!(
                (side.cross(up.vector()) - front).length() < 1e-12,
                "{up}: right-handed"
            );
            let c = Camera::default_upright(b, up);
            let f = c.frame(64, 64).unwrap();
            // Upright: the image's up has a positive share of the axis, and the view is from
            // above (elevation 25 degrees).
            assert!(f.up.normalize().dot(up.vector()) > 0.5, "{up}");
            assert!((c.eye - c.at).normalize().dot(up.vector()) > 0.4, "{up}");
            assert_eq!(up.name().parse::<UpAxis>().unwrap(), up);
            assert_eq!(UpAxis::along(up.vector() * 3.0), Some(up));
        }
        assert!("w".parse::<UpAxis>().is_err());
        assert_eq!("+Z".parse::<UpAxis>().unwrap(), UpAxis::Z);
        // Simulation data is z-up unless it is planar.
        assert_eq!(Camera::default_for(b).up, DVec3::Z);
        let z0 = Bounds {
            min: DVec3::new(0.0, 0.0, 3.0),
            max: DVec3::new(4.0, 2.0, 3.0),
        };
        let c = Camera::default_for(z0);
        assert_eq!(c.up, DVec3::Y);
        assert!((c.eye - c.at).normalize().dot(DVec3::Z) > 0.999, "face on");
        // With z up, azimuth 0 looks from -y with x to the right.
        let c = Camera::orbit(b, UpAxis::Z, 0.0, 0.0, 40.0);
        let f = c.frame(64, 64).unwrap();
        assert!((c.eye - c.at).normalize().dot(DVec3::NEG_Y) > 0.999);
        assert!(f.right.normalize().dot(DVec3::X) > 0.999);
    }

    #[test]
    fn benchmark_orbit_lies_on_the_upper_hemisphere_at_half_the_diagonal() {
        let b = Bounds {
            min: DVec3::ZERO,
            max: DVec3::new(2.0, 1.0, 1.0),
        };
        let mut dirs = Vec::new();
        for i in 0..50 {
            let c = Camera::benchmark_orbit(b, i, 50, 45.0);
            let d = c.eye - b.center();
            assert!((d.length() - b.diagonal() / 2.0).abs() < 1e-9);
            assert!(d.y >= 0.0);
            assert!(c.frame(64, 64).is_ok());
            dirs.push(d.normalize());
        }
        // Distinct positions, spread over azimuth.
        for i in 0..50 {
            for j in 0..i {
                assert!((dirs[i] - dirs[j]).length() > 1e-3, "{i} {j}");
            }
        }
    }
}
