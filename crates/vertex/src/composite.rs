//! Compositing package results over the base frame, and the wireframe
//! overlay of refined faces (the paper's Figure 13).

use glam::{Vec2, Vec3};
use vtfarm_imaging::Image;
use vtfarm_scene::NONE;

use crate::fill::Planes;
use crate::{FinishedFace, SparseBitmap};

/// A frame being assembled: the base frame whose reflector pixels take the
/// traced colours, plus the per-pixel reflected component, reflected object
/// and reflector mask.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameImage {
    pub color: Image,
    /// The reflected component (black outside the reflectors).
    pub reflected: Image,
    /// The transmitted component: what is seen through the reflectors.
    pub transmitted: Image,
    /// The object each reflector pixel mirrors (`NONE` for nothing/elsewhere).
    pub reflected_object: Vec<u32>,
    /// Which pixels the traced bitmaps wrote.
    pub mask: Vec<bool>,
}

impl FrameImage {
    /// Starts from the rasterized base frame. The reflector planes are
    /// zeroed allocations (see [`Image::black`]): compositing touches only
    /// the reflectors' pages, so a frame costs no full-frame pass here.
    pub fn new(base: Image) -> Self {
        let n = base.pixels.len();
        FrameImage {
            reflected: Image::black(base.width, base.height),
            transmitted: Image::black(base.width, base.height),
            reflected_object: vec![NONE; n],
            mask: vec![false; n],
            color: base,
        }
    }

    /// The planes of rows `y0..y1`, where a package writes its pixels.
    pub(crate) fn row_planes(&mut self, y0: u32, y1: u32) -> Planes<'_> {
        let width = self.color.width as usize;
        let rows = y0 as usize * width..y1 as usize * width;
        Planes {
            x0: 0,
            y0,
            stride: width,
            color: &mut self.color.pixels[rows.clone()],
            reflected: &mut self.reflected.pixels[rows.clone()],
            transmitted: &mut self.transmitted.pixels[rows.clone()],
            object: &mut self.reflected_object[rows.clone()],
            mask: &mut self.mask[rows],
        }
    }

    /// Writes a package's pixels over the frame. Packages own disjoint
    /// pixels, so the order of compositing does not matter.
    pub fn composite(&mut self, bitmap: &SparseBitmap) {
        for (x, y, k) in bitmap.covered() {
            let i = self.color.index(x, y);
            self.color.pixels[i] = bitmap.color[k];
            self.reflected.pixels[i] = bitmap.reflected[k];
            self.transmitted.pixels[i] = bitmap.transmitted[k];
            self.reflected_object[i] = bitmap.reflected_object[k];
            self.mask[i] = true;
        }
    }
}

/// Draws the edges of `faces` onto `image` in `color` (one-pixel lines).
pub fn draw_wireframe(image: &mut Image, faces: &[FinishedFace], color: Vec3) {
    for face in faces {
        let p = face.corners.map(|c| Vec2::new(c.x, c.y));
        for (a, b) in [(p[0], p[1]), (p[1], p[2]), (p[2], p[0])] {
            draw_line(image, a, b, color);
        }
    }
}

fn draw_line(image: &mut Image, a: Vec2, b: Vec2, color: Vec3) {
    let steps = (b - a).abs().max_element().ceil().max(1.0) as u32;
    for i in 0..=steps {
        let p = a.lerp(b, i as f32 / steps as f32);
        if p.x >= 0.0 && p.y >= 0.0 && (p.x as u32) < image.width && (p.y as u32) < image.height {
            image.set(p.x as u32, p.y as u32, color);
        }
    }
}
