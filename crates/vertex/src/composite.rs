//! Compositing package results over the base frame, and the wireframe
//! overlay of refined faces (the paper's Figure 13).

use glam::{Vec2, Vec3};
use vtfarm_imaging::Image;
use vtfarm_scene::NONE;

use crate::fill::Planes;
use crate::{FinishedFace, PixelRect, PixelValue, SparseBitmap};

/// A frame being assembled: the base frame whose reflector pixels take the
/// traced colours, plus the per-pixel reflected component, reflected object
/// and reflector mask. Those component planes cover only the reflectors'
/// screen rectangle ([`crate::reflector_bounds`]), where every reflector
/// pixel lies; outside it a pixel reads as black, `NONE` and unmasked. They
/// start as zeroed allocations, so a frame touches only the reflectors'
/// pages of them: no full-frame pass and no full-frame first touch.
#[derive(Debug)]
pub struct FrameImage {
    pub color: Image,
    /// The rectangle the component planes cover.
    bounds: PixelRect,
    /// Over `bounds`; the reflected object is only meaningful where masked
    /// (it starts zeroed rather than `NONE`, which would cost a pass).
    components: Components,
}

/// A frame's per-pixel components over the whole frame: what the outputs
/// write and the wire carries ([`FrameImage::components`]).
#[derive(Debug, PartialEq)]
pub struct Components {
    /// The reflected component (black outside the reflectors).
    pub reflected: Image,
    /// The transmitted component: what is seen through the reflectors.
    pub transmitted: Image,
    /// The object each reflector pixel mirrors (`NONE` for nothing/elsewhere).
    pub reflected_object: Vec<u32>,
    /// Which pixels the traced bitmaps wrote.
    pub mask: Vec<bool>,
}

/// Field by field, so that [`Clone::clone_from`] copies into the
/// target's allocations (the view keeps a stage's frame so, without fresh
/// buffers' page faults).
impl Clone for FrameImage {
    fn clone(&self) -> Self {
        FrameImage {
            color: self.color.clone(),
            bounds: self.bounds,
            components: self.components.clone(),
        }
    }

    fn clone_from(&mut self, source: &Self) {
        self.color.clone_from(&source.color);
        self.bounds = source.bounds;
        self.components.clone_from(&source.components);
    }
}

impl Clone for Components {
    fn clone(&self) -> Self {
        Components {
            reflected: self.reflected.clone(),
            transmitted: self.transmitted.clone(),
            reflected_object: self.reflected_object.clone(),
            mask: self.mask.clone(),
        }
    }

    fn clone_from(&mut self, source: &Self) {
        self.reflected.clone_from(&source.reflected);
        self.transmitted.clone_from(&source.transmitted);
        self.reflected_object.clone_from(&source.reflected_object);
        self.mask.clone_from(&source.mask);
    }
}

impl FrameImage {
    /// Starts from the rasterized base frame, with component planes over
    /// `bounds` (cut to the frame; the reflectors' rectangle, see
    /// [`crate::reflector_bounds`] with no margin).
    pub fn new(base: Image, bounds: PixelRect) -> Self {
        let mut bounds = bounds.clamped(base.width, base.height);
        if bounds.is_empty() {
            bounds = PixelRect::full(0, 0);
        }
        let (width, height) = (bounds.x1 - bounds.x0, bounds.y1 - bounds.y0);
        let n = (width * height) as usize;
        FrameImage {
            bounds,
            components: Components {
                reflected: Image::black(width, height),
                transmitted: Image::black(width, height),
                reflected_object: vec![0; n],
                mask: vec![false; n],
            },
            color: base,
        }
    }

    /// A frame from full-frame components (as the wire carries them).
    /// `components` must be `color`'s size.
    pub fn from_components(color: Image, components: Components) -> Self {
        FrameImage {
            bounds: PixelRect::full(color.width, color.height),
            components,
            color,
        }
    }

    /// The components over the whole frame.
    pub fn components(&self) -> Components {
        let (width, height) = (self.color.width, self.color.height);
        let n = self.color.pixels.len();
        let mut full = Components {
            reflected: Image::black(width, height),
            transmitted: Image::black(width, height),
            reflected_object: vec![NONE; n],
            mask: vec![false; n],
        };
        for i in self.glass() {
            let value = self.pixel(i);
            full.reflected.pixels[i] = value.reflected;
            full.transmitted.pixels[i] = value.transmitted;
            full.reflected_object[i] = value.object;
            full.mask[i] = true;
        }
        full
    }

    /// The frame indices of the pixels the traced bitmaps wrote, row-major.
    pub fn glass(&self) -> impl Iterator<Item = usize> + '_ {
        let width = self.color.width as usize;
        let stride = (self.bounds.x1 - self.bounds.x0) as usize;
        let (x0, y0) = (self.bounds.x0 as usize, self.bounds.y0 as usize);
        let mask = &self.components.mask;
        (0..mask.len())
            .filter(move |&j| mask[j])
            .map(move |j| (y0 + j / stride) * width + x0 + j % stride)
    }

    /// Whether the traced bitmaps wrote pixel `i` (`y * width + x`).
    pub fn is_glass(&self, i: usize) -> bool {
        self.local(i).is_some_and(|j| self.components.mask[j])
    }

    /// Pixel `i`'s values (`y * width + x`); black and `NONE` where the
    /// traced bitmaps did not write.
    pub fn pixel(&self, i: usize) -> PixelValue {
        let mut value = PixelValue {
            index: i as u32,
            color: self.color.pixels[i],
            reflected: Vec3::ZERO,
            transmitted: Vec3::ZERO,
            object: NONE,
        };
        if let Some(j) = self.local(i).filter(|&j| self.components.mask[j]) {
            value.reflected = self.components.reflected.pixels[j];
            value.transmitted = self.components.transmitted.pixels[j];
            value.object = self.components.reflected_object[j];
        }
        value
    }

    /// Writes a pixel (at `value.index`), which must lie within the
    /// component planes' rectangle.
    pub fn set_pixel(&mut self, value: &PixelValue) {
        let i = value.index as usize;
        let j = self
            .local(i)
            .expect("a written pixel lies within the reflectors' bounds");
        self.color.pixels[i] = value.color;
        self.components.reflected.pixels[j] = value.reflected;
        self.components.transmitted.pixels[j] = value.transmitted;
        self.components.reflected_object[j] = value.object;
        self.components.mask[j] = true;
    }

    /// Where frame pixel `i` lies in the component planes, if inside.
    fn local(&self, i: usize) -> Option<usize> {
        let width = self.color.width as usize;
        let (x, y) = ((i % width) as u32, (i / width) as u32);
        let b = self.bounds;
        b.contains(x, y)
            .then(|| ((y - b.y0) * (b.x1 - b.x0) + (x - b.x0)) as usize)
    }

    /// The planes of rows `y0..y1` (cut to the component planes' rows),
    /// where a package writes its pixels.
    pub(crate) fn row_planes(&mut self, y0: u32, y1: u32) -> Planes<'_> {
        let b = self.bounds;
        let (y0, y1) = (y0.max(b.y0), y1.min(b.y1).max(y0.max(b.y0)));
        let width = self.color.width as usize;
        let stride = (b.x1 - b.x0) as usize;
        let rows = (y0 - b.y0) as usize * stride..(y1 - b.y0) as usize * stride;
        let c = &mut self.components;
        Planes {
            x0: b.x0,
            y0,
            stride,
            color_x0: 0,
            color_stride: width,
            color: &mut self.color.pixels[y0 as usize * width..y1 as usize * width],
            reflected: &mut c.reflected.pixels[rows.clone()],
            transmitted: &mut c.transmitted.pixels[rows.clone()],
            object: &mut c.reflected_object[rows.clone()],
            mask: &mut c.mask[rows],
        }
    }

    /// Writes a package's pixels over the frame. Packages own disjoint
    /// pixels, so the order of compositing does not matter.
    pub fn composite(&mut self, bitmap: &SparseBitmap) {
        for (x, y, k) in bitmap.covered() {
            self.set_pixel(&PixelValue {
                index: self.color.index(x, y) as u32,
                color: bitmap.color[k],
                reflected: bitmap.reflected[k],
                transmitted: bitmap.transmitted[k],
                object: bitmap.reflected_object[k],
            });
        }
    }
}

/// Frames are equal when their colours and full-frame components are,
/// whatever rectangles their planes cover.
impl PartialEq for FrameImage {
    fn eq(&self, other: &Self) -> bool {
        self.color == other.color && self.components() == other.components()
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Two pixels of a 4x3 frame, at (1, 1) and (2, 1).
    fn bitmap() -> SparseBitmap {
        SparseBitmap {
            x0: 1,
            y0: 1,
            width: 2,
            height: 1,
            mask: vec![true, true],
            color: vec![Vec3::X, Vec3::Y],
            reflected: vec![Vec3::splat(0.25), Vec3::splat(0.5)],
            transmitted: vec![Vec3::Z, Vec3::ONE],
            reflected_object: vec![NONE, 7],
        }
    }

    #[test]
    fn planes_over_the_bounds_give_what_full_frame_planes_give() {
        let base = Image::new(4, 3, Vec3::splat(0.1));
        let bounds = PixelRect {
            x0: 1,
            y0: 1,
            x1: 3,
            y1: 2,
        };
        let mut small = FrameImage::new(base.clone(), bounds);
        let mut full = FrameImage::new(base.clone(), PixelRect::full(4, 3));
        small.composite(&bitmap());
        full.composite(&bitmap());
        assert_eq!(small.components(), full.components());
        assert!(small == full);
        assert_eq!(small.glass().collect::<Vec<_>>(), [5, 6]);
        assert_eq!(small.pixel(6).object, 7);
        assert_eq!(small.pixel(6).reflected, Vec3::splat(0.5));
        // Outside the bounds, and unwritten pixels: black, NONE, unmasked.
        for i in [0, 4, 7, 11] {
            assert!(!small.is_glass(i));
            let p = small.pixel(i);
            assert_eq!(
                (p.color, p.reflected, p.transmitted, p.object),
                (Vec3::splat(0.1), Vec3::ZERO, Vec3::ZERO, NONE)
            );
        }
        let components = small.components();
        assert_eq!(components.reflected.pixels.len(), 12);
        assert_eq!(components.reflected_object[4], NONE);
        assert_eq!(components.reflected_object[5], NONE);
        // A frame without reflectors has no planes and no glass.
        let empty = FrameImage::new(base, PixelRect::full(0, 0));
        assert_eq!(empty.glass().count(), 0);
        assert_eq!(
            empty.components(),
            FrameImage::new(empty.color.clone(), PixelRect::full(4, 3)).components()
        );
    }

    #[test]
    fn row_planes_are_cut_to_the_bounds() {
        let bounds = PixelRect {
            x0: 1,
            y0: 1,
            x1: 3,
            y1: 2,
        };
        let mut image = FrameImage::new(Image::black(4, 3), bounds);
        let mut planes = image.row_planes(0, 3);
        assert_eq!(planes.rows(), (1, 2));
        planes.set(
            2,
            1,
            &PixelValue {
                index: 6,
                color: Vec3::X,
                reflected: Vec3::Y,
                transmitted: Vec3::Z,
                object: 3,
            },
        );
        assert_eq!(image.pixel(6).object, 3);
        assert_eq!(image.color.pixels[6], Vec3::X);
        assert_eq!(image.glass().collect::<Vec<_>>(), [6]);
    }
}
