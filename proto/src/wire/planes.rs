//! What the bitmap and image codecs share: values as little-endian byte
//! planes (byte 0 of every value, then byte 1 ...), which puts the slowly
//! varying sign and exponent bytes of neighbouring pixels side by side, and
//! zstd with a context per thread, decompressing into exactly the size the
//! caller expects.

use std::cell::RefCell;

use glam::Vec3;

use super::WireError;

/// zstd's fastest level: results are encoded once per package on the
/// worker's critical path, finished frames once per frame on the master's,
/// and level 1 already gets most of the gain.
const ZSTD_LEVEL: i32 = 1;

/// The pixels' channels as little-endian byte planes ([`byte_planes_into`]
/// of every channel), into `planes` (whatever it held).
pub(super) fn pixel_planes_into(pixels: &[Vec3], planes: &mut Vec<u8>) {
    let channels = pixels.iter().flat_map(|c| c.to_array());
    byte_planes_into(channels.map(f32::to_le_bytes), 3 * pixels.len(), planes);
}

/// Little-endian values as byte planes: byte 0 of every value, then byte 1 …
pub(super) fn byte_planes(values: &[[u8; 4]]) -> Vec<u8> {
    let mut planes = Vec::new();
    byte_planes_into(values.iter().copied(), values.len(), &mut planes);
    planes
}

/// [`byte_planes`] of `count` values into `planes` (whatever it held).
fn byte_planes_into(values: impl Iterator<Item = [u8; 4]>, count: usize, planes: &mut Vec<u8>) {
    planes.clear();
    planes.resize(4 * count, 0);
    for (i, bytes) in values.take(count).enumerate() {
        for (k, byte) in bytes.into_iter().enumerate() {
            planes[k * count + i] = byte;
        }
    }
}

thread_local! {
    /// zstd's contexts, one of each per thread, kept from call to call: a
    /// fresh one allocates its tables again for every result and frame.
    static COMPRESSOR: RefCell<Option<zstd::bulk::Compressor<'static>>> =
        const { RefCell::new(None) };
    static DECOMPRESSOR: RefCell<Option<zstd::bulk::Decompressor<'static>>> =
        const { RefCell::new(None) };
}

pub(super) fn compress(bytes: &[u8]) -> Vec<u8> {
    if bytes.is_empty() {
        return Vec::new();
    }
    // Compressing from memory into memory fails only on allocation failure.
    COMPRESSOR.with_borrow_mut(|compressor| {
        let compressor = compressor.get_or_insert_with(|| {
            zstd::bulk::Compressor::new(ZSTD_LEVEL).expect("zstd makes a context")
        });
        compressor
            .compress(bytes)
            .expect("zstd compresses in memory")
    })
}

/// Decompresses exactly `expected` bytes (no more may be allocated).
pub(super) fn decompress(field: &str, bytes: &[u8], expected: usize) -> Result<Vec<u8>, WireError> {
    let data = if expected == 0 && bytes.is_empty() {
        Vec::new()
    } else {
        let decompressed = DECOMPRESSOR.with_borrow_mut(|decompressor| {
            let decompressor = match decompressor {
                Some(d) => d,
                None => decompressor.insert(zstd::bulk::Decompressor::new()?),
            };
            decompressor.decompress(bytes, expected)
        });
        decompressed.map_err(|e| WireError::Decode {
            what: "compressed data",
            message: format!("{field}: {e}"),
        })?
    };
    if data.len() != expected {
        return Err(WireError::SizeMismatch {
            field: field.to_owned(),
            expected: expected as u64,
            actual: data.len() as u64,
        });
    }
    Ok(data)
}
