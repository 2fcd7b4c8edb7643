//! The pinhole camera and vtfarm's pixel convention, shared by the rasterizer,
//! the ray tracer and the vertex tracer so that all three agree to the bit.
//!
//! Convention: pixel (x, y) has its centre at (x + 0.5, y + 0.5); row 0 is the
//! top row; x grows to the right. The vertical field of view spans the image
//! height. Depth is the distance along the viewing direction (view-space z).

use glam::Vec3;

use crate::bounds::{self, OutOfBounds, check};

/// The largest image width or height in pixels.
pub const MAX_IMAGE_SIDE: u32 = 16384;

/// The most pixels one frame may have: 2^24 (4096 × 4096, or 16384 × 1024).
/// A frame costs about 100 bytes per pixel between master and worker (ID and
/// behind-the-glass buffers 24, the composited image with its components and
/// masks about 50, the finished image on the wire 12), so this keeps one frame
/// near 1.6 GB and its image within the message limit; 16384 × 16384 would
/// need 27 GB.
pub const MAX_PIXELS: u64 = 1 << 24;

/// A pinhole camera. [`Camera::validate`] states what makes one usable.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    pub eye: Vec3,
    pub target: Vec3,
    pub up: Vec3,
    /// Vertical field of view in degrees.
    pub fov_y_deg: f32,
    pub width: u32,
    pub height: u32,
}

/// A point projected to continuous pixel coordinates plus its view depth.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScreenPoint {
    pub x: f32,
    pub y: f32,
    /// Distance along the viewing direction; positive in front of the eye.
    pub depth: f32,
}

/// Points closer than this (in metres of view depth) are not projected.
pub const NEAR: f32 = 1e-3;

impl Camera {
    /// Checks every bound: eye and target within [`bounds::MAX_COORDINATE`],
    /// `up` finite, the field of view, the image size (each side 1 to
    /// [`MAX_IMAGE_SIDE`], at most [`MAX_PIXELS`] in all) and a view that
    /// makes a basis (the eye away from the target, `up` not along the view).
    pub fn validate(&self) -> Result<(), OutOfBounds> {
        bounds::point("eye", self.eye)?;
        bounds::point("target", self.target)?;
        Camera::check_up(self.up)?;
        Camera::check_fov(self.fov_y_deg)?;
        Camera::check_size(self.width, self.height)?;
        Camera::check_view(self.eye, self.target, self.up)
    }

    /// The up vector: finite and not zero.
    pub fn check_up(up: Vec3) -> Result<Vec3, OutOfBounds> {
        if up.is_finite() && up != Vec3::ZERO {
            Ok(up)
        } else {
            Err(OutOfBounds::new("up", up, "finite and not zero"))
        }
    }

    /// The vertical field of view: above 0 and below 180 degrees.
    pub fn check_fov(fov_y_deg: f32) -> Result<f32, OutOfBounds> {
        check(
            "fov_y_deg",
            fov_y_deg,
            "between 0 and 180 degrees, exclusive",
            |f| f > 0.0 && f < 180.0,
        )
    }

    /// One image side: 1 to [`MAX_IMAGE_SIDE`] pixels.
    pub fn check_side(field: &'static str, pixels: u32) -> Result<u32, OutOfBounds> {
        check(field, pixels, format!("1 to {MAX_IMAGE_SIDE}"), |n| {
            (1..=MAX_IMAGE_SIDE).contains(&n)
        })
    }

    /// Both sides, and at most [`MAX_PIXELS`] in all.
    pub fn check_size(width: u32, height: u32) -> Result<(), OutOfBounds> {
        Camera::check_side("width", width)?;
        Camera::check_side("height", height)?;
        let pixels = u64::from(width) * u64::from(height);
        if pixels > MAX_PIXELS {
            return Err(OutOfBounds::new(
                "width × height",
                format!("{width} × {height}"),
                format!("at most {MAX_PIXELS} pixels (about 100 bytes each in memory)"),
            ));
        }
        Ok(())
    }

    /// Whether an eye, target and up vector make a camera basis: the eye
    /// away from the target, `up` not along the view (the basis takes
    /// right = forward × up). Blames `eye` or `up`.
    pub fn check_view(eye: Vec3, target: Vec3, up: Vec3) -> Result<(), OutOfBounds> {
        let forward = target - eye;
        let length = forward.length();
        if length.is_nan() || length < 1e-6 {
            return Err(OutOfBounds::new(
                "eye",
                eye,
                format!("away from the target {target}"),
            ));
        }
        let sine = forward.normalize().cross(up.normalize_or_zero()).length();
        if sine.is_nan() || sine < 1e-4 {
            return Err(OutOfBounds::new(
                "up",
                up,
                format!("not zero and not parallel to the view direction {forward}"),
            ));
        }
        Ok(())
    }

    /// The orthonormal camera basis: (forward, right, up).
    pub fn basis(&self) -> (Vec3, Vec3, Vec3) {
        let forward = (self.target - self.eye).normalize();
        let right = forward.cross(self.up).normalize();
        let up = right.cross(forward);
        (forward, right, up)
    }

    /// Half the image height at view depth 1.
    pub fn tan_half_fov(&self) -> f32 {
        (self.fov_y_deg.to_radians() * 0.5).tan()
    }

    /// Size in world units of one pixel at view depth 1.
    pub fn pixel_size_at_unit_depth(&self) -> f32 {
        2.0 * self.tan_half_fov() / self.height as f32
    }

    /// The solid angle (sr) pixel (`x`, `y`) subtends at the eye: its area
    /// on the image plane at unit depth times cos³ of its centre's angle
    /// off the view axis. The sum of luminance times this over the pixels
    /// is the illuminance at the eye (on a plane facing what is summed).
    pub fn pixel_solid_angle(&self, x: u32, y: u32) -> f32 {
        let s = self.pixel_size_at_unit_depth();
        let cx = (x as f32 + 0.5 - 0.5 * self.width as f32) * s;
        let cy = (y as f32 + 0.5 - 0.5 * self.height as f32) * s;
        let cos = 1.0 / (1.0 + cx * cx + cy * cy).sqrt();
        s * s * cos * cos * cos
    }

    /// The unit direction of the ray from the eye through continuous pixel
    /// coordinates (`px`, `py`); the centre of pixel (x, y) is (x + 0.5, y + 0.5).
    pub fn ray_direction(&self, px: f32, py: f32) -> Vec3 {
        Projector::new(self).ray_direction(px, py)
    }

    /// The ray direction through the centre of pixel (`x`, `y`).
    pub fn pixel_ray(&self, x: u32, y: u32) -> Vec3 {
        self.ray_direction(x as f32 + 0.5, y as f32 + 0.5)
    }

    /// Projects a world point to continuous pixel coordinates, or `None` when
    /// it lies behind the near plane.
    pub fn project(&self, p: Vec3) -> Option<ScreenPoint> {
        Projector::new(self).project(p)
    }
}

/// A camera with its basis precomputed, for projecting many points or
/// casting many pixel rays (bit-identical to the `Camera` methods).
#[derive(Clone, Copy, Debug)]
pub struct Projector {
    eye: Vec3,
    forward: Vec3,
    right: Vec3,
    up: Vec3,
    pixel: f32,
    inv_pixel: f32,
    half_w: f32,
    half_h: f32,
}

impl Projector {
    pub fn new(camera: &Camera) -> Self {
        let (forward, right, up) = camera.basis();
        Projector {
            eye: camera.eye,
            forward,
            right,
            up,
            pixel: camera.pixel_size_at_unit_depth(),
            inv_pixel: 1.0 / camera.pixel_size_at_unit_depth(),
            half_w: camera.width as f32 * 0.5,
            half_h: camera.height as f32 * 0.5,
        }
    }

    /// See [`Camera::ray_direction`].
    pub fn ray_direction(&self, px: f32, py: f32) -> Vec3 {
        let cx = (px - self.half_w) * self.pixel;
        let cy = (self.half_h - py) * self.pixel;
        (self.forward + self.right * cx + self.up * cy).normalize()
    }

    /// See [`Camera::pixel_ray`].
    pub fn pixel_ray(&self, x: u32, y: u32) -> Vec3 {
        self.ray_direction(x as f32 + 0.5, y as f32 + 0.5)
    }

    /// The direction through the centre of pixel (`x`, `y`), scaled to a
    /// unit step along the view axis: the point seen there at view depth
    /// `d` is `eye + d × this`. No square root or division, for passes over
    /// many pixels that only need the points.
    pub fn pixel_depth_step(&self, x: u32, y: u32) -> Vec3 {
        let cx = (x as f32 + 0.5 - self.half_w) * self.pixel;
        let cy = (self.half_h - (y as f32 + 0.5)) * self.pixel;
        self.forward + self.right * cx + self.up * cy
    }

    /// See [`Camera::project`].
    pub fn project(&self, p: Vec3) -> Option<ScreenPoint> {
        let d = p - self.eye;
        let depth = d.dot(self.forward);
        if depth < NEAR {
            return None;
        }
        let k = self.inv_pixel / depth;
        Some(ScreenPoint {
            x: self.half_w + d.dot(self.right) * k,
            y: self.half_h - d.dot(self.up) * k,
            depth,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn camera() -> Camera {
        Camera {
            eye: Vec3::new(0.0, 1.0, 2.0),
            target: Vec3::new(0.3, 0.8, 0.0),
            up: Vec3::Y,
            fov_y_deg: 50.0,
            width: 64,
            height: 48,
        }
    }

    #[test]
    fn projecting_a_point_on_a_pixel_ray_gives_that_pixel_centre() {
        let cam = camera();
        for (x, y) in [(0, 0), (63, 47), (10, 30), (32, 24)] {
            let p = cam.eye + cam.pixel_ray(x, y) * 3.7;
            let s = cam.project(p).unwrap();
            assert!((s.x - (x as f32 + 0.5)).abs() < 1e-3, "{x} {y} {s:?}");
            assert!((s.y - (y as f32 + 0.5)).abs() < 1e-3, "{x} {y} {s:?}");
        }
    }

    #[test]
    fn a_pixel_depth_step_reaches_the_point_at_that_view_depth() {
        let cam = camera();
        let projector = Projector::new(&cam);
        for (x, y) in [(0, 0), (63, 47), (10, 30), (32, 24)] {
            let p = cam.eye + projector.pixel_depth_step(x, y) * 3.7;
            let s = cam.project(p).unwrap();
            assert!((s.depth - 3.7).abs() < 1e-5, "{x} {y} {s:?}");
            assert!((s.x - (x as f32 + 0.5)).abs() < 1e-3, "{x} {y} {s:?}");
            assert!((s.y - (y as f32 + 0.5)).abs() < 1e-3, "{x} {y} {s:?}");
        }
    }

    #[test]
    fn row_zero_is_the_top_row() {
        let cam = camera();
        let (_, _, up) = cam.basis();
        let above = cam.project(cam.target + up * 0.1).unwrap();
        let below = cam.project(cam.target - up * 0.1).unwrap();
        assert!(above.y < below.y);
    }

    #[test]
    fn points_behind_the_eye_do_not_project() {
        let cam = camera();
        assert!(cam.project(cam.eye - (cam.target - cam.eye)).is_none());
    }
}
