//! Pinhole cameras: look-at with a vertical field of view, orbits around a centre, and the
//! paper's benchmark orbit (50 positions on a Fibonacci hemisphere).

use glam::DVec3;
use serde::{Deserialize, Serialize};

use crate::values::Bounds;
use crate::values::frame::CameraFrame;

/// A pinhole camera looking from `eye` at `at`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Camera {
    pub eye: DVec3,
    pub at: DVec3,
    pub up: DVec3,
    /// Vertical field of view in degrees.
    pub fovy: f64,
}

/// A camera that cannot form an image.
#[derive(Debug, thiserror::Error)]
pub enum CameraError {
    #[error("camera eye and target coincide ({0})")]
    EyeIsTarget(DVec3),
    #[error("camera up vector {0} is parallel to the view direction")]
    UpParallel(DVec3),
    #[error("field of view {0} degrees is outside (0, 180)")]
    Fov(f64),
    #[error("camera values must be finite")]
    NotFinite,
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

    /// A camera at azimuth/elevation (degrees, y up) around `bounds`, far enough back that the
    /// bounding sphere fills the view.
    pub fn orbit(bounds: Bounds, azimuth: f64, elevation: f64, fovy: f64) -> Camera {
        let centre = bounds.center();
        let radius = (bounds.diagonal() * 0.5).max(1e-9);
        // The bounding sphere just fits; its corners are rarely occupied, so crop them a little.
        let distance = radius / (fovy.to_radians() * 0.5).sin() * 0.9;
        let (a, e) = (azimuth.to_radians(), elevation.to_radians());
        let dir = DVec3::new(e.cos() * a.sin(), e.sin(), e.cos() * a.cos());
        Camera {
            eye: centre + dir * distance,
            at: centre,
            up: DVec3::Y,
            fovy,
        }
    }

    /// The default view of a data set: from the front right, slightly above.
    pub fn default_for(bounds: Bounds) -> Camera {
        Camera::orbit(bounds, 35.0, 25.0, 40.0)
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
