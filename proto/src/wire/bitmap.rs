//! A package's result on the wire: the bitmap codec ([`WireBitmap`], a
//! `SparseBitmap` packed and compressed, lossless).

use glam::Vec3;
use serde::{Deserialize, Serialize};
use vtfarm_scene::MAX_IMAGE_SIDE;
use vtfarm_vertex::SparseBitmap;

use super::planes::{byte_planes, compress, decompress};
use super::{WireError, finite3, out_of_range};

/// Which per-pixel arrays of a [`SparseBitmap`] travel: the colour always,
/// the components (reflected, transmitted, reflected object) only when the
/// job asks for them (`FrameStart::aux`), since they triple the bytes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum WireBitmapParts {
    Color,
    #[default]
    All,
}

/// [`SparseBitmap`] on the wire, compact and lossless: the rectangle; the
/// coverage mask packed eight pixels a byte (row-major within the rectangle,
/// least significant bit first, unused high bits of the last byte zero), then
/// zstd-compressed; and the covered pixels' arrays (in [`WireBitmapParts`])
/// as little-endian byte planes — byte k of every value, then byte k + 1 …
/// — zstd-compressed. Byte planes put the slowly varying sign and exponent
/// bytes of neighbouring pixels side by side, which is what makes float
/// colours compress. Both decompress into exactly the size the rectangle and
/// the mask imply, so hostile input cannot make the receiver allocate more.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct WireBitmap {
    pub x0: u32,
    pub y0: u32,
    pub width: u32,
    pub height: u32,
    pub parts: WireBitmapParts,
    #[serde(with = "crate::message::bytes")]
    pub mask: Vec<u8>,
    #[serde(with = "crate::message::bytes")]
    pub pixels: Vec<u8>,
}

impl From<&SparseBitmap> for WireBitmap {
    fn from(b: &SparseBitmap) -> Self {
        WireBitmap::encode(b, WireBitmapParts::All)
    }
}

impl WireBitmap {
    /// Encodes `parts` of a bitmap.
    pub fn encode(b: &SparseBitmap, parts: WireBitmapParts) -> Self {
        let mut mask = vec![0u8; b.mask.len().div_ceil(8)];
        for (i, _) in b.mask.iter().enumerate().filter(|(_, m)| **m) {
            mask[i / 8] |= 1 << (i % 8);
        }
        let mut values: Vec<[u8; 4]> = Vec::new();
        let mut colors = |v: &[Vec3]| {
            values.extend(v.iter().flat_map(|c| c.to_array()).map(f32::to_le_bytes));
        };
        colors(&b.color);
        if parts == WireBitmapParts::All {
            colors(&b.reflected);
            colors(&b.transmitted);
            values.extend(b.reflected_object.iter().map(|o| o.to_le_bytes()));
        }
        let planes = byte_planes(&values);
        WireBitmap {
            x0: b.x0,
            y0: b.y0,
            width: b.width,
            height: b.height,
            parts,
            mask: compress(&mask),
            pixels: compress(&planes),
        }
    }

    /// Converts like `TryFrom`, and also checks that the rectangle lies
    /// inside a `width` × `height` frame, as compositing requires.
    pub fn into_bitmap_within(self, width: u32, height: u32) -> Result<SparseBitmap, WireError> {
        self.check_within(width, height)?;
        self.try_into()
    }

    /// Whether the rectangle lies inside a `width` × `height` frame.
    fn check_within(&self, width: u32, height: u32) -> Result<(), WireError> {
        // u64: the sums cannot overflow.
        let (x_end, y_end) = (
            u64::from(self.x0) + u64::from(self.width),
            u64::from(self.y0) + u64::from(self.height),
        );
        if x_end > width.into() || y_end > height.into() {
            return Err(out_of_range(
                "bitmap rectangle",
                format!("({}, {}) {}x{}", self.x0, self.y0, self.width, self.height),
                "inside the frame",
            ));
        }
        Ok(())
    }
}

/// A [`WireBitmap`]'s checked and decompressed parts.
struct DecodedBitmap {
    /// The coverage bits, eight pixels a byte, padding checked to be zero.
    mask: Vec<u8>,
    /// Pixels of the rectangle.
    area: usize,
    /// Covered pixels.
    covered: usize,
    /// Values (each four bytes, one byte per plane) of the covered pixels.
    values: usize,
    planes: Vec<u8>,
}

impl DecodedBitmap {
    /// Whether pixel `i` of the rectangle is covered.
    fn is_covered(&self, i: usize) -> bool {
        self.mask[i / 8] >> (i % 8) & 1 == 1
    }

    /// Value `i`'s four bytes, one from each plane.
    fn value(&self, i: usize) -> [u8; 4] {
        [0, 1, 2, 3].map(|k| self.planes[k * self.values + i])
    }

    /// Covered pixel `p`'s colour of the component whose values start at
    /// `first`, checked finite.
    fn color(&self, field: &str, first: usize, p: usize) -> Result<Vec3, WireError> {
        let c = [0, 1, 2].map(|c| f32::from_le_bytes(self.value(first + 3 * p + c)));
        finite3(|| format!("{field}[{p}]"), c)
    }
}

impl WireBitmap {
    /// The rectangle checked to fit the coordinate type, the mask and the
    /// byte planes decompressed into exactly the sizes they imply.
    fn decode(&self) -> Result<DecodedBitmap, WireError> {
        // Both ends of the rectangle must fit the frame's coordinate type.
        for (field, start, size) in [
            ("bitmap x", self.x0, self.width),
            ("bitmap y", self.y0, self.height),
        ] {
            if start
                .checked_add(size)
                .is_none_or(|end| end > MAX_IMAGE_SIDE)
            {
                return Err(out_of_range(
                    field,
                    format!("{start} + {size}"),
                    "within 16384 pixels",
                ));
            }
        }
        let area = self.width as usize * self.height as usize;
        let mask = decompress("bitmap mask bytes", &self.mask, area.div_ceil(8))?;
        if area % 8 != 0 && mask.last().is_some_and(|&b| b >> (area % 8) != 0) {
            return Err(out_of_range(
                "bitmap mask padding",
                "set bits",
                "zero past the last pixel",
            ));
        }
        let covered: usize = mask.iter().map(|b| b.count_ones() as usize).sum();
        let values_per_pixel = match self.parts {
            WireBitmapParts::Color => 3,
            WireBitmapParts::All => 10,
        };
        let values = covered * values_per_pixel;
        let planes = decompress("bitmap pixel bytes", &self.pixels, values * 4)?;
        Ok(DecodedBitmap {
            mask,
            area,
            covered,
            values,
            planes,
        })
    }

    /// The covered pixels' colours with their indices in a `width`-wide
    /// frame (`y * width + x`), in the order of the mask, decoded straight
    /// from the wire for compositing the colour alone (the components, if
    /// sent, are skipped); the rectangle must lie inside the `width` ×
    /// `height` frame. The same checks as the conversion to
    /// [`SparseBitmap`], without building one.
    pub fn colors_within(&self, width: u32, height: u32) -> Result<Vec<(usize, Vec3)>, WireError> {
        self.check_within(width, height)?;
        let decoded = self.decode()?;
        let mut colors = Vec::with_capacity(decoded.covered);
        for i in (0..decoded.area).filter(|&i| decoded.is_covered(i)) {
            let p = colors.len();
            let (x, y) = (
                self.x0 as usize + i % self.width as usize,
                self.y0 as usize + i / self.width as usize,
            );
            colors.push((y * width as usize + x, decoded.color("bitmap color", 0, p)?));
        }
        Ok(colors)
    }
}

impl TryFrom<WireBitmap> for SparseBitmap {
    type Error = WireError;

    fn try_from(w: WireBitmap) -> Result<Self, WireError> {
        let decoded = w.decode()?;
        let covered = decoded.covered;
        let colors = |field: &'static str, first: usize| {
            (0..covered)
                .map(|p| decoded.color(field, first, p))
                .collect::<Result<Vec<_>, _>>()
        };
        let color = colors("bitmap color", 0)?;
        let (reflected, transmitted, reflected_object) = match w.parts {
            WireBitmapParts::Color => (
                vec![Vec3::ZERO; covered],
                vec![Vec3::ZERO; covered],
                vec![vtfarm_scene::NONE; covered],
            ),
            WireBitmapParts::All => (
                colors("bitmap reflected", 3 * covered)?,
                colors("bitmap transmitted", 6 * covered)?,
                (0..covered)
                    .map(|p| u32::from_le_bytes(decoded.value(9 * covered + p)))
                    .collect(),
            ),
        };
        Ok(SparseBitmap {
            x0: w.x0,
            y0: w.y0,
            width: w.width,
            height: w.height,
            mask: (0..decoded.area).map(|i| decoded.is_covered(i)).collect(),
            color,
            reflected,
            transmitted,
            reflected_object,
        })
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec3;
    use proptest::prelude::*;
    use vtfarm_vertex::SparseBitmap;

    use super::*;
    use crate::wire::planes::compress;
    use crate::wire::tests::{any_f32, bitmap, check_rejects, round_trip};

    #[test]
    fn bitmaps_round_trip_with_packed_masks() {
        let b = bitmap();
        let wire = WireBitmap::from(&b);
        assert_eq!(
            zstd::bulk::decompress(&wire.mask, 2).expect("zstd"),
            vec![0b1100_0001, 0b0100_0000]
        );
        assert_eq!(round_trip::<SparseBitmap, WireBitmap>(&b), b);
        assert_eq!(
            wire.into_bitmap_within(8, 5).expect("fits exactly"),
            bitmap()
        );
        let empty = SparseBitmap::default();
        assert_eq!(round_trip::<SparseBitmap, WireBitmap>(&empty), empty);
    }

    #[test]
    fn color_only_bitmaps_leave_the_components_empty() {
        let b = bitmap();
        let wire = WireBitmap::encode(&b, WireBitmapParts::Color);
        assert!(wire.pixels.len() < WireBitmap::from(&b).pixels.len());
        let back = SparseBitmap::try_from(wire).expect("valid");
        assert_eq!((&back.mask, &back.color), (&b.mask, &b.color));
        assert_eq!(back.reflected, vec![Vec3::ZERO; 4]);
        assert_eq!(back.transmitted, vec![Vec3::ZERO; 4]);
        assert_eq!(back.reflected_object, vec![vtfarm_scene::NONE; 4]);
    }

    /// The colours alone, straight from the wire: each covered pixel's
    /// index in the frame with its colour, whichever parts were sent.
    #[test]
    fn colors_come_straight_from_the_wire_with_frame_indices() {
        let b = bitmap();
        let expected: Vec<(usize, Vec3)> = (b.covered())
            .map(|(x, y, k)| ((y * 9 + x) as usize, b.color[k]))
            .collect();
        assert_eq!(expected.len(), 4);
        for parts in [WireBitmapParts::Color, WireBitmapParts::All] {
            let wire = WireBitmap::encode(&b, parts);
            assert_eq!(wire.colors_within(9, 5).expect("inside"), expected);
            let error = wire.colors_within(7, 5).expect_err("one column short");
            assert!(error.to_string().contains("inside the frame"), "{error}");
        }
    }

    #[test]
    fn smooth_colors_compress() {
        // A 200 x 100 gradient, like a reflection: the byte planes compress.
        let (width, height) = (200u32, 100u32);
        let n = (width * height) as usize;
        let shade = |i: usize| Vec3::new(0.2 + i as f32 * 1e-5, 0.3, 0.4 - i as f32 * 1e-5);
        let b = SparseBitmap {
            x0: 0,
            y0: 0,
            width,
            height,
            mask: vec![true; n],
            color: (0..n).map(shade).collect(),
            reflected: (0..n).map(shade).collect(),
            transmitted: vec![Vec3::splat(0.1); n],
            reflected_object: vec![3; n],
        };
        let raw = n * 40;
        let wire = WireBitmap::from(&b);
        assert!(
            wire.pixels.len() * 2 < raw,
            "{} of {raw}",
            wire.pixels.len()
        );
        assert_eq!(SparseBitmap::try_from(wire).expect("valid"), b);
    }

    #[test]
    fn hostile_bitmaps_are_rejected() {
        let valid = WireBitmap::from(&bitmap());
        let check = |damage: fn(&mut WireBitmap), expected| {
            check_rejects::<WireBitmap, SparseBitmap>(&valid, damage, expected)
        };
        check(
            |b| b.mask = zstd::bulk::compress(&[0b1100_0001, 0, 0], 1).expect("zstd"),
            "bitmap mask bytes",
        );
        check(
            |b| b.mask = zstd::bulk::compress(&[0b1100_0001, 0b1100_0000], 1).expect("zstd"),
            "bitmap mask padding",
        );
        check(
            |b| b.mask = zstd::bulk::compress(&[0b1100_0011, 0b0100_0000], 1).expect("zstd"),
            "bitmap pixel bytes",
        );
        check(|b| b.mask = vec![1, 2, 3], "bitmap mask bytes");
        check(|b| b.pixels.truncate(5), "bitmap pixel bytes");
        check(|b| b.parts = WireBitmapParts::Color, "bitmap pixel bytes");
        check(
            |b| {
                let mut bad = bitmap();
                bad.color[3].y = f32::NEG_INFINITY;
                *b = WireBitmap::from(&bad);
            },
            "bitmap color[3] is not finite",
        );
        check(|b| b.x0 = u32::MAX, "bitmap x");
        check(|b| (b.width, b.height) = (u32::MAX, u32::MAX), "bitmap x");
        let outside = valid
            .clone()
            .into_bitmap_within(7, 5)
            .expect_err("one column short");
        assert!(
            outside.to_string().contains("inside the frame"),
            "{outside}"
        );
    }

    prop_compose! {
        fn any_bitmap()(
            x0 in prop_oneof![0u32..20, Just(u32::MAX)],
            y0 in 0u32..20,
            width in prop_oneof![0u32..20, Just(u32::MAX)],
            height in 0u32..20,
            all in any::<bool>(),
            mask in proptest::collection::vec(any::<u8>(), 0..8),
            colors in proptest::collection::vec(any_f32(), 0..300),
            compressed in any::<bool>(),
        ) -> WireBitmap {
            let parts = if all { WireBitmapParts::All } else { WireBitmapParts::Color };
            let planes: Vec<u8> = colors.iter().flat_map(|c| c.to_le_bytes()).collect();
            // Well-formed zstd of arbitrary content, or arbitrary bytes.
            let pack = |b: &[u8]| if compressed { compress(b) } else { b.to_vec() };
            WireBitmap { x0, y0, width, height, parts, mask: pack(&mask), pixels: pack(&planes) }
        }
    }

    proptest! {
        #[test]
        fn hostile_bitmaps_never_panic(b in any_bitmap(), w in 0u32..40, h in 0u32..40) {
            let accepted = SparseBitmap::try_from(b.clone());
            if let Ok(bitmap) = &accepted {
                // Whatever is accepted is self-consistent.
                prop_assert_eq!(bitmap.mask.len(), (bitmap.width * bitmap.height) as usize);
                prop_assert_eq!(bitmap.covered().count(), bitmap.color.len());
            }
            // Compositing the colour straight from the wire accepts the
            // same results and gives the same pixels.
            let colors = b.colors_within(w, h);
            match b.into_bitmap_within(w, h) {
                Ok(bitmap) => {
                    let expected: Vec<(usize, Vec3)> = (bitmap.covered())
                        .map(|(x, y, k)| ((y * w + x) as usize, bitmap.color[k]))
                        .collect();
                    prop_assert_eq!(colors.expect("accepted as a bitmap"), expected);
                }
                Err(_) => prop_assert!(colors.is_err()),
            }
        }
    }
}
