//! Textures: images decoded once (`image`), kept as 8-bit sRGB colour with
//! linear alpha and a mip pyramid, sampled bilinearly between two mip
//! levels (trilinear) with repeating edges.
//!
//! The scene's texture coordinates are per triangle corner
//! ([`crate::Scene::corner_uvs`]), with OBJ's convention: `u` to the right,
//! `v` up (v = 0 is the image's bottom row). Mip levels are averaged in
//! linear light. The level is chosen from the footprint of a pixel on the
//! surface (its width in metres) and the triangle's texel density, one
//! isotropic rule ([`crate::Scene::textured_material`]).

use std::path::Path;

use glam::{Vec2, Vec4};

/// Index of a texture in [`crate::Scene::textures`].
pub type TextureId = u32;

/// The largest width or height of a texture.
pub const MAX_TEXTURE_SIDE: u32 = 8192;
/// The most texture bytes (8-bit RGBA, level 0) one scene may hold: the
/// scene travels to every worker in one message.
pub const MAX_TEXTURE_BYTES: usize = 96 << 20;

/// Why a texture could not be made.
#[derive(Debug, thiserror::Error)]
pub enum TextureError {
    /// The file could not be read or decoded.
    #[error("{}: {error}", .path.display())]
    Decode {
        path: std::path::PathBuf,
        error: image::ImageError,
    },
    /// The size is zero or beyond [`MAX_TEXTURE_SIDE`].
    #[error("texture {name:?} is {width}×{height}: each side must be 1 to {MAX_TEXTURE_SIDE}")]
    Size {
        name: String,
        width: u32,
        height: u32,
    },
    /// The pixel bytes do not match the size.
    #[error("texture {name:?}: {actual} bytes for {width}×{height} RGBA (expected {expected})")]
    Bytes {
        name: String,
        width: u32,
        height: u32,
        expected: usize,
        actual: usize,
    },
}

/// A texture: 8-bit RGBA (colour in sRGB, alpha linear), row 0 at the top.
/// Two textures are equal when their pixels are (the name is for messages;
/// the mip levels follow from the pixels).
#[derive(Clone, Debug)]
pub struct Texture {
    name: String,
    /// Level 0 is the image itself; each next one half as wide and high
    /// (rounded up), down to 1×1.
    levels: Vec<Level>,
    /// Whether any texel's alpha is below 255 (an alpha map, `map_d`, then
    /// reads alpha; otherwise the grey level).
    has_alpha: bool,
}

#[derive(Clone, Debug)]
struct Level {
    width: u32,
    height: u32,
    rgba8: Vec<u8>,
}

impl PartialEq for Texture {
    fn eq(&self, other: &Self) -> bool {
        self.levels[0].rgba8 == other.levels[0].rgba8 && {
            let (a, b) = (&self.levels[0], &other.levels[0]);
            (a.width, a.height) == (b.width, b.height)
        }
    }
}

/// 8-bit sRGB to linear, by table.
fn srgb8_to_linear() -> &'static [f32; 256] {
    static TABLE: std::sync::OnceLock<[f32; 256]> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| std::array::from_fn(|i| vtfarm_imaging::srgb_to_linear(i as f32 / 255.0)))
}

impl Texture {
    /// A texture of `width × height` RGBA bytes (colour sRGB, alpha
    /// linear), named for messages (its file name).
    pub fn from_rgba8(
        name: &str,
        width: u32,
        height: u32,
        rgba8: Vec<u8>,
    ) -> Result<Texture, TextureError> {
        if width == 0 || height == 0 || width > MAX_TEXTURE_SIDE || height > MAX_TEXTURE_SIDE {
            return Err(TextureError::Size {
                name: name.to_owned(),
                width,
                height,
            });
        }
        let expected = width as usize * height as usize * 4;
        if rgba8.len() != expected {
            return Err(TextureError::Bytes {
                name: name.to_owned(),
                width,
                height,
                expected,
                actual: rgba8.len(),
            });
        }
        let has_alpha = rgba8.chunks_exact(4).any(|t| t[3] < 255);
        let mut levels = vec![Level {
            width,
            height,
            rgba8,
        }];
        while let Some(next) = levels.last().and_then(Level::half) {
            levels.push(next);
        }
        Ok(Texture {
            name: name.to_owned(),
            levels,
            has_alpha,
        })
    }

    /// Reads and decodes an image file (PNG, JPEG or PNM), named by its
    /// file name; only a regular file of at most
    /// [`MAX_IMAGE_FILE_BYTES`](crate::file::MAX_IMAGE_FILE_BYTES) is read.
    pub fn load(path: &Path) -> Result<Texture, TextureError> {
        let bytes =
            crate::file::read_regular(path, crate::file::MAX_IMAGE_FILE_BYTES).map_err(|e| {
                TextureError::Decode {
                    path: path.to_owned(),
                    error: image::ImageError::IoError(e),
                }
            })?;
        let name = path.file_name().map_or_else(
            || path.display().to_string(),
            |n| n.to_string_lossy().into_owned(),
        );
        Texture::decode(&name, &bytes).map_err(|e| match e {
            // A decoding error names the file by its path, as a read error does.
            TextureError::Decode { error, .. } => TextureError::Decode {
                path: path.to_owned(),
                error,
            },
            other => other,
        })
    }

    /// Decodes an image file's bytes (PNG, JPEG or PNM).
    pub fn decode(name: &str, bytes: &[u8]) -> Result<Texture, TextureError> {
        let decode = |error| TextureError::Decode {
            path: name.into(),
            error,
        };
        let reader = image::ImageReader::new(std::io::Cursor::new(bytes))
            .with_guessed_format()
            .map_err(|e| decode(image::ImageError::IoError(e)))?;
        let (width, height) = reader.into_dimensions().map_err(decode)?;
        if width == 0 || height == 0 || width > MAX_TEXTURE_SIDE || height > MAX_TEXTURE_SIDE {
            return Err(TextureError::Size {
                name: name.to_owned(),
                width,
                height,
            });
        }
        let rgba = image::load_from_memory(bytes).map_err(decode)?.to_rgba8();
        Texture::from_rgba8(name, width, height, rgba.into_raw())
    }

    /// The name messages use (the file name).
    pub fn name(&self) -> &str {
        &self.name
    }

    pub fn width(&self) -> u32 {
        self.levels[0].width
    }

    pub fn height(&self) -> u32 {
        self.levels[0].height
    }

    /// The RGBA bytes of the image itself (level 0).
    pub fn rgba8(&self) -> &[u8] {
        &self.levels[0].rgba8
    }

    /// The linear RGBA colour at `uv` with mip level `lod` (0: the image
    /// itself; fractions blend two levels; clamped to the levels there are).
    pub fn sample(&self, uv: Vec2, lod: f32) -> Vec4 {
        let top = (self.levels.len() - 1) as f32;
        let lod = if lod.is_finite() {
            lod.clamp(0.0, top)
        } else {
            0.0
        };
        let fine = lod.floor();
        let blend = lod - fine;
        let a = self.levels[fine as usize].bilinear(uv);
        if blend == 0.0 {
            return a;
        }
        let b = self.levels[fine as usize + 1].bilinear(uv);
        a + (b - a) * blend
    }

    /// The value an alpha map (`map_d`) gives at `uv`: alpha where the image
    /// has any, otherwise its grey level.
    pub fn sample_alpha(&self, uv: Vec2, lod: f32) -> f32 {
        let texel = self.sample(uv, lod);
        if self.has_alpha {
            texel.w
        } else {
            crate::photometry::luminance(texel.truncate())
        }
    }

    /// The mip level at which one pixel footprint (`texels` texels of
    /// level 0 wide) covers about one texel.
    pub fn lod(texels: f32) -> f32 {
        if texels > 1.0 { texels.log2() } else { 0.0 }
    }
}

impl Level {
    /// The next level: half as wide and high, rounded up, each texel the
    /// average (in linear light) of the up to four it covers.
    fn half(&self) -> Option<Level> {
        if self.width == 1 && self.height == 1 {
            return None;
        }
        let (width, height) = (self.width.div_ceil(2), self.height.div_ceil(2));
        let mut rgba8 = Vec::with_capacity(width as usize * height as usize * 4);
        for y in 0..height {
            for x in 0..width {
                let mut sum = Vec4::ZERO;
                for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    let sx = (2 * x + dx).min(self.width - 1);
                    let sy = (2 * y + dy).min(self.height - 1);
                    sum += self.texel(sx, sy);
                }
                let mean = sum * 0.25;
                let [r, g, b] = vtfarm_imaging::encode_srgb8(mean.truncate());
                let a = (mean.w.clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
                rgba8.extend_from_slice(&[r, g, b, a]);
            }
        }
        Some(Level {
            width,
            height,
            rgba8,
        })
    }

    /// Texel (x, y), linear.
    fn texel(&self, x: u32, y: u32) -> Vec4 {
        let i = (y as usize * self.width as usize + x as usize) * 4;
        let t = &self.rgba8[i..i + 4];
        let table = srgb8_to_linear();
        Vec4::new(
            table[t[0] as usize],
            table[t[1] as usize],
            table[t[2] as usize],
            t[3] as f32 / 255.0,
        )
    }

    /// Bilinear filtering at `uv` (v up), repeating at the edges.
    fn bilinear(&self, uv: Vec2) -> Vec4 {
        let (w, h) = (self.width as f32, self.height as f32);
        let u = if uv.x.is_finite() { uv.x } else { 0.0 };
        let v = if uv.y.is_finite() { uv.y } else { 0.0 };
        // Texel centres at half-integers; row 0 is the top (v = 1).
        let x = (u - u.floor()) * w - 0.5;
        let y = ((1.0 - v) - (1.0 - v).floor()) * h - 0.5;
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let wrap = |i: f32, n: u32| (i as i64).rem_euclid(n as i64) as u32;
        let (xa, xb) = (wrap(x0, self.width), wrap(x0 + 1.0, self.width));
        let (ya, yb) = (wrap(y0, self.height), wrap(y0 + 1.0, self.height));
        let top = self.texel(xa, ya) * (1.0 - fx) + self.texel(xb, ya) * fx;
        let bottom = self.texel(xa, yb) * (1.0 - fx) + self.texel(xb, yb) * fx;
        top * (1.0 - fy) + bottom * fy
    }
}

/// Texels of `texture`'s level 0 per metre on a triangle covering
/// `uv_area` in texture coordinates and `world_area` m² (0 when either is
/// empty).
pub(crate) fn texel_scale(uv_area: f32, world_area: f32, texture: &Texture) -> f32 {
    let texels = uv_area * texture.width() as f32 * texture.height() as f32;
    if world_area > 0.0 && texels > 0.0 {
        (texels / world_area).sqrt()
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn checker() -> Texture {
        // 2×2: red, green / blue, white (top row first).
        let rgba = [
            [255, 0, 0, 255],
            [0, 255, 0, 255],
            [0, 0, 255, 255],
            [255; 4],
        ]
        .concat();
        Texture::from_rgba8("checker", 2, 2, rgba).unwrap()
    }

    #[test]
    fn texel_centres_give_their_colours_and_v_points_up() {
        let t = checker();
        let at = |u, v| t.sample(Vec2::new(u, v), 0.0).truncate();
        assert_eq!(at(0.25, 0.75), Vec3::X, "top left");
        assert_eq!(at(0.75, 0.75), Vec3::Y, "top right");
        assert_eq!(at(0.25, 0.25), Vec3::Z, "bottom left");
        assert_eq!(at(0.75, 0.25), Vec3::ONE, "bottom right");
        // Halfway between two centres: the mean, in linear light.
        assert_eq!(at(0.5, 0.75), Vec3::new(0.5, 0.5, 0.0));
        // Repeating edges.
        assert_eq!(at(1.25, -0.25), Vec3::X);
        assert_eq!(at(-0.25, 1.25), Vec3::ONE);
    }

    #[test]
    fn mip_levels_average_in_linear_light_down_to_one_texel() {
        let t = checker();
        assert_eq!(t.levels.len(), 2);
        let top = t.sample(Vec2::new(0.3, 0.6), 1.0).truncate();
        // (1 + 0 + 0 + 1) / 4 per channel, through 8-bit sRGB.
        let mean = srgb8_to_linear()[vtfarm_imaging::encode_srgb8(Vec3::splat(0.5))[0] as usize];
        assert!(
            (top - Vec3::splat(mean)).abs().max_element() < 1e-6,
            "{top}"
        );
        // Blending halfway between the levels, and clamping past the last.
        let half = t.sample(Vec2::new(0.25, 0.75), 0.5).truncate();
        assert!(
            (half - (Vec3::X + Vec3::splat(mean)) * 0.5)
                .abs()
                .max_element()
                < 1e-6
        );
        assert_eq!(
            t.sample(Vec2::new(0.3, 0.6), 9.0),
            t.sample(Vec2::new(0.3, 0.6), 1.0)
        );
        assert_eq!(Texture::lod(4.0), 2.0);
        assert_eq!(Texture::lod(0.5), 0.0);
    }

    #[test]
    fn sizes_and_byte_counts_are_checked() {
        assert!(matches!(
            Texture::from_rgba8("t", 0, 1, vec![]),
            Err(TextureError::Size { .. })
        ));
        assert!(matches!(
            Texture::from_rgba8("t", MAX_TEXTURE_SIDE + 1, 1, vec![]),
            Err(TextureError::Size { .. })
        ));
        assert!(matches!(
            Texture::from_rgba8("t", 2, 2, vec![0; 15]),
            Err(TextureError::Bytes { expected: 16, .. })
        ));
    }
}
