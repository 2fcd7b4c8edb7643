//! The view's stage messages: what the master streams to the dashboard per
//! move of the eye (`GET /view/stream`, the format in `docs/http-api.md`).
//!
//! A `preview` or `refine` stage is the reflector's refinement meshes with
//! their traced samples and the glass's weights ([`StageMessage::Mesh`]):
//! the page Gouraud-shades them with the vertex colours over what it draws
//! behind the glass, weighted as the CPU's thin-glass pass weights it. A
//! `full` stage is a sparse pixel overlay ([`StageMessage::Overlay`]): the
//! finished frame's reflector pixels, which the page draws while the eye
//! stays. Each carries its move's number, so a page drops what a newer move
//! made outdated. Little-endian throughout; floats travel as their bits,
//! so a decoded sample is the traced one byte for byte.

use glam::Vec3;
use vtfarm_vertex::{FrameImage, PixelValue, Quality, SlabWeights, StageMesh};

/// The first bytes of every stage message.
pub const MAGIC: [u8; 4] = *b"VTVS";
/// The format's version, after [`MAGIC`].
pub const VERSION: u8 = 2;
/// Bytes before a message's body: magic, version, kind, quality, a zero
/// byte, the move (u64) and the eye (three f32).
pub const HEADER_BYTES: usize = 4 + 4 + 8 + 12;

const KIND_MESH: u8 = 1;
const KIND_OVERLAY: u8 = 2;

/// What every stage message starts with.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StageHeader {
    /// The move (the view's generation) the stage belongs to.
    pub generation: u64,
    pub quality: Quality,
    /// The eye the stage was traced from, in world metres.
    pub eye: Vec3,
}

/// A decoded stage message.
#[derive(Clone, Debug, PartialEq)]
pub enum StageMessage {
    /// A `preview` or `refine` stage: every reflector triangle's mesh.
    Mesh {
        header: StageHeader,
        meshes: Vec<StageMesh>,
    },
    /// A `full` stage: the frame's reflector pixels.
    Overlay {
        header: StageHeader,
        overlay: Overlay,
    },
}

impl StageMessage {
    pub fn header(&self) -> &StageHeader {
        match self {
            StageMessage::Mesh { header, .. } | StageMessage::Overlay { header, .. } => header,
        }
    }
}

/// The reflector pixels of a finished frame: a rectangle, a coverage mask
/// (row-major in it) and each covered pixel's linear colour, in mask order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Overlay {
    /// The frame's size.
    pub frame_width: u32,
    pub frame_height: u32,
    pub x0: u32,
    pub y0: u32,
    pub width: u32,
    pub height: u32,
    pub mask: Vec<bool>,
    pub colors: Vec<Vec3>,
}

impl Overlay {
    /// Every pixel `image`'s traced bitmaps wrote, over their bounding rectangle.
    pub fn of(image: &FrameImage) -> Overlay {
        let frame_width = image.color.width;
        let xy = |i: usize| {
            (
                (i % frame_width as usize) as u32,
                (i / frame_width as usize) as u32,
            )
        };
        let (mut x0, mut y0, mut x1, mut y1) = (u32::MAX, u32::MAX, 0, 0);
        for (x, y) in image.glass().map(xy) {
            (x0, y0, x1, y1) = (x0.min(x), y0.min(y), x1.max(x + 1), y1.max(y + 1));
        }
        let mut overlay = Overlay {
            frame_width,
            frame_height: image.color.height,
            ..Overlay::default()
        };
        if x0 >= x1 {
            return overlay;
        }
        let width = x1 - x0;
        overlay.x0 = x0;
        overlay.y0 = y0;
        overlay.width = width;
        overlay.height = y1 - y0;
        overlay.mask = vec![false; (width * (y1 - y0)) as usize];
        for i in image.glass() {
            let (x, y) = xy(i);
            overlay.mask[((y - y0) * width + x - x0) as usize] = true;
            overlay.colors.push(image.color.pixels[i]);
        }
        overlay
    }

    /// The covered pixels: (x, y) in the frame and the colour.
    pub fn pixels(&self) -> impl Iterator<Item = (u32, u32, Vec3)> + '_ {
        let width = self.width.max(1);
        (self.mask.iter().enumerate())
            .filter(|(_, m)| **m)
            .zip(&self.colors)
            .map(move |((i, _), &c)| (self.x0 + i as u32 % width, self.y0 + i as u32 / width, c))
    }
}

/// Why bytes are not a stage message.
#[derive(Debug, PartialEq, Eq, thiserror::Error)]
pub enum StreamError {
    #[error("not a stage message (bad magic)")]
    Magic,
    #[error("stage message version {0}, this reads {VERSION}")]
    Version(u8),
    #[error("unknown stage message kind {0}")]
    Kind(u8),
    #[error("unknown quality {0}")]
    Quality(u8),
    #[error("the message ends early, at byte {0}")]
    Short(usize),
    #[error("{0} bytes after the message's end")]
    Trailing(usize),
    #[error("{field} = {value} is out of range")]
    OutOfRange { field: &'static str, value: u64 },
}

fn quality_code(q: Quality) -> u8 {
    q as u8
}

fn quality_of(code: u8) -> Result<Quality, StreamError> {
    (Quality::ALL.get(code as usize).copied()).ok_or(StreamError::Quality(code))
}

fn header_bytes(out: &mut Vec<u8>, kind: u8, header: &StageHeader) {
    out.extend(MAGIC);
    out.extend([VERSION, kind, quality_code(header.quality), 0]);
    out.extend(header.generation.to_le_bytes());
    vec3(out, header.eye);
}

fn vec3(out: &mut Vec<u8>, v: Vec3) {
    for c in v.to_array() {
        out.extend(c.to_le_bytes());
    }
}

/// Bytes per vertex of a mesh stage's message.
const VERTEX_BYTES: u64 = 4 * 3 * 5 + 4 + 4;

/// A mesh stage's message: counts of vertices and faces, then per vertex
/// its position, colour, reflected and transmitted parts (each three f32,
/// plane after plane), reflected object (u32), what the glass lets through
/// of the scene behind (three f32) and the factor on its reflection (f32)
/// ([`SlabWeights`]), then the faces (three u32 each, indices over all the
/// meshes' vertices in order).
pub fn encode_mesh(header: &StageHeader, meshes: &[StageMesh]) -> Vec<u8> {
    let vertices: usize = meshes.iter().map(|m| m.positions.len()).sum();
    let faces: usize = meshes.iter().map(|m| m.faces.len()).sum();
    let mut out =
        Vec::with_capacity(HEADER_BYTES + 8 + vertices * VERTEX_BYTES as usize + faces * 12);
    header_bytes(&mut out, KIND_MESH, header);
    out.extend((vertices as u32).to_le_bytes());
    out.extend((faces as u32).to_le_bytes());
    for m in meshes {
        m.positions.iter().for_each(|&p| vec3(&mut out, p));
    }
    let samples = || meshes.iter().flat_map(|m| &m.samples);
    let planes: [fn(&PixelValue) -> Vec3; 3] = [|s| s.color, |s| s.reflected, |s| s.transmitted];
    for plane in planes {
        samples().for_each(|s| vec3(&mut out, plane(s)));
    }
    samples().for_each(|s| out.extend(s.object.to_le_bytes()));
    let slabs = || meshes.iter().flat_map(|m| &m.slabs);
    slabs().for_each(|s| vec3(&mut out, s.behind));
    slabs().for_each(|s| out.extend(s.reflection_scale.to_le_bytes()));
    let mut base = 0u32;
    for m in meshes {
        for v in m.faces.iter().flatten() {
            out.extend((base + v).to_le_bytes());
        }
        base += m.positions.len() as u32;
    }
    out
}

/// An overlay stage's message: the frame's width and height, the
/// rectangle (x0, y0, width, height; u32 each), the mask (one bit a pixel,
/// row-major, lowest bit first, padded to a byte) and each covered pixel's
/// linear colour (three f32).
pub fn encode_overlay(header: &StageHeader, overlay: &Overlay) -> Vec<u8> {
    let mut out = Vec::with_capacity(
        HEADER_BYTES + 24 + overlay.mask.len().div_ceil(8) + overlay.colors.len() * 12,
    );
    header_bytes(&mut out, KIND_OVERLAY, header);
    for v in [
        overlay.frame_width,
        overlay.frame_height,
        overlay.x0,
        overlay.y0,
        overlay.width,
        overlay.height,
    ] {
        out.extend(v.to_le_bytes());
    }
    let mut bits = vec![0u8; overlay.mask.len().div_ceil(8)];
    for (i, _) in overlay.mask.iter().enumerate().filter(|(_, m)| **m) {
        bits[i / 8] |= 1 << (i % 8);
    }
    out.extend(bits);
    overlay.colors.iter().for_each(|&c| vec3(&mut out, c));
    out
}

/// Reads bytes in order, failing at the first that is missing.
struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize) -> Result<&'a [u8], StreamError> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.bytes.len());
        let end = end.ok_or(StreamError::Short(self.bytes.len()))?;
        let taken = &self.bytes[self.at..end];
        self.at = end;
        Ok(taken)
    }

    fn u8(&mut self) -> Result<u8, StreamError> {
        Ok(self.take(1)?[0])
    }

    fn u32(&mut self) -> Result<u32, StreamError> {
        Ok(u32::from_le_bytes(
            self.take(4)?.try_into().expect("4 bytes"),
        ))
    }

    fn u64(&mut self) -> Result<u64, StreamError> {
        Ok(u64::from_le_bytes(
            self.take(8)?.try_into().expect("8 bytes"),
        ))
    }

    fn f32(&mut self) -> Result<f32, StreamError> {
        Ok(f32::from_bits(self.u32()?))
    }

    fn vec3(&mut self) -> Result<Vec3, StreamError> {
        Ok(Vec3::new(self.f32()?, self.f32()?, self.f32()?))
    }

    /// `count` items of `size` bytes must still be there (checked before
    /// anything is allocated for them).
    fn expect(&self, count: u64, size: u64, field: &'static str) -> Result<(), StreamError> {
        let left = (self.bytes.len() - self.at) as u64;
        if count.saturating_mul(size) > left {
            return Err(StreamError::OutOfRange {
                field,
                value: count,
            });
        }
        Ok(())
    }
}

/// Decodes one stage message (every byte of `bytes`). The meshes come back
/// as one [`StageMesh`] holding every vertex and face (its `triangle` 0).
pub fn decode(bytes: &[u8]) -> Result<StageMessage, StreamError> {
    let mut r = Reader { bytes, at: 0 };
    if r.take(4)? != MAGIC {
        return Err(StreamError::Magic);
    }
    let version = r.u8()?;
    if version != VERSION {
        return Err(StreamError::Version(version));
    }
    let kind = r.u8()?;
    let quality = quality_of(r.u8()?)?;
    r.u8()?;
    let header = StageHeader {
        generation: r.u64()?,
        quality,
        eye: r.vec3()?,
    };
    let message = match kind {
        KIND_MESH => {
            let vertices = r.u32()? as usize;
            let faces = r.u32()? as usize;
            r.expect(vertices as u64, VERTEX_BYTES, "vertices")?;
            let positions = (0..vertices)
                .map(|_| r.vec3())
                .collect::<Result<Vec<_>, _>>()?;
            let mut planes = [(); 3].map(|_| Vec::with_capacity(vertices));
            for plane in &mut planes {
                for _ in 0..vertices {
                    plane.push(r.vec3()?);
                }
            }
            let [color, reflected, transmitted] = planes;
            let mut samples = Vec::with_capacity(vertices);
            for k in 0..vertices {
                samples.push(PixelValue {
                    index: 0,
                    color: color[k],
                    reflected: reflected[k],
                    transmitted: transmitted[k],
                    object: r.u32()?,
                });
            }
            let behind = (0..vertices)
                .map(|_| r.vec3())
                .collect::<Result<Vec<_>, _>>()?;
            let mut slabs = Vec::with_capacity(vertices);
            for behind in behind {
                let reflection_scale = r.f32()?;
                slabs.push(SlabWeights {
                    behind,
                    reflection_scale,
                });
            }
            r.expect(faces as u64, 12, "faces")?;
            let mut face_list = Vec::with_capacity(faces);
            for _ in 0..faces {
                let face = [r.u32()?, r.u32()?, r.u32()?];
                if let Some(&v) = face.iter().find(|&&v| v as usize >= vertices) {
                    let field = "face vertex";
                    return Err(StreamError::OutOfRange {
                        field,
                        value: v.into(),
                    });
                }
                face_list.push(face);
            }
            let mesh = StageMesh {
                triangle: vtfarm_scene::TriangleId(0),
                positions,
                samples,
                slabs,
                faces: face_list,
            };
            StageMessage::Mesh {
                header,
                meshes: vec![mesh],
            }
        }
        KIND_OVERLAY => {
            let (frame_width, frame_height) = (r.u32()?, r.u32()?);
            let (x0, y0, width, height) = (r.u32()?, r.u32()?, r.u32()?, r.u32()?);
            let inside = |start: u32, len: u32, size: u32| {
                start.checked_add(len).is_some_and(|end| end <= size)
            };
            if !inside(x0, width, frame_width) || !inside(y0, height, frame_height) {
                let field = "overlay rectangle";
                let value = u64::from(x0.max(y0));
                return Err(StreamError::OutOfRange { field, value });
            }
            let n = u64::from(width) * u64::from(height);
            r.expect(n.div_ceil(8), 1, "overlay mask")?;
            let bits = r.take(n.div_ceil(8) as usize)?;
            let mask: Vec<bool> = (0..n as usize)
                .map(|i| bits[i / 8] >> (i % 8) & 1 == 1)
                .collect();
            let covered = mask.iter().filter(|&&m| m).count();
            r.expect(covered as u64, 12, "overlay pixels")?;
            let colors = (0..covered).map(|_| r.vec3()).collect::<Result<_, _>>()?;
            let overlay = Overlay {
                frame_width,
                frame_height,
                x0,
                y0,
                width,
                height,
                mask,
                colors,
            };
            StageMessage::Overlay { header, overlay }
        }
        other => return Err(StreamError::Kind(other)),
    };
    if r.at != bytes.len() {
        return Err(StreamError::Trailing(bytes.len() - r.at));
    }
    Ok(message)
}

/// Joins meshes into one, as [`decode`] returns them: the vertices in
/// order, the faces' indices over them all.
pub fn joined(meshes: &[StageMesh]) -> StageMesh {
    let mut out = StageMesh::default();
    for m in meshes {
        let base = out.positions.len() as u32;
        out.positions.extend(&m.positions);
        out.samples.extend(&m.samples);
        out.slabs.extend(&m.slabs);
        out.faces
            .extend(m.faces.iter().map(|f| f.map(|v| base + v)));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(k: f32) -> PixelValue {
        PixelValue {
            index: 0,
            color: Vec3::new(k, 0.5 * k, f32::from_bits(0x3e80_0001)),
            reflected: Vec3::splat(k * 0.25),
            transmitted: Vec3::new(0.0, -0.0, k),
            object: k as u32,
        }
    }

    fn slab(k: f32) -> SlabWeights {
        SlabWeights {
            behind: Vec3::new(0.7 * k, -0.0, f32::from_bits(0x3f00_0001)),
            reflection_scale: 1.0 + k,
        }
    }

    fn header(quality: Quality) -> StageHeader {
        StageHeader {
            generation: 0x0102_0304_0506_0708,
            quality,
            eye: Vec3::new(0.1, -0.2, 1.3),
        }
    }

    #[test]
    fn a_mesh_stage_decodes_to_its_meshes_joined_bit_for_bit() {
        let meshes = [
            StageMesh {
                triangle: vtfarm_scene::TriangleId(4),
                positions: vec![Vec3::X, Vec3::Y, Vec3::Z],
                samples: vec![sample(1.0), sample(2.0), sample(3.0)],
                slabs: vec![slab(1.0), slab(2.0), slab(3.0)],
                faces: vec![[0, 1, 2]],
            },
            StageMesh {
                triangle: vtfarm_scene::TriangleId(9),
                positions: vec![Vec3::ONE, Vec3::NEG_ONE, Vec3::ZERO, Vec3::X],
                samples: vec![sample(4.0), sample(5.0), sample(6.0), sample(7.0)],
                slabs: vec![slab(4.0), slab(5.0), slab(6.0), slab(7.0)],
                faces: vec![[0, 1, 3], [3, 1, 2]],
            },
        ];
        let bytes = encode_mesh(&header(Quality::Refine), &meshes);
        assert_eq!(bytes.len(), HEADER_BYTES + 8 + 7 * 68 + 3 * 12);
        let StageMessage::Mesh {
            header: h,
            meshes: decoded,
        } = decode(&bytes).unwrap()
        else {
            panic!("a mesh stage")
        };
        assert_eq!(h, header(Quality::Refine));
        assert_eq!(decoded, [joined(&meshes)]);
        assert_eq!(decoded[0].faces[2], [6, 4, 5]);
        let bits = |v: Vec3| v.to_array().map(f32::to_bits);
        let sent = meshes.iter().flat_map(|m| &m.samples);
        for (a, b) in sent.zip(&decoded[0].samples) {
            assert_eq!(bits(a.color), bits(b.color));
            assert_eq!(bits(a.transmitted), bits(b.transmitted));
        }
        let sent = meshes.iter().flat_map(|m| &m.slabs);
        for (a, b) in sent.zip(&decoded[0].slabs) {
            assert_eq!(bits(a.behind), bits(b.behind));
            assert_eq!(a.reflection_scale.to_bits(), b.reflection_scale.to_bits());
        }
    }

    #[test]
    fn an_overlay_decodes_to_the_frames_reflector_pixels() {
        let mut image = FrameImage::new(
            vtfarm_imaging::Image::new(7, 5, Vec3::splat(0.5)),
            vtfarm_raster::PixelRect {
                x0: 1,
                y0: 1,
                x1: 6,
                y1: 4,
            },
        );
        let written = [(2, 1, 0.1), (5, 1, 0.2), (3, 3, 0.3)];
        for (x, y, c) in written {
            image.set_pixel(&PixelValue {
                index: y * 7 + x,
                color: Vec3::splat(c),
                reflected: Vec3::ZERO,
                transmitted: Vec3::ZERO,
                object: 0,
            });
        }
        let overlay = Overlay::of(&image);
        assert_eq!(
            (overlay.x0, overlay.y0, overlay.width, overlay.height),
            (2, 1, 4, 3)
        );
        let bytes = encode_overlay(&header(Quality::Full), &overlay);
        let StageMessage::Overlay { overlay: back, .. } = decode(&bytes).unwrap() else {
            panic!("an overlay")
        };
        assert_eq!(back, overlay);
        let pixels: Vec<(u32, u32, Vec3)> = back.pixels().collect();
        let expected: Vec<(u32, u32, Vec3)> = written
            .iter()
            .map(|&(x, y, c)| (x, y, Vec3::splat(c)))
            .collect();
        assert_eq!(pixels, expected);
    }

    #[test]
    fn damaged_messages_are_refused_by_name() {
        let bytes = encode_overlay(&header(Quality::Full), &Overlay::default());
        assert_eq!(decode(&bytes[..10]), Err(StreamError::Short(10)));
        assert_eq!(decode(b"VTVX0000"), Err(StreamError::Magic));
        let mut extra = bytes.clone();
        extra.push(0);
        assert_eq!(decode(&extra), Err(StreamError::Trailing(1)));
        let mut kind = bytes.clone();
        kind[5] = 9;
        assert_eq!(decode(&kind), Err(StreamError::Kind(9)));
        // A face naming a vertex that is not there.
        let mesh = StageMesh {
            triangle: vtfarm_scene::TriangleId(0),
            positions: vec![Vec3::X],
            samples: vec![sample(1.0)],
            slabs: vec![slab(1.0)],
            faces: vec![[0, 0, 0]],
        };
        let mut bad = encode_mesh(&header(Quality::Preview), &[mesh]);
        let last = bad.len() - 4;
        bad[last] = 5;
        assert!(matches!(decode(&bad), Err(StreamError::OutOfRange { .. })));
        // A huge count is refused before anything is allocated for it.
        let mut huge = encode_mesh(&header(Quality::Preview), &[]);
        huge[HEADER_BYTES..HEADER_BYTES + 4].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(matches!(decode(&huge), Err(StreamError::OutOfRange { .. })));
    }
}
