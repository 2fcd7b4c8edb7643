//! Rasterized transmission of the base frame: glass that is no reflector
//! (a window, a lamp's cover, the other glass objects of an exported
//! scene) blended over what lies behind it, as a rasterizer draws a
//! transparent surface, instead of its own dark colour alone.

use std::collections::BTreeSet;

use glam::Vec3;
use rayon::prelude::*;
use vtfarm_imaging::Image;
use vtfarm_scene::shading::phong;
use vtfarm_scene::{Camera, Lighting, NONE, ObjectId, Projector, Scene, TriangleId};

use crate::{IdBuffer, IdPass, PixelRect};

/// Adds to each pixel of `image` (the base frame shaded from `ids`, a
/// buffer of the whole frame) whose triangle is see-through and not a
/// reflector (`is_reflector` per triangle; reflector pixels are the
/// reflection methods' to finish) kt times the opaque scene behind it,
/// seen straight along the pixel's ray and shaded as the base frame is
/// (local Phong, no shadows). kt is the glass's head-on transmittance, and
/// that of the glass's back surface when one faces away behind it (a
/// closed glass object). Nothing is done (no pass over the pixels) unless
/// such glass exists; deterministic for any thread count. Returns the
/// objects of the glass it blended, ascending (for the caller's warning:
/// such glass shows no reflection).
pub fn blend_see_through(
    scene: &Scene,
    camera: &Camera,
    lighting: &Lighting,
    ids: &IdBuffer,
    image: &mut Image,
    is_reflector: &[bool],
) -> Vec<ObjectId> {
    let see_through = |t: TriangleId| scene.material_of(t).see_through();
    let glass: Vec<bool> = scene
        .triangle_ids()
        .map(|t| see_through(t) && !is_reflector.get(t.index()).copied().unwrap_or(false))
        .collect();
    if !glass.contains(&true) || ids.width == 0 {
        return Vec::new();
    }
    let is_glass = |t: u32| t != NONE && glass[t as usize];
    let width = ids.width as usize;
    // The rectangle of the glass pixels, row by row.
    let rows: Vec<Option<(u32, u32)>> = ids
        .triangle
        .par_chunks(width)
        .map(|row| {
            let first = row.iter().position(|&t| is_glass(t))?;
            let last = row.iter().rposition(|&t| is_glass(t))?;
            Some((first as u32, last as u32 + 1))
        })
        .collect();
    let mut within: Option<PixelRect> = None;
    for (y, span) in rows.iter().enumerate() {
        if let Some((x0, x1)) = *span {
            let row = PixelRect {
                x0,
                y0: y as u32,
                x1,
                y1: y as u32 + 1,
            };
            within = Some(within.map_or(row, |w| w.union(row)));
        }
    }
    let Some(within) = within else {
        return Vec::new();
    };
    let eye = camera.eye;
    let opaque = |t: TriangleId| !see_through(t);
    // The back of a closed glass object: glass facing away from the eye.
    let back = |t: TriangleId| glass[t.index()] && faces_away(scene, eye, t);
    let passes = [
        IdPass {
            within,
            keep: &opaque,
        },
        IdPass {
            within,
            keep: &back,
        },
    ];
    let [behind, backs]: [IdBuffer; 2] = crate::id_buffers_within(scene, camera, &passes)
        .try_into()
        .expect("one buffer per pass");
    let projector = Projector::new(camera);
    let footprint = camera.pixel_size_at_unit_depth();
    let objects: BTreeSet<ObjectId> = image
        .pixels
        .par_chunks_mut(width)
        .zip(ids.triangle.par_chunks(width))
        .enumerate()
        .filter(|(y, _)| rows[*y].is_some())
        .map(|(y, (colors, triangles))| {
            let y = y as u32;
            let mut objects = BTreeSet::new();
            for (x, (color, &front)) in colors.iter_mut().zip(triangles).enumerate() {
                if !is_glass(front) {
                    continue;
                }
                let front = TriangleId(front);
                objects.insert(scene.triangles[front.index()].object);
                let x = x as u32;
                // The glass's own transmittance, and its back's when the
                // back lies between it and the opaque scene.
                let mut kt = transmittance(
                    scene,
                    front,
                    eye + projector.pixel_depth_step(x, y) * ids.depth_at(x, y),
                    footprint,
                    eye,
                );
                let b = backs.triangle_at(x, y);
                if b != NONE && b != front.raw() && backs.depth_at(x, y) < behind.depth_at(x, y) {
                    let at = eye + projector.pixel_depth_step(x, y) * backs.depth_at(x, y);
                    kt *= transmittance(scene, TriangleId(b), at, footprint, eye);
                }
                if kt.max_element() <= 0.0 {
                    continue;
                }
                let seen = match behind.triangle_at(x, y) {
                    NONE => lighting.background,
                    t => {
                        let position =
                            eye + projector.pixel_depth_step(x, y) * behind.depth_at(x, y);
                        shade(scene, lighting, TriangleId(t), position, eye, footprint)
                    }
                };
                *color += kt * seen;
            }
            objects
        })
        .reduce(BTreeSet::new, |mut a, b| {
            a.extend(b);
            a
        });
    objects.into_iter().collect()
}

/// Whether `triangle`'s front (its winding's normal) faces away from `eye`.
fn faces_away(scene: &Scene, eye: Vec3, triangle: TriangleId) -> bool {
    let [a, ..] = scene.triangle_positions(triangle);
    (a - eye).dot(scene.geometric_normal(triangle)) > 0.0
}

/// The transmittance of `triangle` at `position` (textured: an alpha map).
fn transmittance(
    scene: &Scene,
    triangle: TriangleId,
    position: Vec3,
    footprint: f32,
    eye: Vec3,
) -> Vec3 {
    let material = scene.material_of(triangle);
    if !material.is_textured() {
        return material.transmittance;
    }
    let weights = scene.barycentrics(triangle, position);
    let size = (position - eye).length() * footprint;
    (scene.textured_material(triangle, weights, size)).transmittance
}

/// Local Phong (no shadows) of `triangle` at `position`, seen from `eye`.
fn shade(
    scene: &Scene,
    lighting: &Lighting,
    triangle: TriangleId,
    position: Vec3,
    eye: Vec3,
    footprint: f32,
) -> Vec3 {
    let weights = scene.barycentrics(triangle, position);
    let [na, nb, nc] = scene.triangle_normals(triangle);
    let normal = (na * weights.x + nb * weights.y + nc * weights.z)
        .normalize_or(scene.geometric_normal(triangle).normalize_or(Vec3::Y));
    let size = (position - eye).length() * footprint;
    let material = scene.textured_material(triangle, weights, size);
    phong(
        &material,
        lighting,
        position,
        normal,
        (eye - position).normalize_or(normal),
        |_, _, _| true,
    )
}
