//! A finished frame on the wire: the image codec ([`WireImage`], linear
//! f32 byte planes or the PNG's sRGB bytes, compressed) and a frame's
//! components (`WireFrameAux`).

use glam::Vec3;
use serde::{Deserialize, Serialize};
use vtfarm_scene::MAX_IMAGE_SIDE;
use vtfarm_vertex::{Components, FrameImage};

use super::planes::{byte_planes, compress, decompress, pixel_planes_into};
use super::{WireError, finite3, out_of_range};

/// How a [`WireImage`] codes its pixels: what the job's outputs need
/// (`WireJob::image`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum WireImageFormat {
    /// Linear RGB f32, lossless: for `.npy` files, error figures and the
    /// components.
    #[default]
    LinearF32,
    /// 8-bit sRGB, [`vtfarm_imaging::encode_srgb8`] of every pixel: exactly
    /// what a PNG of the frame holds, for a job that writes only PNGs.
    Srgb8,
}

/// A finished frame (row 0 at the top, row-major) in a
/// [`WireImageFormat`]: linear f32 channels as little-endian byte planes
/// (as in [`WireBitmap`](super::WireBitmap)), or sRGB bytes, RGB interleaved; zstd-compressed
/// either way. The master encodes a finished frame once and the same bytes
/// go to the submitter and the journal (a 1080p frame is 25 MB of floats
/// before compression, a few MB as sRGB after). The submitter decides on
/// PNG or NPY, since sRGB happens only in vtfarm-imaging. Decoding
/// decompresses into exactly the size the sides imply, so hostile input
/// cannot make the receiver allocate more.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct WireImage {
    pub width: u32,
    pub height: u32,
    pub format: WireImageFormat,
    #[serde(with = "crate::message::bytes")]
    pub pixels: Vec<u8>,
}

impl WireImage {
    /// The wire form of a `width` × `height` linear image, lossless.
    pub fn from_pixels(width: u32, height: u32, pixels: &[Vec3]) -> Self {
        let mut planes = Vec::new();
        pixel_planes_into(pixels, &mut planes);
        WireImage::from_uncompressed(width, height, WireImageFormat::LinearF32, &planes)
    }

    /// The wire form of `image` in `format`.
    pub fn encode(image: &vtfarm_imaging::Image, format: WireImageFormat) -> Self {
        WireImage::encode_reusing(image, format, &mut Vec::new())
    }

    /// [`WireImage::encode`] with the uncompressed bytes in `scratch`
    /// (whatever it held): a buffer kept from frame to frame spares a
    /// fresh one's page faults (6 MB of sRGB, 25 MB of floats at 1080p).
    pub fn encode_reusing(
        image: &vtfarm_imaging::Image,
        format: WireImageFormat,
        scratch: &mut Vec<u8>,
    ) -> Self {
        match format {
            WireImageFormat::LinearF32 => pixel_planes_into(&image.pixels, scratch),
            // On every core of the calling pool (`Image::to_srgb8_into`).
            WireImageFormat::Srgb8 => image.to_srgb8_into(scratch),
        }
        WireImage::from_uncompressed(image.width, image.height, format, scratch)
    }

    /// The wire form of a `width` × `height` image whose uncompressed
    /// bytes in `format` the caller made (as [`WireImage::encode_reusing`]
    /// makes them: a master that converted a frame's base to sRGB ahead
    /// converts only what changed since): compressed as one zstd frame.
    ///
    /// # Panics
    /// If `bytes` is not `format`'s size for the sides.
    pub fn from_uncompressed(
        width: u32,
        height: u32,
        format: WireImageFormat,
        bytes: &[u8],
    ) -> Self {
        let per_pixel = match format {
            WireImageFormat::LinearF32 => 12,
            WireImageFormat::Srgb8 => 3,
        };
        assert_eq!(
            bytes.len(),
            per_pixel * width as usize * height as usize,
            "{format:?} bytes of a {width}x{height} image"
        );
        WireImage {
            width,
            height,
            format,
            pixels: compress(bytes),
        }
    }

    /// The pixel count, with the sides checked.
    fn pixel_count(&self) -> Result<usize, WireError> {
        for (field, side) in [("image width", self.width), ("image height", self.height)] {
            if side > MAX_IMAGE_SIDE {
                return Err(out_of_range(field, side, "0 to 16384"));
            }
        }
        Ok(self.width as usize * self.height as usize)
    }

    /// The validated linear pixels: sizes in range, `width * height` of
    /// them, all finite. An sRGB image is refused: its linear colours are
    /// lost (the job asked for sRGB).
    pub fn into_pixels(self) -> Result<(u32, u32, Vec<Vec3>), WireError> {
        let n = self.pixel_count()?;
        if self.format != WireImageFormat::LinearF32 {
            return Err(out_of_range(
                "image format",
                format!("{:?}", self.format),
                "LinearF32 where linear colours are needed",
            ));
        }
        let values = 3 * n;
        let planes = decompress("image pixel bytes", &self.pixels, 4 * values)?;
        let value = |i: usize| f32::from_le_bytes([0, 1, 2, 3].map(|k| planes[k * values + i]));
        let pixels = (0..n)
            .map(|i| {
                let p = [value(3 * i), value(3 * i + 1), value(3 * i + 2)];
                finite3(|| format!("image pixel {i}"), p)
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok((self.width, self.height, pixels))
    }

    /// The 8-bit sRGB pixels (RGB interleaved), `width * height * 3` of
    /// them: as sent, or encoded here from linear ones.
    pub fn into_srgb8(self) -> Result<(u32, u32, Vec<u8>), WireError> {
        let n = self.pixel_count()?;
        match self.format {
            WireImageFormat::Srgb8 => {
                let bytes = decompress("image pixel bytes", &self.pixels, 3 * n)?;
                Ok((self.width, self.height, bytes))
            }
            WireImageFormat::LinearF32 => {
                let (width, height, pixels) = self.into_pixels()?;
                let image = vtfarm_imaging::Image {
                    width,
                    height,
                    pixels,
                };
                Ok((width, height, image.to_srgb8()))
            }
        }
    }
}

impl crate::WireFrameAux {
    /// The wire form of a frame's components (its colour travels apart, in
    /// `FrameDone::image`).
    pub fn encode(image: &FrameImage) -> Self {
        let image = image.components();
        let objects: Vec<[u8; 4]> = image
            .reflected_object
            .iter()
            .map(|o| o.to_le_bytes())
            .collect();
        let mask: Vec<u8> = image.mask.iter().map(|&m| u8::from(m)).collect();
        crate::WireFrameAux {
            reflected: WireImage::encode(&image.reflected, WireImageFormat::LinearF32),
            transmitted: WireImage::encode(&image.transmitted, WireImageFormat::LinearF32),
            reflected_object: compress(&byte_planes(&objects)),
            mask: compress(&mask),
        }
    }

    /// The frame with its components, every array checked to hold one
    /// entry per pixel of `color`.
    pub fn into_components(self, color: vtfarm_imaging::Image) -> Result<FrameImage, WireError> {
        let n = color.pixels.len();
        let component = |field: &str, image: WireImage| {
            let (width, height, pixels) = image.into_pixels()?;
            if (width, height) != (color.width, color.height) {
                return Err(out_of_range(
                    field,
                    format!("{width}x{height}"),
                    "the frame's size",
                ));
            }
            Ok(vtfarm_imaging::Image {
                width,
                height,
                pixels,
            })
        };
        let reflected = component("reflected component", self.reflected)?;
        let transmitted = component("transmitted component", self.transmitted)?;
        let planes = decompress("reflected object bytes", &self.reflected_object, 4 * n)?;
        let reflected_object = (0..n)
            .map(|i| u32::from_le_bytes([0, 1, 2, 3].map(|k| planes[k * n + i])))
            .collect();
        let mask = decompress("mask bytes", &self.mask, n)?;
        if let Some(i) = mask.iter().position(|&m| m > 1) {
            return Err(out_of_range(
                "mask",
                format!("{} at pixel {i}", mask[i]),
                "0 or 1",
            ));
        }
        let components = Components {
            reflected,
            transmitted,
            reflected_object,
            mask: mask.into_iter().map(|m| m == 1).collect(),
        };
        Ok(FrameImage::from_components(color, components))
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec3;
    use vtfarm_vertex::{Components, FrameImage};

    use super::*;
    use crate::wire::planes::compress;

    #[test]
    fn linear_images_round_trip() {
        let pixels = vec![Vec3::new(0.5, 1.5, 2.5); 6];
        let image = WireImage::from_pixels(3, 2, &pixels);
        assert_eq!(image.into_pixels().expect("valid image"), (3, 2, pixels));
    }

    #[test]
    fn images_smaller_than_their_sides_are_refused() {
        let mut image = WireImage::from_pixels(2, 1, &[Vec3::ZERO; 2]);
        image.height = 2;
        let error = image.into_pixels().expect_err("two pixels for four");
        assert!(error.to_string().contains("image pixel bytes"), "{error}");
    }

    /// A frame's image crosses the wire bit for bit (compressed byte
    /// planes); a non-finite pixel or damaged bytes are refused, naming what
    /// is wrong.
    #[test]
    fn wire_images_round_trip_bit_exact_and_refuse_bad_pixels() {
        let pixels = vec![
            Vec3::new(0.1, -0.0, 3.5e-39),
            Vec3::new(1e30, 0.5, 0.25),
            Vec3::splat(f32::MIN_POSITIVE),
            Vec3::new(7.0, 8.0, 9.0),
        ];
        let wire = WireImage::from_pixels(2, 2, &pixels);
        let message = crate::Message::FrameDone(crate::FrameDone {
            job: crate::JobId(1),
            frame: 2,
            image: wire,
            stats: Default::default(),
            aux: None,
        });
        let encoded = crate::encode_message(&message).unwrap();
        let crate::Message::FrameDone(done) = crate::decode_message(&encoded[4..]).unwrap() else {
            panic!("a FrameDone comes back");
        };
        let (w, h, back) = done.image.into_pixels().unwrap();
        assert_eq!((w, h), (2, 2));
        let bits = |p: &[Vec3]| -> Vec<u32> {
            p.iter()
                .flat_map(|v| v.to_array())
                .map(f32::to_bits)
                .collect()
        };
        assert_eq!(bits(&back), bits(&pixels));

        let mut nan = pixels.clone();
        nan[1].y = f32::NAN;
        let error = (WireImage::from_pixels(2, 2, &nan).into_pixels()).expect_err("a NaN pixel");
        assert!(error.to_string().contains("image pixel 1"), "{error}");
        let mut ragged = WireImage::from_pixels(2, 2, &pixels);
        ragged.pixels.pop();
        assert!(ragged.into_pixels().is_err());
    }

    /// A frame's components cross the wire bit for bit; arrays of another
    /// size than the frame's, or a mask that is not 0 or 1, are refused.
    #[test]
    fn frame_components_round_trip_and_refuse_bad_sizes() {
        let image = |pixels: Vec<Vec3>| vtfarm_imaging::Image {
            width: 3,
            height: 1,
            pixels,
        };
        let frame = FrameImage::from_components(
            image(vec![Vec3::ONE, Vec3::X, Vec3::Y]),
            Components {
                reflected: image(vec![Vec3::ZERO, Vec3::splat(0.25), Vec3::Z]),
                transmitted: image(vec![Vec3::ZERO, Vec3::splat(1e-30), Vec3::X]),
                reflected_object: vec![vtfarm_scene::NONE, 7, 0],
                mask: vec![false, true, true],
            },
        );
        let wire = crate::WireFrameAux::encode(&frame);
        assert_eq!(
            wire.clone().into_components(frame.color.clone()).unwrap(),
            frame
        );

        let wider = vtfarm_imaging::Image::black(4, 1);
        let error = wire
            .clone()
            .into_components(wider)
            .expect_err("a wider frame");
        assert!(
            error.to_string().contains("reflected component = 3x1"),
            "{error}"
        );
        let mut bad_mask = wire;
        bad_mask.mask = compress(&[0, 2, 1]);
        let error = (bad_mask.into_components(frame.color.clone())).expect_err("a mask of 2");
        assert!(error.to_string().contains("mask = 2 at pixel 1"), "{error}");
    }

    /// A frame's sRGB conversion runs on every core in tasks: on one
    /// thread or several, exactly the bytes of the whole image converted
    /// and compressed at once (one zstd frame).
    #[test]
    fn srgb_images_convert_on_every_core_to_the_same_bytes() {
        let (width, height) = (700, 400);
        let image = vtfarm_imaging::Image {
            width,
            height,
            pixels: (0..width * height)
                .map(|i| Vec3::new((i % 977) as f32 / 500.0, (i % 13) as f32 * 0.1, 0.3))
                .collect(),
        };
        assert!(
            image.pixels.len() > 2 * vtfarm_imaging::SRGB_TASK_PIXELS,
            "several tasks"
        );
        let pool = |threads| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
        };
        let format = WireImageFormat::Srgb8;
        let one = pool(1).install(|| WireImage::encode(&image, format));
        let three = pool(3).install(|| WireImage::encode(&image, format));
        assert_eq!(one, three, "the bytes do not depend on the threads");
        assert_eq!(one.pixels, compress(&image.to_srgb8()), "one zstd frame");
        // Bytes converted by the caller take the same compression.
        let made = WireImage::from_uncompressed(width, height, format, &image.to_srgb8());
        assert_eq!(made, one, "one compression path");
        assert_eq!(one.into_srgb8().unwrap(), (width, height, image.to_srgb8()));
    }

    /// An sRGB frame carries exactly the bytes a PNG of the linear one
    /// holds; a linear frame gives the same bytes; linear colours are not
    /// made up from sRGB ones.
    #[test]
    fn srgb_wire_images_carry_the_png_bytes() {
        let image = vtfarm_imaging::Image {
            width: 3,
            height: 2,
            pixels: (0..6)
                .map(|i| Vec3::new(0.1 * i as f32, 0.5, 2.0))
                .collect(),
        };
        let srgb = WireImage::encode(&image, WireImageFormat::Srgb8);
        assert_eq!(srgb.clone().into_srgb8().unwrap(), (3, 2, image.to_srgb8()));
        let linear = WireImage::encode(&image, WireImageFormat::LinearF32);
        assert_eq!(linear.into_srgb8().unwrap(), (3, 2, image.to_srgb8()));
        let error = srgb.clone().into_pixels().expect_err("no linear colours");
        assert!(error.to_string().contains("image format"), "{error}");
        let mut short = srgb;
        short.width = 4;
        let error = short.into_srgb8().expect_err("six pixels for eight");
        assert!(error.to_string().contains("image pixel bytes"), "{error}");
        // Encoded in a buffer that held more or less, the same bytes.
        for format in [WireImageFormat::Srgb8, WireImageFormat::LinearF32] {
            for stale in [vec![0xab; 1000], vec![0xab; 1]] {
                let mut scratch = stale;
                let reused = WireImage::encode_reusing(&image, format, &mut scratch);
                assert_eq!(reused, WireImage::encode(&image, format), "{format:?}");
            }
        }
    }
}
