//! The instrument area and its markings as seen through the cover glass,
//! from the ID buffer of everything behind the glass.

use vtfarm_scene::{Camera, ObjectId, Scene, TriangleId};

/// Per-pixel masks of one frame (row-major, like the frame).
#[derive(Clone, Debug, PartialEq)]
pub struct InstrumentMasks {
    /// Glass pixels through which an instrument object is seen.
    pub instrument: Vec<bool>,
    /// Instrument pixels that show a marking object.
    pub marking: Vec<bool>,
    /// Each instrument object seen through the glass, with the centre of
    /// its pixels (pixel coordinates): where the sun's glint veils it.
    pub centres: Vec<(ObjectId, [f32; 2])>,
}

impl InstrumentMasks {
    /// Rasterizes what lies behind the reflectors (the scene without them and
    /// without transparent surfaces) and marks the glass pixels that show
    /// one of `instrument` (and of `marking`).
    pub fn new(
        scene: &Scene,
        camera: &Camera,
        reflectors: &[TriangleId],
        glass: &[bool],
        instrument: &[ObjectId],
        marking: &[ObjectId],
    ) -> Self {
        let mut is_reflector = vec![false; scene.triangles.len()];
        for &t in reflectors {
            is_reflector[t.index()] = true;
        }
        let behind = vtfarm_vertex::behind_id_buffer(scene, camera, &is_reflector);
        let instrument_objects = instrument;
        let instrument: Vec<bool> = behind
            .object
            .iter()
            .zip(glass)
            .map(|(&o, &g)| g && instrument.contains(&ObjectId(o)))
            .collect();
        let marking = behind
            .object
            .iter()
            .zip(&instrument)
            .map(|(&o, &i)| i && marking.contains(&ObjectId(o)))
            .collect();
        let width = camera.width as usize;
        let centres = (instrument_objects.iter())
            .filter_map(|&object| {
                let (mut n, mut sx, mut sy) = (0usize, 0f64, 0f64);
                for (i, _) in (behind.object.iter().zip(glass).enumerate())
                    .filter(|(_, (o, g))| **g && **o == object.raw())
                {
                    n += 1;
                    sx += (i % width) as f64 + 0.5;
                    sy += (i / width) as f64 + 0.5;
                }
                (n > 0).then(|| (object, [(sx / n as f64) as f32, (sy / n as f64) as f32]))
            })
            .collect();
        InstrumentMasks {
            instrument,
            marking,
            centres,
        }
    }
}
