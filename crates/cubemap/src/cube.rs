//! Cube-map geometry shared by the reflector maps and the environment map:
//! face bases, direction ↔ texel coordinates, texels across face seams and
//! bilinear taps.
//!
//! A face is a 90° square [`Camera`] looking from the centre along the face
//! axis, so face texel (i, j) is exactly that camera's pixel (x = i, y = j)
//! and the rasterizer can render faces directly (environment map).

use glam::Vec3;
use vtfarm_scene::Camera;

/// The faces in order +X, -X, +Y, -Y, +Z, -Z as (forward, up).
const FACE_AXES: [(Vec3, Vec3); 6] = [
    (Vec3::X, Vec3::Y),
    (Vec3::NEG_X, Vec3::Y),
    (Vec3::Y, Vec3::Z),
    (Vec3::NEG_Y, Vec3::NEG_Z),
    (Vec3::Z, Vec3::Y),
    (Vec3::NEG_Z, Vec3::Y),
];

/// One face's orthonormal basis, as `Camera::basis` derives it.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Face {
    pub(crate) forward: Vec3,
    pub(crate) right: Vec3,
    pub(crate) up: Vec3,
}

pub(crate) fn face(index: usize) -> Face {
    let (forward, up) = FACE_AXES[index];
    Face {
        forward,
        right: forward.cross(up),
        up,
    }
}

/// Where a cube map sits and how fine it is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CubeLayout {
    pub centre: Vec3,
    /// Texels per face side.
    pub resolution: u32,
}

/// Continuous texel coordinates on one face: texel (i, j) covers
/// [i, i+1) × [j, j+1), row 0 at the face's top.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct TexelPoint {
    pub(crate) face: usize,
    pub(crate) s: f32,
    pub(crate) t: f32,
}

impl CubeLayout {
    pub(crate) fn texel_count(&self) -> usize {
        6 * (self.resolution * self.resolution) as usize
    }

    /// The (unnormalised) direction through continuous coordinates (`s`,
    /// `t`) of `face`; coordinates beyond the face extend its plane.
    pub(crate) fn direction(&self, face_index: usize, s: f32, t: f32) -> Vec3 {
        let f = face(face_index);
        let half = self.resolution as f32 * 0.5;
        f.forward + f.right * (s / half - 1.0) + f.up * (1.0 - t / half)
    }

    /// The direction through the centre of texel `index`.
    pub(crate) fn texel_direction(&self, index: usize) -> Vec3 {
        let (face_index, i, j) = self.texel_coordinates(index);
        self.direction(face_index, i as f32 + 0.5, j as f32 + 0.5)
    }

    /// The face and continuous coordinates a direction points at.
    pub(crate) fn locate(&self, direction: Vec3) -> TexelPoint {
        let a = direction.abs();
        let face_index = if a.x >= a.y && a.x >= a.z {
            usize::from(direction.x < 0.0)
        } else if a.y >= a.z {
            2 + usize::from(direction.y < 0.0)
        } else {
            4 + usize::from(direction.z < 0.0)
        };
        let f = face(face_index);
        let depth = direction.dot(f.forward).max(f32::MIN_POSITIVE);
        let res = self.resolution as f32;
        let half = res * 0.5;
        let s = (direction.dot(f.right) / depth + 1.0) * half;
        let t = (1.0 - direction.dot(f.up) / depth) * half;
        TexelPoint {
            face: face_index,
            s: s.clamp(0.0, res),
            t: t.clamp(0.0, res),
        }
    }

    pub(crate) fn texel_index(&self, face_index: usize, i: u32, j: u32) -> usize {
        let res = self.resolution as usize;
        (face_index * res + j as usize) * res + i as usize
    }

    pub(crate) fn texel_coordinates(&self, index: usize) -> (usize, u32, u32) {
        let res = self.resolution as usize;
        let face_index = index / (res * res);
        let rest = index % (res * res);
        (face_index, (rest % res) as u32, (rest / res) as u32)
    }

    /// Texel (`i`, `j`) of `face`; indices just beyond the face wrap onto the
    /// neighbouring face (the texel that direction falls in).
    pub(crate) fn texel_wrapped(&self, face_index: usize, i: i64, j: i64) -> usize {
        let res = i64::from(self.resolution);
        if (0..res).contains(&i) && (0..res).contains(&j) {
            return self.texel_index(face_index, i as u32, j as u32);
        }
        let d = self.direction(face_index, i as f32 + 0.5, j as f32 + 0.5);
        self.nearest(self.locate(d))
    }

    /// The texel containing a point.
    pub(crate) fn nearest(&self, p: TexelPoint) -> usize {
        let last = self.resolution - 1;
        let i = (p.s as u32).min(last);
        let j = (p.t as u32).min(last);
        self.texel_index(p.face, i, j)
    }

    /// The four texels around a point with their bilinear weights (texel
    /// values sit at texel centres).
    pub(crate) fn bilinear(&self, p: TexelPoint) -> [(usize, f32); 4] {
        let (s, t) = (p.s - 0.5, p.t - 0.5);
        let (i0, j0) = (s.floor(), t.floor());
        let (fx, fy) = (s - i0, t - j0);
        let (i0, j0) = (i0 as i64, j0 as i64);
        let tap = |di: i64, dj: i64| self.texel_wrapped(p.face, i0 + di, j0 + dj);
        [
            (tap(0, 0), (1.0 - fx) * (1.0 - fy)),
            (tap(1, 0), fx * (1.0 - fy)),
            (tap(0, 1), (1.0 - fx) * fy),
            (tap(1, 1), fx * fy),
        ]
    }

    /// The square 90° camera that renders `face` with texel (i, j) as
    /// pixel (i, j).
    pub(crate) fn camera(&self, face_index: usize) -> Camera {
        let f = face(face_index);
        Camera {
            eye: self.centre,
            target: self.centre + f.forward,
            up: f.up,
            fov_y_deg: 90.0,
            width: self.resolution,
            height: self.resolution,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const LAYOUT: CubeLayout = CubeLayout {
        centre: Vec3::new(0.5, -1.0, 2.0),
        resolution: 16,
    };

    #[test]
    fn locating_a_texel_direction_gives_that_texel() {
        for index in 0..LAYOUT.texel_count() {
            let p = LAYOUT.locate(LAYOUT.texel_direction(index));
            assert_eq!(LAYOUT.nearest(p), index, "{p:?}");
        }
    }

    #[test]
    fn face_texels_are_the_face_cameras_pixels() {
        for face_index in 0..6 {
            let camera = LAYOUT.camera(face_index);
            for (i, j) in [(0, 0), (15, 3), (7, 12)] {
                let index = LAYOUT.texel_index(face_index, i, j);
                let ours = LAYOUT.texel_direction(index).normalize();
                let theirs = camera.pixel_ray(i, j);
                assert!((ours - theirs).length() < 1e-5, "{ours} vs {theirs}");
            }
        }
    }

    #[test]
    fn texels_beyond_an_edge_are_the_neighbouring_faces_texels() {
        // One beyond +X's right edge lies on the face the right axis points to.
        let index = LAYOUT.texel_wrapped(0, 16, 8);
        let d = LAYOUT.texel_direction(index).normalize();
        let (face_index, _, _) = LAYOUT.texel_coordinates(index);
        assert_ne!(face_index, 0);
        assert!(d.dot(face(0).right) > 0.7, "{d}");
    }
}
