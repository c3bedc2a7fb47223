//! Moving the camera with the mouse as ParaView does: a trackball that turns the view about
//! its focal point (left drag), pan (right or middle drag, or shift + left), dolly (wheel),
//! and snaps to look along the axes.

use glam::{DQuat, DVec3};

use crate::scene::Camera;
use crate::values::Bounds;

/// Radians of rotation per pixel of drag.
const RADIANS_PER_PIXEL: f64 = 0.008;

/// Turns the camera about its focal point: a horizontal drag about the view-up axis, a
/// vertical one about the camera's right axis; the up vector turns with it (a trackball,
/// so the view can go over the top).
pub fn orbit(camera: Camera, dx: f64, dy: f64) -> Camera {
    let offset = camera.eye - camera.at;
    let forward = -offset.normalize_or_zero();
    let right = forward.cross(camera.up).normalize_or_zero();
    let up = right.cross(forward).normalize_or_zero();
    if right == DVec3::ZERO || up == DVec3::ZERO {
        return camera;
    }
    let turn = DQuat::from_axis_angle(up, -dx * RADIANS_PER_PIXEL)
        * DQuat::from_axis_angle(right, -dy * RADIANS_PER_PIXEL);
    Camera {
        eye: camera.at + turn * offset,
        up: (turn * up).normalize(),
        ..camera
    }
}

/// Moves eye and focal point together so the data follows the pointer: `dx`, `dy` in pixels
/// of a view `height` pixels tall.
pub fn pan(camera: Camera, dx: f64, dy: f64, height: f64) -> Camera {
    let offset = camera.eye - camera.at;
    let forward = -offset.normalize_or_zero();
    let right = forward.cross(camera.up).normalize_or_zero();
    let up = right.cross(forward);
    // Data units per pixel at the focal distance.
    let per_pixel =
        2.0 * offset.length() * (camera.fovy.to_radians() * 0.5).tan() / height.max(1.0);
    let shift = (-dx * right + dy * up) * per_pixel;
    Camera {
        eye: camera.eye + shift,
        at: camera.at + shift,
        ..camera
    }
}

/// Moves the eye towards the focal point (`amount` > 0) or away, by a factor per unit, never
/// onto it.
pub fn dolly(camera: Camera, amount: f64) -> Camera {
    let offset = camera.eye - camera.at;
    let factor = (-amount * 0.002).exp().clamp(0.05, 20.0);
    let offset = offset * factor;
    if offset.length() <= 1e-9 * camera.at.length().max(1.0) {
        return camera;
    }
    Camera {
        eye: camera.at + offset,
        ..camera
    }
}

/// The axis views: looking along +X, -X, +Y, -Y, +Z or -Z at the data's centre, from the
/// distance of the default view.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AxisView {
    /// Looking along +X.
    PlusX,
    /// Looking along -X.
    MinusX,
    /// Looking along +Y.
    PlusY,
    /// Looking along -Y.
    MinusY,
    /// Looking along +Z.
    PlusZ,
    /// Looking along -Z.
    MinusZ,
}

impl AxisView {
    /// The six views, in the order their buttons appear.
    pub const ALL: [AxisView; 6] = [
        AxisView::PlusX,
        AxisView::MinusX,
        AxisView::PlusY,
        AxisView::MinusY,
        AxisView::PlusZ,
        AxisView::MinusZ,
    ];

    /// The button text: "+X", "-X", "+Y", "-Y", "+Z" or "-Z".
    pub fn label(self) -> &'static str {
        match self {
            AxisView::PlusX => "+X",
            AxisView::MinusX => "-X",
            AxisView::PlusY => "+Y",
            AxisView::MinusY => "-Y",
            AxisView::PlusZ => "+Z",
            AxisView::MinusZ => "-Z",
        }
    }

    /// The direction the camera looks in.
    fn direction(self) -> DVec3 {
        match self {
            AxisView::PlusX => DVec3::X,
            AxisView::MinusX => DVec3::NEG_X,
            AxisView::PlusY => DVec3::Y,
            AxisView::MinusY => DVec3::NEG_Y,
            AxisView::PlusZ => DVec3::Z,
            AxisView::MinusZ => DVec3::NEG_Z,
        }
    }

    /// The camera of this view of data in `bounds`: looking along the axis at the default view's
    /// target from the default view's distance, with vertical field of view `fovy` in degrees; up
    /// is +Y, or +Z when looking along Y.
    pub fn camera(self, bounds: Bounds, fovy: f64) -> Camera {
        let default = Camera::default_for(bounds);
        let distance = (default.eye - default.at).length();
        let look = self.direction();
        let up = if look.y == 0.0 { DVec3::Y } else { DVec3::Z };
        Camera {
            eye: default.at - look * distance,
            at: default.at,
            up,
            fovy,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn camera() -> Camera {
        Camera {
            eye: DVec3::new(0.0, 0.0, 5.0),
            at: DVec3::new(1.0, 2.0, 0.0),
            up: DVec3::Y,
            fovy: 40.0,
        }
    }

    #[test]
    fn orbit_keeps_the_focal_point_and_distance_and_undoes_itself() {
        let c = camera();
        let d0 = (c.eye - c.at).length();
        let o = orbit(c, 37.0, -12.0);
        assert_eq!(o.at, c.at);
        assert!(((o.eye - o.at).length() - d0).abs() < 1e-12 * d0);
        assert!(o.eye.distance(c.eye) > 0.1);
        // The up vector stays perpendicular to the view.
        assert!((o.eye - o.at).normalize().dot(o.up).abs() < 1e-12);
        // A horizontal drag back and forth returns (rotation about the same view-up axis).
        let back = orbit(orbit(c, 50.0, 0.0), -50.0, 0.0);
        assert!(back.eye.distance(c.eye) < 1e-9, "{back:?}");
        // Over the top: a long vertical drag keeps a valid camera.
        let top = orbit(c, 0.0, 400.0);
        assert!(top.frame(64, 64).is_ok());
    }

    #[test]
    fn pan_moves_eye_and_target_together_by_the_view_scale() {
        let c = camera();
        let p = pan(c, 100.0, 0.0, 200.0);
        assert!((p.eye - c.eye).distance(p.at - c.at) < 1e-12);
        let d = (c.eye - c.at).length();
        let width_at_focus = 2.0 * d * (20f64).to_radians().tan();
        // Half the view's height in pixels moves the data by half the view's height.
        assert!(((p.at - c.at).length() - 0.5 * width_at_focus).abs() < 1e-9);
    }

    #[test]
    fn dolly_approaches_without_reaching_the_target() {
        let c = camera();
        let d0 = (c.eye - c.at).length();
        let nearer = dolly(c, 200.0);
        let d1 = (nearer.eye - nearer.at).length();
        assert!(d1 < d0 && d1 > 0.0);
        let far = dolly(c, -200.0);
        assert!((far.eye - far.at).length() > d0);
        let mut c2 = c;
        for _ in 0..1000 {
            c2 = dolly(c2, 1e4);
        }
        assert!(c2.frame(8, 8).is_ok());
    }

    #[test]
    fn axis_views_look_along_their_axis_at_the_centre() {
        let b = Bounds {
            min: DVec3::new(-1.0, 0.0, 2.0),
            max: DVec3::new(3.0, 1.0, 4.0),
        };
        for v in AxisView::ALL {
            let c = v.camera(b, 30.0);
            assert_eq!(c.at, b.center());
            let look = (c.at - c.eye).normalize();
            assert!(look.distance(v.direction()) < 1e-12, "{v:?}");
            assert!(c.frame(16, 16).is_ok(), "{v:?}");
        }
    }
}
