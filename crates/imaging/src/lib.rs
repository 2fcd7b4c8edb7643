//! Linear RGB float images and their output: 8-bit sRGB PNG (with an
//! [`Exposure`]: a scale and a tone curve), 16-bit grayscale PNG (for index
//! maps), float32 OpenEXR ([`write_exr_f32`], named channels) and raw
//! little-endian float32 `.npy` arrays.
//!
//! Architecture invariant: colours are linear everywhere in vtfarm; sRGB
//! encoding happens only here, on the way out.

use std::io::Write;
use std::ops::Range;
use std::path::{Path, PathBuf};

use glam::Vec3;

/// Errors while writing an image file. The message names the file and
/// the cause once (the cause is not also the error's `source`, so a chain
/// printed with `{:#}` does not repeat it).
#[derive(Debug, thiserror::Error)]
pub enum ImageError {
    #[error("cannot write {path}: {cause}")]
    Io {
        path: PathBuf,
        cause: std::io::Error,
    },
    #[error("cannot encode {path}: {cause}")]
    Encode {
        path: PathBuf,
        cause: image::ImageError,
    },
    #[error("cannot write OpenEXR {path}: {cause}")]
    Exr {
        path: PathBuf,
        cause: exr::error::Error,
    },
}

/// How linear colours become the 8-bit PNG's: each channel is multiplied
/// by `scale`, goes through `tone`, and is encoded as sRGB (values at or
/// above 1 are white). The default (scale 1, [`ToneCurve::Clip`]) leaves
/// the colours as they are: 1.0 is white.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Exposure {
    pub scale: f32,
    pub tone: ToneCurve,
}

impl Default for Exposure {
    fn default() -> Self {
        Exposure {
            scale: 1.0,
            tone: ToneCurve::Clip,
        }
    }
}

/// The tone curve of an [`Exposure`], applied per channel to the scaled
/// value `x`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ToneCurve {
    /// `x` itself: linear up to white, clipped above.
    #[default]
    Clip,
    /// Reinhard's global operator `x / (1 + x)`: nothing clips, `x = 1`
    /// shows at half (sRGB 188), brighter values are compressed towards
    /// white.
    Reinhard,
}

impl ToneCurve {
    pub const ALL: [ToneCurve; 2] = [ToneCurve::Clip, ToneCurve::Reinhard];

    /// The name in job files.
    pub fn name(self) -> &'static str {
        match self {
            ToneCurve::Clip => "clip",
            ToneCurve::Reinhard => "reinhard",
        }
    }

    pub fn from_name(name: &str) -> Option<ToneCurve> {
        ToneCurve::ALL.into_iter().find(|t| t.name() == name)
    }

    fn apply(self, x: f32) -> f32 {
        match self {
            ToneCurve::Clip => x,
            ToneCurve::Reinhard if x > 0.0 => x / (1.0 + x),
            ToneCurve::Reinhard => 0.0,
        }
    }
}

impl Exposure {
    /// Whether the exposure leaves every colour as it is.
    pub fn is_identity(&self) -> bool {
        *self == Exposure::default()
    }

    /// The image as the PNG shows it, still linear: scaled and toned.
    pub fn apply(&self, image: &Image) -> Image {
        let Exposure { scale, tone } = *self;
        Image {
            width: image.width,
            height: image.height,
            pixels: (image.pixels.iter())
                .map(|c| (*c * scale).map(|x| tone.apply(x)))
                .collect(),
        }
    }
}

/// A linear RGB image, row 0 at the top.
#[derive(Debug, PartialEq)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    pub pixels: Vec<Vec3>,
}

impl Clone for Image {
    fn clone(&self) -> Self {
        Image {
            width: self.width,
            height: self.height,
            pixels: self.pixels.clone(),
        }
    }

    /// Copies `source` into this image's allocation (a copy without the
    /// page faults of a fresh 1080p buffer when it fits).
    fn clone_from(&mut self, source: &Self) {
        (self.width, self.height) = (source.width, source.height);
        self.pixels.clone_from(&source.pixels);
    }
}

impl Image {
    /// An image filled with one colour.
    pub fn new(width: u32, height: u32, fill: Vec3) -> Self {
        Image {
            width,
            height,
            pixels: vec![fill; (width * height) as usize],
        }
    }

    /// Makes this a `width` × `height` image filled with `fill`, as
    /// [`Image::new`] makes one, in this image's allocation: a frame's
    /// buffer reused for the next costs one pass over its pixels, where a
    /// fresh one costs a page fault per 4 KiB on first write as well.
    pub fn refill(&mut self, width: u32, height: u32, fill: Vec3) {
        self.width = width;
        self.height = height;
        self.pixels.clear();
        self.pixels.resize((width * height) as usize, fill);
    }

    /// A black image, [`Image::new`] with `Vec3::ZERO`, whose pixels come
    /// from a zeroed allocation: the operating system maps untouched pages on
    /// first use, so a full-frame plane of which little is written (a
    /// frame's reflected component outside the reflectors) costs only what
    /// is touched, not a full-frame pass.
    pub fn black(width: u32, height: u32) -> Self {
        const { assert!(size_of::<Vec3>() == 3 * size_of::<f32>()) };
        const { assert!(align_of::<Vec3>() == align_of::<f32>()) };
        let n = (width * height) as usize;
        // `vec![0.0; len]` allocates zeroed (calloc) rather than writing.
        let floats = std::mem::ManuallyDrop::new(vec![0.0f32; 3 * n]);
        if floats.capacity() != 3 * n {
            // Never taken (`vec!` allocates exactly), but the cast below
            // needs it: fall back on writing every pixel.
            std::mem::ManuallyDrop::into_inner(floats);
            return Image::new(width, height, Vec3::ZERO);
        }
        let mut floats = floats;
        // SAFETY: `Vec3` is `#[repr(C)]` of three `f32` (size and alignment
        // checked above), so the buffer of 3n zeroed `f32` with capacity 3n
        // is a valid, identically laid out allocation of n zero `Vec3`; the
        // original `Vec` is never dropped (`ManuallyDrop`), so the allocation
        // has one owner.
        let pixels = unsafe { Vec::from_raw_parts(floats.as_mut_ptr().cast::<Vec3>(), n, n) };
        Image {
            width,
            height,
            pixels,
        }
    }

    /// The index of pixel (`x`, `y`) in [`Image::pixels`].
    pub fn index(&self, x: u32, y: u32) -> usize {
        (y * self.width + x) as usize
    }

    pub fn get(&self, x: u32, y: u32) -> Vec3 {
        self.pixels[self.index(x, y)]
    }

    pub fn set(&mut self, x: u32, y: u32, c: Vec3) {
        let i = self.index(x, y);
        self.pixels[i] = c;
    }

    /// The 8-bit sRGB encoding, RGB interleaved, row-major from the top row
    /// ([`encode_srgb8`] of every pixel, by table).
    pub fn to_srgb8(&self) -> Vec<u8> {
        let mut out = Vec::new();
        self.to_srgb8_into(&mut out);
        out
    }

    /// [`Image::to_srgb8`] into `out`'s allocation (whatever it held): a
    /// buffer kept from frame to frame spares a fresh one's page faults.
    /// Converted on the calling rayon pool's threads in tasks of
    /// [`SRGB_TASK_PIXELS`]: per pixel, so the bytes do not depend on them.
    pub fn to_srgb8_into(&self, out: &mut Vec<u8>) {
        use rayon::prelude::*;
        out.clear();
        out.resize(3 * self.pixels.len(), 0);
        let table = Srgb8Table::get();
        (out.par_chunks_mut(3 * SRGB_TASK_PIXELS))
            .zip(self.pixels.par_chunks(SRGB_TASK_PIXELS))
            .for_each(|(out, pixels)| table.encode_pixels(out, pixels));
    }

    /// [`Image::to_srgb8_into`] of the pixels in `columns` × `rows` only,
    /// into `out`, which holds this image's sRGB bytes elsewhere: a frame
    /// whose base was converted ahead converts only the pixels written
    /// since. The bytes are [`Image::to_srgb8`]'s there (per pixel, on the
    /// calling pool's threads, row by row).
    ///
    /// # Panics
    /// If `out` is not 3 bytes a pixel of this image, or the region
    /// reaches outside it.
    pub fn to_srgb8_region_into(&self, out: &mut [u8], columns: Range<u32>, rows: Range<u32>) {
        use rayon::prelude::*;
        assert_eq!(
            out.len(),
            3 * self.pixels.len(),
            "an sRGB buffer of the image's size"
        );
        assert!(
            columns.end <= self.width && rows.end <= self.height,
            "the region {columns:?} x {rows:?} lies inside the {}x{} image",
            self.width,
            self.height
        );
        if columns.is_empty() || rows.is_empty() {
            return;
        }
        let width = self.width as usize;
        let (x0, x1) = (columns.start as usize, columns.end as usize);
        // About SRGB_TASK_PIXELS a task, as for a whole image.
        let rows_per_task = (SRGB_TASK_PIXELS / (x1 - x0)).max(1);
        let table = Srgb8Table::get();
        (out.par_chunks_mut(3 * width))
            .zip(self.pixels.par_chunks(width))
            .skip(rows.start as usize)
            .take(rows.len())
            .with_min_len(rows_per_task)
            .for_each(|(out, pixels)| {
                table.encode_pixels(&mut out[3 * x0..3 * x1], &pixels[x0..x1])
            });
    }

    /// The image reduced `factor` times in each direction (rounded up) for
    /// a display smaller than it: each pixel the mean, in linear light, of
    /// the up to `factor` × `factor` pixels it covers. Factor 1 (or 0) is
    /// the image itself.
    pub fn reduced(&self, factor: u32) -> Image {
        let factor = factor.max(1);
        if factor == 1 {
            return self.clone();
        }
        let (width, height) = (self.width.div_ceil(factor), self.height.div_ceil(factor));
        let mut pixels = Vec::with_capacity(width as usize * height as usize);
        for y in 0..height {
            let rows = y * factor..((y + 1) * factor).min(self.height);
            for x in 0..width {
                let columns = x * factor..((x + 1) * factor).min(self.width);
                let mut sum = Vec3::ZERO;
                for sy in rows.clone() {
                    let row = self.index(0, sy);
                    for sx in columns.clone() {
                        sum += self.pixels[row + sx as usize];
                    }
                }
                pixels.push(sum / (rows.len() * columns.len()) as f32);
            }
        }
        Image {
            width,
            height,
            pixels,
        }
    }

    /// Writes an 8-bit sRGB PNG ([`write_srgb8_png`] of [`Image::to_srgb8`]).
    pub fn write_png(&self, path: &Path) -> Result<(), ImageError> {
        write_srgb8_png(path, self.width, self.height, &self.to_srgb8())
    }

    /// [`Image::write_png`] of the image under `exposure` (the same bytes
    /// for the default exposure).
    pub fn write_png_exposed(&self, path: &Path, exposure: &Exposure) -> Result<(), ImageError> {
        if exposure.is_identity() {
            self.write_png(path)
        } else {
            exposure.apply(self).write_png(path)
        }
    }

    /// Writes the linear colours as a `.npy` array of shape (height, width, 3),
    /// little-endian float32.
    pub fn write_npy(&self, path: &Path) -> Result<(), ImageError> {
        let data: Vec<f32> = self.pixels.iter().flat_map(|c| c.to_array()).collect();
        write_npy_f32(path, &[self.height as usize, self.width as usize, 3], &data)
    }
}

/// Writes 8-bit sRGB pixels (RGB interleaved, row-major from the top row)
/// as a PNG, with fast compression (fdeflate) and the `Sub` filter: every
/// frame of a farm job goes through here on a machine that also renders.
/// Measured on a 1080p cockpit frame: 9 ms and 202 kB, against 64 ms and
/// 180 kB with the image crate's default (adaptive filter). Every RGB PNG of
/// vtfarm is written here, so the same pixels give the same file whichever
/// command wrote it.
///
/// # Panics
/// If `pixels` does not hold `width * height * 3` bytes.
pub fn write_srgb8_png(
    path: &Path,
    width: u32,
    height: u32,
    pixels: &[u8],
) -> Result<(), ImageError> {
    let file = std::fs::File::create(path).map_err(|cause| ImageError::Io {
        path: path.to_owned(),
        cause,
    })?;
    let mut out = std::io::BufWriter::new(file);
    encode_srgb8_png(&mut out, width, height, pixels).map_err(|cause| ImageError::Encode {
        path: path.to_owned(),
        cause,
    })?;
    out.flush().map_err(|cause| ImageError::Io {
        path: path.to_owned(),
        cause,
    })
}

/// [`write_srgb8_png`]'s encoding into `out` (an HTTP answer's bytes, a
/// file): the same bytes for the same pixels.
///
/// # Panics
/// If `pixels` does not hold `width * height * 3` bytes.
pub fn encode_srgb8_png(
    out: impl Write,
    width: u32,
    height: u32,
    pixels: &[u8],
) -> Result<(), image::ImageError> {
    use image::ImageEncoder;
    use image::codecs::png::{CompressionType, FilterType, PngEncoder};
    let encoder = PngEncoder::new_with_quality(out, CompressionType::Fast, FilterType::Sub);
    encoder.write_image(pixels, width, height, image::ExtendedColorType::Rgb8)
}

/// Pixels per task of [`Image::to_srgb8_into`], which spreads the
/// conversion over the calling pool's threads: a finished 1080p frame's
/// conversion is most of the master's serial work after a split frame's
/// last result (15 ms of one thread's 17, zstd the rest); 32 tasks at 1080p.
pub const SRGB_TASK_PIXELS: usize = 1 << 16;

/// [`encode_srgb8`]'s channel rule by table: per bucket of floats in
/// [0, 1] (sign, exponent and top 7 mantissa bits) the code at the
/// bucket's start and the smallest value in the bucket coded one more.
/// Since the rule is monotonic in its input and no bucket holds two code
/// steps (at most 0.66 of one: the rule's steepest part against the widest
/// buckets, checked as the table is built), a value's code is the bucket's
/// or one more: its exact bytes (the tests check every float in [0, 1]) at
/// a fraction of a `powf`, without a branch to mispredict.
struct Srgb8Table {
    /// Indexed by `v.to_bits() >> BUCKET_SHIFT` for every `v` in [0, 1].
    buckets: Vec<Srgb8Bucket>,
}

#[derive(Clone, Copy)]
struct Srgb8Bucket {
    /// The code of the bucket's first value.
    code: u8,
    /// The smallest value in [0, 1] coded `code + 1` (infinity for 255).
    next: f32,
}

const BUCKET_SHIFT: u32 = 16;

/// The reference rule: one channel as [`encode_srgb8`] writes it.
fn srgb8_channel(v: f32) -> u8 {
    (linear_to_srgb(v) * 255.0 + 0.5) as u8
}

impl Srgb8Table {
    fn get() -> &'static Srgb8Table {
        static TABLE: std::sync::OnceLock<Srgb8Table> = std::sync::OnceLock::new();
        TABLE.get_or_init(Srgb8Table::build)
    }

    fn build() -> Srgb8Table {
        let one = 1.0f32.to_bits();
        // `thresholds[k]`: the smallest value in [0, 1] coded k or more.
        let mut thresholds = [f32::INFINITY; 258];
        for (k, t) in thresholds.iter_mut().enumerate().take(256).skip(1) {
            // Binary search over the bit patterns of [0, 1] (ordered as the values).
            let (mut lo, mut hi) = (0u32, one + 1);
            while lo < hi {
                let mid = lo + (hi - lo) / 2;
                if usize::from(srgb8_channel(f32::from_bits(mid))) >= k {
                    hi = mid;
                } else {
                    lo = mid + 1;
                }
            }
            if lo <= one {
                *t = f32::from_bits(lo);
            }
        }
        let buckets = (0..=one >> BUCKET_SHIFT)
            .map(|b| {
                let first = f32::from_bits(b << BUCKET_SHIFT);
                let last = f32::from_bits(((b + 1) << BUCKET_SHIFT) - 1).min(1.0);
                let code = srgb8_channel(first);
                let next = thresholds[usize::from(code) + 1];
                assert!(
                    last < thresholds[usize::from(code) + 2],
                    "the sRGB bucket at {first:e} holds two code steps"
                );
                Srgb8Bucket { code, next }
            })
            .collect();
        Srgb8Table { buckets }
    }

    /// Codes `pixels` into `out`, three bytes each.
    fn encode_pixels(&self, out: &mut [u8], pixels: &[Vec3]) {
        for (bytes, c) in out.chunks_exact_mut(3).zip(pixels) {
            bytes.copy_from_slice(&[self.encode(c.x), self.encode(c.y), self.encode(c.z)]);
        }
    }

    #[inline]
    fn encode(&self, v: f32) -> u8 {
        // NaN and everything at or below zero is code 0, as in the rule.
        let v = if v > 0.0 { v.min(1.0) } else { 0.0 };
        let bucket = self.buckets[(v.to_bits() >> BUCKET_SHIFT) as usize];
        bucket.code + u8::from(v >= bucket.next)
    }
}

/// Encodes one linear channel value to sRGB in [0, 1] (clamped).
pub fn linear_to_srgb(v: f32) -> f32 {
    let v = v.clamp(0.0, 1.0);
    if v <= 0.003_130_8 {
        v * 12.92
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// Decodes one sRGB channel value in [0, 1] to linear.
pub fn srgb_to_linear(v: f32) -> f32 {
    if v <= 0.040_45 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// Encodes a linear colour as three 8-bit sRGB values (rounded to nearest).
pub fn encode_srgb8(c: Vec3) -> [u8; 3] {
    c.to_array()
        .map(|v| (linear_to_srgb(v) * 255.0 + 0.5) as u8)
}

/// Writes a 16-bit grayscale PNG (used for index maps such as the
/// reflected-object map, where 0 means "nothing").
pub fn write_gray16_png(
    path: &Path,
    width: u32,
    height: u32,
    values: &[u16],
) -> Result<(), ImageError> {
    let buf =
        image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_raw(width, height, values.to_vec())
            .expect("caller passes width * height values");
    buf.save_with_format(path, image::ImageFormat::Png)
        .map_err(|cause| ImageError::Encode {
            path: path.to_owned(),
            cause,
        })
}

/// Writes an 8-bit grayscale PNG (used for masks).
pub fn write_gray8_png(
    path: &Path,
    width: u32,
    height: u32,
    values: &[u8],
) -> Result<(), ImageError> {
    let buf = image::GrayImage::from_raw(width, height, values.to_vec())
        .expect("caller passes width * height values");
    buf.save_with_format(path, image::ImageFormat::Png)
        .map_err(|cause| ImageError::Encode {
            path: path.to_owned(),
            cause,
        })
}

/// Writes a float32 OpenEXR file of one part with the named channels
/// (`R`, `G`, `B`, `Y`, `reflected.R`, …: OpenEXR's layer convention),
/// each `width * height` values row-major from the top row; ZIP
/// compressed, so the values read back exactly.
///
/// # Panics
/// If a channel does not hold `width * height` values.
pub fn write_exr_f32(
    path: &Path,
    width: u32,
    height: u32,
    channels: &[(&str, &[f32])],
) -> Result<(), ImageError> {
    use exr::prelude::*;
    let n = width as usize * height as usize;
    let list: SmallVec<[AnyChannel<FlatSamples>; 4]> = channels
        .iter()
        .map(|&(name, values)| {
            assert_eq!(values.len(), n, "channel {name}: width * height values");
            AnyChannel::new(name, FlatSamples::F32(values.to_vec()))
        })
        .collect();
    let layer = Layer::new(
        (width as usize, height as usize),
        LayerAttributes::default(),
        Encoding::SMALL_LOSSLESS,
        AnyChannels::sort(list),
    );
    exr::prelude::Image::from_layer(layer)
        .write()
        .to_file(path)
        .map_err(|cause| ImageError::Exr {
            path: path.to_owned(),
            cause,
        })
}

/// Writes a little-endian float32 `.npy` file (format version 1.0).
pub fn write_npy_f32(path: &Path, shape: &[usize], data: &[f32]) -> Result<(), ImageError> {
    let io = |cause| ImageError::Io {
        path: path.to_owned(),
        cause,
    };
    let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    let shape_text = if dims.len() == 1 {
        format!("({},)", dims[0])
    } else {
        format!("({})", dims.join(", "))
    };
    let mut header = format!("{{'descr': '<f4', 'fortran_order': False, 'shape': {shape_text}, }}");
    // Magic (6) + version (2) + header length (2) + header + newline, padded to 64 bytes.
    let unpadded = 10 + header.len() + 1;
    header.push_str(&" ".repeat((64 - unpadded % 64) % 64));
    header.push('\n');
    let mut out = Vec::with_capacity(10 + header.len() + data.len() * 4);
    out.extend_from_slice(b"\x93NUMPY\x01\x00");
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    for v in data {
        out.extend_from_slice(&v.to_le_bytes());
    }
    std::fs::File::create(path)
        .and_then(|mut f| f.write_all(&out))
        .map_err(io)
}

/// Text escaped for HTML and SVG, in element content and in quoted
/// attributes alike: the one escaper of vtfarm's reports (the study's HTML,
/// the master's frame timelines).
pub fn escape_html(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    #[test]
    fn markup_characters_are_escaped_for_content_and_attributes() {
        use super::escape_html;
        assert_eq!(
            escape_html(r#"<a href="x">Tom & Jerry's</a>"#),
            "&lt;a href=&quot;x&quot;&gt;Tom &amp; Jerry&#39;s&lt;/a&gt;"
        );
        assert_eq!(escape_html("plain ü"), "plain ü");
    }

    #[test]
    fn a_black_image_is_a_zero_filled_one() {
        for (w, h) in [(0, 0), (1, 1), (3, 2), (1920, 1080)] {
            let mut black = Image::black(w, h);
            assert_eq!(black, Image::new(w, h, Vec3::ZERO));
            if w > 0 {
                // It is an ordinary image: writable and growable.
                black.set(w - 1, h - 1, Vec3::ONE);
                black.pixels.push(Vec3::X);
                assert_eq!(black.pixels.len(), (w * h) as usize + 1);
            }
        }
    }

    use super::*;

    /// A reduced pixel is the mean of the pixels it covers, the partial
    /// blocks at the right and bottom edges over the pixels they hold.
    #[test]
    fn a_reduced_image_averages_the_blocks_it_covers() {
        let mut image = Image::black(5, 4);
        for y in 0..4 {
            for x in 0..5 {
                image.set(x, y, Vec3::new(x as f32, y as f32, (x * y) as f32));
            }
        }
        assert_eq!(image.reduced(1), image);
        assert_eq!(image.reduced(0), image);
        let half = image.reduced(2);
        assert_eq!((half.width, half.height), (3, 2));
        assert_eq!(half.get(0, 0), Vec3::new(0.5, 0.5, 0.25));
        // Columns 4 only, rows 2 and 3.
        assert_eq!(half.get(2, 1), Vec3::new(4.0, 2.5, 10.0));
        let whole = image.reduced(8);
        assert_eq!((whole.width, whole.height), (1, 1));
        assert_eq!(whole.get(0, 0), Vec3::new(2.0, 1.5, 3.0));
    }

    /// The bytes encoder and the file writer give the same PNG, and it
    /// decodes to the pixels.
    #[test]
    fn a_png_in_bytes_is_the_file_and_decodes_to_its_pixels() {
        let (w, h) = (7, 3);
        let pixels: Vec<u8> = (0..w * h * 3).map(|i| (i * 37 % 251) as u8).collect();
        let mut bytes = Vec::new();
        encode_srgb8_png(&mut bytes, w, h, &pixels).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.png");
        write_srgb8_png(&path, w, h, &pixels).unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), bytes);
        let decoded = image::load_from_memory(&bytes).unwrap().to_rgb8();
        assert_eq!(decoded.into_raw(), pixels);
    }

    /// A refilled image is the new one whatever it held before, larger or
    /// smaller.
    #[test]
    fn a_refilled_image_is_a_new_one() {
        let mut image = Image::new(4, 3, Vec3::splat(f32::NAN));
        image.set(3, 2, Vec3::X);
        for (w, h, fill) in [
            (2, 2, Vec3::Y),
            (5, 4, Vec3::ONE),
            (0, 7, Vec3::ZERO),
            (3, 1, Vec3::Z),
        ] {
            image.refill(w, h, fill);
            assert!(image == Image::new(w, h, fill), "{w}x{h}");
        }
    }

    #[test]
    fn srgb_round_trips_and_hits_the_ends() {
        for i in 0..=255u32 {
            let s = i as f32 / 255.0;
            assert!((linear_to_srgb(srgb_to_linear(s)) - s).abs() < 1e-5);
        }
        assert_eq!(encode_srgb8(Vec3::ZERO), [0, 0, 0]);
        assert_eq!(encode_srgb8(Vec3::ONE), [255, 255, 255]);
        assert_eq!(encode_srgb8(Vec3::splat(0.214_041_14)), [128, 128, 128]);
    }

    /// The table gives the rule's bytes for every float in [0, 1] (about a
    /// billion: seconds in the optimised test profile) and the special values.
    #[test]
    fn the_srgb8_table_gives_exactly_the_rules_codes() {
        let table = Srgb8Table::get();
        let check = |v: f32| assert_eq!(table.encode(v), srgb8_channel(v), "{v:e}");
        for b in 0..=1.0f32.to_bits() {
            check(f32::from_bits(b));
        }
        for v in [
            0.0,
            -0.0,
            -1.0,
            1.0,
            1.5,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
            f32::MIN_POSITIVE,
            1e-45,
        ] {
            check(v);
        }
        let image = Image {
            width: 2,
            height: 1,
            pixels: vec![Vec3::new(0.2, 0.5, 2.0), Vec3::new(f32::NAN, -1.0, 0.003)],
        };
        let by_rule: Vec<u8> = image.pixels.iter().flat_map(|c| encode_srgb8(*c)).collect();
        assert_eq!(image.to_srgb8(), by_rule);
        // Into a buffer that held more, and less.
        for stale in [vec![7; 100], vec![9; 2]] {
            let mut out = stale;
            image.to_srgb8_into(&mut out);
            assert_eq!(out, by_rule);
        }
    }

    /// A region's conversion writes exactly the whole image's bytes inside
    /// it and leaves every byte outside it as it was: the bytes of an
    /// image changed only there, converted before, come out as the changed
    /// image's whole conversion.
    #[test]
    fn a_regions_conversion_writes_the_whole_images_bytes_there_only() {
        let (width, height) = (300u32, 700u32);
        let pixel =
            |i: u32, k: f32| Vec3::new((i % 97) as f32 / 50.0 * k, 0.25 * k, (i % 7) as f32 * 0.1);
        let before = Image {
            width,
            height,
            pixels: (0..width * height).map(|i| pixel(i, 1.0)).collect(),
        };
        let (columns, rows) = (17..250, 3..690);
        let mut after = before.clone();
        for (y, x) in rows
            .clone()
            .flat_map(|y| columns.clone().map(move |x| (y, x)))
        {
            after.set(x, y, pixel(y * width + x, 0.5));
        }
        assert!(
            rows.len() * columns.len() > 2 * SRGB_TASK_PIXELS,
            "several tasks"
        );
        let mut bytes = before.to_srgb8();
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(3)
            .build()
            .unwrap();
        pool.install(|| after.to_srgb8_region_into(&mut bytes, columns.clone(), rows.clone()));
        assert_eq!(bytes, after.to_srgb8());
        // Outside the region nothing is written.
        let mut stale = vec![0xab; bytes.len()];
        after.to_srgb8_region_into(&mut stale, columns.clone(), rows.clone());
        let inside = |i: usize| {
            let (x, y) = ((i / 3) as u32 % width, (i / 3) as u32 / width);
            columns.contains(&x) && rows.contains(&y)
        };
        for (i, (&got, &whole)) in stale.iter().zip(&bytes).enumerate() {
            assert_eq!(got, if inside(i) { whole } else { 0xab }, "byte {i}");
        }
        // An empty region writes nothing.
        let mut untouched = before.to_srgb8();
        after.to_srgb8_region_into(&mut untouched, 5..5, rows.clone());
        assert_eq!(untouched, before.to_srgb8());
    }

    #[test]
    fn png_reads_back_as_written() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.png");
        let mut img = Image::new(3, 2, Vec3::ZERO);
        img.set(2, 0, Vec3::new(1.0, 0.0, 0.5));
        img.write_png(&path).unwrap();
        let back = image::open(&path).unwrap().to_rgb8();
        assert_eq!(back.as_raw(), &img.to_srgb8());
        assert_eq!(
            back.get_pixel(2, 0).0,
            encode_srgb8(Vec3::new(1.0, 0.0, 0.5))
        );
    }

    #[test]
    fn npy_header_is_aligned_and_data_follows() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.npy");
        let img = Image::new(2, 1, Vec3::new(0.25, 0.5, 1.0));
        img.write_npy(&path).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let header_len = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
        assert_eq!((10 + header_len) % 64, 0);
        let header = std::str::from_utf8(&bytes[10..10 + header_len]).unwrap();
        assert!(header.contains("'shape': (1, 2, 3)"), "{header}");
        let first = f32::from_le_bytes(bytes[10 + header_len..14 + header_len].try_into().unwrap());
        assert_eq!(first, 0.25);
        assert_eq!(bytes.len(), 10 + header_len + 6 * 4);
    }
}
