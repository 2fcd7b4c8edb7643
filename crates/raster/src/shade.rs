//! Deferred shading of the base frame: visibility is resolved first, then
//! each pixel is lit once with the shared local Phong model (no shadows, no
//! ray tracing).

use glam::Vec3;
use rayon::prelude::*;
use vtfarm_imaging::Image;
use vtfarm_scene::{Camera, LightKind, Lighting, Material, NONE, Scene, TriangleId};

#[cfg(target_arch = "x86_64")]
use crate::lanes::Avx2;
use crate::lanes::{Backend, F, LANES, Portable, V3};

use crate::IdBuffer;

/// Rows per rayon task: enough work per task to amortise scheduling.
const ROWS_PER_TASK: usize = 8;

/// Triangle set-ups a task keeps, by triangle id modulo this: a triangle
/// seen in a row is mostly seen in the next, between a hundred or so others
/// at 1080p.
const SURFACE_SLOTS: usize = 512;

/// Shades every pixel of `ids`, a buffer of the whole frame; empty pixels
/// get the background.
pub(crate) fn shade(scene: &Scene, camera: &Camera, lighting: &Lighting, ids: &IdBuffer) -> Image {
    let mut image = Image::new(0, 0, lighting.background);
    shade_into(scene, camera, lighting, ids, &mut image);
    image
}

/// [`shade`] into `image`, whatever it holds.
pub(crate) fn shade_into(
    scene: &Scene,
    camera: &Camera,
    lighting: &Lighting,
    ids: &IdBuffer,
    image: &mut Image,
) {
    assert_eq!(
        ids.window,
        crate::PixelRect::full(ids.width, ids.height),
        "shading needs an ID buffer of the whole frame"
    );
    // Every pixel is written below (empty ones get the background), so a
    // reused image of the right size is not filled first.
    (image.width, image.height) = (ids.width, ids.height);
    image.pixels.resize(
        ids.width as usize * ids.height as usize,
        lighting.background,
    );
    let width = ids.width as usize;
    if width == 0 {
        return;
    }
    let frame = FrameShading::new(scene, camera, lighting);
    image
        .pixels
        .par_chunks_mut(width * ROWS_PER_TASK)
        .zip(ids.triangle.par_chunks(width * ROWS_PER_TASK))
        .enumerate()
        .for_each(|(task, (colors, triangles))| {
            let first_row = (task * ROWS_PER_TASK) as u32;
            frame.shade_rows(first_row, colors, triangles);
        });
}

/// What shading needs of the camera and the lights, set up once per frame.
struct FrameShading<'a> {
    scene: &'a Scene,
    lighting: &'a Lighting,
    eye: Vec3,
    /// The frame's width in pixels.
    width: usize,
    /// Per column, the pixel ray's part that depends on the column
    /// (`Projector::pixel_ray` before its row term and normalization), by
    /// component, padded with [`LANES`] zeros so that a row's last lanes
    /// load whole registers.
    columns: [Vec<f32>; 3],
    up: Vec3,
    pixel: f32,
    half_height: f32,
    lights: Vec<LightTerms>,
}

/// A light as the shading of every pixel sees it.
struct LightTerms {
    toward: Toward,
    radiance: Vec3,
}

enum Toward {
    /// The unit direction towards a directional light, normalized once.
    Direction(Vec3),
    Point(Vec3),
}

impl<'a> FrameShading<'a> {
    fn new(scene: &'a Scene, camera: &Camera, lighting: &'a Lighting) -> Self {
        // The arithmetic of `Projector::ray_direction`, split into a column
        // and a row term (the test `pixel_rays_are_the_projectors` pins it).
        let (forward, right, up) = camera.basis();
        let pixel = camera.pixel_size_at_unit_depth();
        let half_width = camera.width as f32 * 0.5;
        let column = |x: u32| forward + right * ((x as f32 + 0.5 - half_width) * pixel);
        let padded = |component: fn(Vec3) -> f32| {
            (0..camera.width)
                .map(|x| component(column(x)))
                .chain([0.0; LANES])
                .collect()
        };
        let columns = [padded(|v| v.x), padded(|v| v.y), padded(|v| v.z)];
        let lights = lighting
            .lights
            .iter()
            .map(|light| LightTerms {
                toward: match light.kind {
                    LightKind::Directional { .. } => {
                        Toward::Direction(light.direction_from(Vec3::ZERO).0)
                    }
                    LightKind::Point { position } => Toward::Point(position),
                },
                radiance: light.radiance(),
            })
            .collect();
        FrameShading {
            scene,
            lighting,
            eye: camera.eye,
            width: camera.width as usize,
            columns,
            up,
            pixel,
            half_height: camera.height as f32 * 0.5,
            lights,
        }
    }

    /// Shades whole rows from `first_row` on: their pixels `colors`, their
    /// ID buffer rows `triangles`. With AVX2 where this CPU has it: the same
    /// bits either way (IEEE arithmetic is exact per lane and nothing is
    /// fused).
    fn shade_rows(&self, first_row: u32, colors: &mut [Vec3], triangles: &[u32]) {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports AVX2, checked just above.
            unsafe { self.shade_rows_avx2(first_row, colors, triangles) };
            return;
        }
        self.shade_rows_with::<Portable>(first_row, colors, triangles);
    }

    /// [`Self::shade_rows_with`] in AVX registers, compiled for AVX2.
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn shade_rows_avx2(&self, first_row: u32, colors: &mut [Vec3], triangles: &[u32]) {
        self.shade_rows_with::<Avx2>(first_row, colors, triangles);
    }

    /// See [`Self::shade_rows`]. A row is shaded run by run of pixels that
    /// see the same triangle, with the triangle's set-up from a small cache
    /// (a triangle's runs in neighbouring rows reuse it); empty runs get the
    /// background.
    #[inline(always)]
    fn shade_rows_with<B: Backend>(&self, first_row: u32, colors: &mut [Vec3], triangles: &[u32]) {
        let width = self.width;
        let mut surfaces: Vec<Option<Surface>> = (0..SURFACE_SLOTS).map(|_| None).collect();
        let rows = colors.chunks_mut(width).zip(triangles.chunks(width));
        for (row, (colors, triangles)) in rows.enumerate() {
            let row_ray = V3::splat(self.row_ray(first_row + row as u32));
            let mut x = 0;
            while x < width {
                let t = triangles[x];
                let mut run = 1;
                while x + run < width && triangles[x + run] == t {
                    run += 1;
                }
                if t == NONE {
                    colors[x..x + run].fill(self.lighting.background);
                } else {
                    let t = TriangleId(t);
                    let surface = match &mut surfaces[t.index() % SURFACE_SLOTS] {
                        Some(s) if s.id == t => s,
                        slot => slot.insert(Surface::new(self, t)),
                    };
                    for start in (x..x + run).step_by(LANES) {
                        let color = self.shade::<B>(surface, row_ray, start, x + run - start);
                        // Whole registers where the row has room: lanes
                        // beyond the run land on pixels of later runs,
                        // which their own runs overwrite.
                        match colors.get_mut(start..start + LANES) {
                            // A copy of a constant size: no call.
                            Some(whole) => whole.copy_from_slice(&color),
                            None => colors[start..].copy_from_slice(&color[..width - start]),
                        }
                    }
                }
                x += run;
            }
        }
    }

    /// The pixel ray's row term for row `y`.
    fn row_ray(&self, y: u32) -> Vec3 {
        self.up * ((self.half_height - (y as f32 + 0.5)) * self.pixel)
    }

    /// The pixel rays of columns `x0..x0 + LANES` with row term `row_ray`,
    /// before normalization (lanes beyond the row read padding).
    #[inline(always)]
    fn column_rays<B: Backend>(&self, x0: usize, row_ray: V3<B>) -> V3<B> {
        let [x, y, z] = &self.columns;
        let lanes = x0..x0 + LANES;
        V3 {
            x: F::load(&x[lanes.clone()]),
            y: F::load(&y[lanes.clone()]),
            z: F::load(&z[lanes]),
        } + row_ray
    }

    /// Shades pixels `x0..x0 + used` (`used` at most [`LANES`]; the other
    /// lanes are padding) of a row with ray term `row_ray`, all on
    /// `surface`: Phong at the point the pixel ray meets the triangle,
    /// exactly as `vtfarm_scene::shading::phong` lights it.
    #[inline(always)]
    fn shade<B: Backend>(
        &self,
        surface: &Surface,
        row_ray: V3<B>,
        x0: usize,
        used: usize,
    ) -> [Vec3; LANES] {
        let used = used.min(LANES);
        let dir = self.column_rays(x0, row_ray).normalize();
        let w = perspective_barycentrics(surface.opposite, dir);
        let [n0, n1, n2] = surface.normals;
        let [n0, n1, n2] = [V3::splat(n0), V3::splat(n1), V3::splat(n2)];
        let normal = (n0 * w.x + n1 * w.y + n2 * w.z)
            .normalize_or_else(|| V3::splat(surface.scene.geometric_normal(surface.id)));
        let [c0, c1, c2] = surface.corners;
        let [c0, c1, c2] = [V3::splat(c0), V3::splat(c1), V3::splat(c2)];
        let offset = c0 * w.x + c1 * w.y + c2 * w.z;
        let to_eye = (-offset).normalize_or(-dir);
        let position = V3::splat(self.eye) + offset;
        let albedo = if surface.material.is_textured() {
            self.textured(surface, w, offset, used)
        } else {
            Albedo {
                diffuse: V3::splat(surface.material.diffuse),
                unlit: V3::splat(surface.unlit),
            }
        };
        self.phong(surface, &albedo, position, normal, to_eye, used)
            .to_array()
    }

    /// The textured diffuse and unlit terms of lanes `..used` at weights
    /// `w`, eye-relative positions `offset`
    /// ([`vtfarm_scene::Scene::textured_material`], a pixel's footprint
    /// there choosing the mip level); padding lanes repeat the last.
    #[cold]
    fn textured<B: Backend>(
        &self,
        surface: &Surface,
        w: V3<B>,
        offset: V3<B>,
        used: usize,
    ) -> Albedo<B> {
        let (w, offset) = (w.to_array(), offset.to_array());
        let mut diffuse = [Vec3::ZERO; LANES];
        let mut unlit = [Vec3::ZERO; LANES];
        for i in 0..LANES {
            let lane = i.min(used - 1);
            let footprint = offset[lane].length() * self.pixel;
            let material = (self.scene).textured_material(surface.id, w[lane], footprint);
            diffuse[i] = material.diffuse;
            unlit[i] = material.emission + material.ambient * self.lighting.ambient;
        }
        Albedo {
            diffuse: V3::from_fn(|i| diffuse[i]),
            unlit: V3::from_fn(|i| unlit[i]),
        }
    }

    /// `vtfarm_scene::shading::phong` (no shadows) lane by lane, with the
    /// per-material and per-light terms computed once; lanes from `used` on
    /// are padding.
    #[inline(always)]
    fn phong<B: Backend>(
        &self,
        surface: &Surface,
        albedo: &Albedo<B>,
        position: V3<B>,
        normal: V3<B>,
        to_eye: V3<B>,
        used: usize,
    ) -> V3<B> {
        let material = surface.material;
        let facing_away = normal.dot(to_eye).lt(F::splat(0.0));
        let n = V3::select(facing_away, -normal, normal);
        let mut color = albedo.unlit;
        for light in &self.lights {
            let to_light = match light.toward {
                Toward::Direction(d) => V3::splat(d),
                Toward::Point(p) => {
                    let d = V3::splat(p) - position;
                    let length = d.dot(d).sqrt();
                    d / F::select(
                        length.gt(F::splat(f32::MIN_POSITIVE)),
                        length,
                        F::splat(f32::MIN_POSITIVE),
                    )
                }
            };
            let n_dot_l = n.dot(to_light);
            // As `phong`'s `n_dot_l <= 0.0` skip: a NaN lights.
            let lit = n_dot_l.not_le(F::splat(0.0));
            let mut term = albedo.diffuse * n_dot_l;
            if material.specular.max_element() > 0.0 {
                let reflected = n * (F::splat(2.0) * n_dot_l) - to_light;
                // `max(0.0)`: NaN gives 0; the sign of a zero cannot reach
                // the colour (it only meets `power`'s zero cases).
                let r_dot_v = reflected.dot(to_eye).positive_part().to_array();
                let exponent = material.shininess.max(1.0);
                // The one call that does not vectorize: only where it counts.
                let lit = B::mask_to_array(lit);
                let mut highlight = [0.0; LANES];
                for i in (0..used).filter(|&i| lit[i]) {
                    highlight[i] = power(r_dot_v[i], exponent);
                }
                term = term + V3::splat(material.specular) * F(B::from_array(highlight));
            }
            color = V3::select(lit, color + term * V3::splat(light.radiance), color);
        }
        color
    }
}

/// `base.powf(exponent)` for an `exponent` of at least 1, with the common
/// bases 0 and 1 answered without the call, as C's `pow` answers them.
#[inline(always)]
fn power(base: f32, exponent: f32) -> f32 {
    if base == 0.0 {
        // pow(±0, y > 0) is ±0 for odd integer y, +0 otherwise.
        if exponent % 2.0 == 1.0 { base } else { 0.0 }
    } else if base == 1.0 {
        1.0
    } else {
        base.powf(exponent)
    }
}

/// The per-lane diffuse reflectance and unlit (emission plus ambient) term:
/// the material's own, or textured.
struct Albedo<B: Backend> {
    diffuse: V3<B>,
    unlit: V3<B>,
}

/// What shading a triangle's pixels needs, set up once per triangle.
struct Surface<'a> {
    scene: &'a Scene,
    id: TriangleId,
    /// Corners relative to the eye.
    corners: [Vec3; 3],
    /// [`opposite_products`] of the corners.
    opposite: [Vec3; 3],
    normals: [Vec3; 3],
    material: &'a Material,
    /// The material's emission plus its ambient term.
    unlit: Vec3,
}

impl<'a> Surface<'a> {
    fn new(frame: &FrameShading<'a>, id: TriangleId) -> Self {
        let scene = frame.scene;
        let corners = scene.triangle_positions(id).map(|p| p - frame.eye);
        let material = scene.material_of(id);
        Surface {
            scene,
            id,
            corners,
            opposite: opposite_products(corners),
            normals: scene.triangle_normals(id),
            material,
            unlit: material.emission + material.ambient * frame.lighting.ambient,
        }
    }
}

/// [b × c, c × a, a × b] for corners [a, b, c].
fn opposite_products([a, b, c]: [Vec3; 3]) -> [Vec3; 3] {
    [b.cross(c), c.cross(a), a.cross(b)]
}

/// The barycentric coordinates of the point where the ray from the eye along
/// `dir` meets the plane of a triangle with corners a, b, c relative to the
/// eye, given `opposite` = [b × c, c × a, a × b]. Each weight is the volume of
/// the tetrahedron spanned by the ray and the opposite edge: this equals
/// screen-space barycentrics weighted by 1/z (perspective-correct
/// interpolation) but needs no projected corners, so it also holds for
/// triangles clipped at the near plane.
#[inline(always)]
fn perspective_barycentrics<B: Backend>([bc, ca, ab]: [Vec3; 3], dir: V3<B>) -> V3<B> {
    let raw = V3 {
        x: dir.dot(V3::splat(bc)),
        y: dir.dot(V3::splat(ca)),
        z: dir.dot(V3::splat(ab)),
    };
    let w = raw / (raw.x + raw.y + raw.z);
    // Where the ray grazes the plane, any point of the triangle will do.
    let finite = B::and(B::and(w.x.is_finite(), w.y.is_finite()), w.z.is_finite());
    let w = V3::select(finite, w, V3::splat(Vec3::splat(1.0 / 3.0)));
    // Pixel centres lie inside the triangle up to snapping; clamp the rest.
    let w = V3 {
        x: w.x.positive_part(),
        y: w.y.positive_part(),
        z: w.z.positive_part(),
    };
    w / (w.x + w.y + w.z)
}

#[cfg(test)]
mod tests {
    use glam::Vec3;
    use vtfarm_scene::shading::phong;
    use vtfarm_scene::{Light, LightKind, Object, Projector, Triangle};

    use super::*;

    fn camera(width: u32, height: u32) -> Camera {
        Camera {
            eye: Vec3::new(0.3, 1.2, 2.0),
            target: Vec3::new(-0.2, 0.9, -1.0),
            up: Vec3::Y,
            fov_y_deg: 55.0,
            width,
            height,
        }
    }

    /// The scalar shading the lanes must reproduce bit for bit: Phong at
    /// the point of triangle `id` seen along `dir`.
    fn scalar_shade(
        scene: &Scene,
        eye: Vec3,
        lighting: &Lighting,
        id: TriangleId,
        dir: Vec3,
    ) -> Vec3 {
        let corners = scene.triangle_positions(id).map(|p| p - eye);
        let [a, b, c] = corners;
        let raw = Vec3::new(
            dir.dot(b.cross(c)),
            dir.dot(c.cross(a)),
            dir.dot(a.cross(b)),
        );
        let w = raw / raw.element_sum();
        let w = if w.is_finite() {
            w
        } else {
            Vec3::splat(1.0 / 3.0)
        };
        let w = w.max(Vec3::ZERO);
        let w = w / w.element_sum();
        let [n0, n1, n2] = scene.triangle_normals(id);
        let normal = (n0 * w.x + n1 * w.y + n2 * w.z)
            .try_normalize()
            .unwrap_or_else(|| scene.geometric_normal(id));
        let offset = corners[0] * w.x + corners[1] * w.y + corners[2] * w.z;
        let to_eye = (-offset).normalize_or(-dir);
        phong(
            scene.material_of(id),
            lighting,
            eye + offset,
            normal,
            to_eye,
            |_, _, _| true,
        )
    }

    #[test]
    fn pixel_rays_are_the_projectors() {
        for (width, height) in [(64, 48), (1920, 1080), (7, 300)] {
            let camera = camera(width, height);
            let (scene, lighting) = (Scene::default(), Lighting::default());
            let frame = FrameShading::new(&scene, &camera, &lighting);
            let rays = Projector::new(&camera);
            for y in (0..height).step_by(7) {
                for x in (0..width).step_by(5) {
                    let row_ray = V3::<Portable>::splat(frame.row_ray(y));
                    let lanes = frame.column_rays(x as usize, row_ray);
                    assert_eq!(
                        lanes.normalize().to_array()[0],
                        rays.pixel_ray(x, y),
                        "({x}, {y})"
                    );
                }
            }
        }
    }

    #[test]
    fn lanes_shade_every_pixel_as_scalar_phong_does_bit_for_bit() {
        // Triangles facing towards and away from the eye, one seen edge on,
        // one with cancelling normals; shiny and matte; a point and a
        // directional light.
        let mut shiny = Material::diffuse("shiny", Vec3::new(0.5, 0.3, 0.2));
        shiny.specular = Vec3::splat(0.4);
        shiny.shininess = 23.0;
        shiny.emission = Vec3::new(0.01, 0.0, 0.02);
        let matte = Material::diffuse("matte", Vec3::splat(0.7));
        let positions = vec![
            Vec3::new(-1.0, 0.0, -1.0),
            Vec3::new(1.0, 0.2, -1.5),
            Vec3::new(0.0, 1.5, -1.2),
            Vec3::new(-2.0, 0.5, 0.0),
            Vec3::new(2.0, 0.6, 0.5),
            Vec3::new(0.0, 1.2, -3.0),
        ];
        let normals = vec![
            Vec3::new(0.0, 0.0, 1.0),
            Vec3::new(0.3, 0.1, 0.9).normalize(),
            Vec3::new(0.0, 0.0, -1.0),
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(0.5, 0.5, 0.0).normalize(),
            Vec3::new(0.0, -1.0, 0.0),
        ];
        let triangles = [[0, 1, 2, 0], [2, 1, 0, 1], [3, 4, 5, 0], [5, 4, 3, 1]]
            .map(|[a, b, c, m]| Triangle {
                vertices: [a, b, c],
                object: vtfarm_scene::ObjectId(0),
                material: vtfarm_scene::MaterialId(m),
            })
            .to_vec();
        let scene = Scene {
            positions,
            normals,
            triangles,
            objects: vec![Object { name: "o".into() }],
            materials: vec![shiny, matte],
            ..Default::default()
        };
        let lighting = Lighting {
            lights: vec![
                Light {
                    kind: LightKind::Point {
                        position: Vec3::new(0.5, 3.0, 1.0),
                    },
                    color: Vec3::new(1.0, 0.9, 0.8),
                    intensity: 3.0,
                },
                Light {
                    kind: LightKind::Directional {
                        direction: Vec3::new(0.3, -1.0, -0.4),
                        angular_diameter_deg: 0.0,
                    },
                    color: Vec3::ONE,
                    intensity: 0.7,
                },
            ],
            ambient: Vec3::splat(0.05),
            background: Vec3::ZERO,
        };
        let camera = camera(40, 30);
        let rays = Projector::new(&camera);
        // Every triangle on every pixel, in runs of 1 to 13 pixels (so chunks
        // of every fill) between empty runs, through the whole shading path
        // (the vector width this CPU picks, lanes, run set-up).
        let triangles = scene.triangles.len() as u32;
        for shift in 0..triangles + 1 {
            let mut ids = IdBuffer::new(camera.width, camera.height);
            let (mut run, mut left, mut t) = (0, 0, shift);
            for slot in &mut ids.triangle {
                if left == 0 {
                    (run, t) = (run % 13 + 1, (t + 1) % (triangles + 1));
                    left = run;
                }
                left -= 1;
                *slot = if t == triangles { NONE } else { t };
            }
            let image = shade(&scene, &camera, &lighting, &ids);
            // The portable lanes too, where this CPU picks AVX2 above.
            let frame = FrameShading::new(&scene, &camera, &lighting);
            let mut portable = Image::new(camera.width, camera.height, Vec3::NAN);
            frame.shade_rows_with::<Portable>(0, &mut portable.pixels, &ids.triangle);
            assert_eq!(
                portable
                    .pixels
                    .iter()
                    .map(|p| p.to_array().map(f32::to_bits))
                    .collect::<Vec<_>>(),
                image
                    .pixels
                    .iter()
                    .map(|p| p.to_array().map(f32::to_bits))
                    .collect::<Vec<_>>(),
                "the portable lanes give the same bits"
            );
            for (x, y) in crate::PixelRect::full(camera.width, camera.height).pixels() {
                let id = ids.triangle_at(x, y);
                let expected = if id == NONE {
                    lighting.background
                } else {
                    scalar_shade(
                        &scene,
                        camera.eye,
                        &lighting,
                        TriangleId(id),
                        rays.pixel_ray(x, y),
                    )
                };
                assert_eq!(
                    image.get(x, y).to_array().map(f32::to_bits),
                    expected.to_array().map(f32::to_bits),
                    "triangle {id} ({x}, {y})"
                );
            }
        }
    }

    #[test]
    fn barycentrics_follow_the_ray_not_the_screen() {
        let corners = [
            Vec3::new(-1.0, -1.0, -1.0),
            Vec3::new(3.0, -1.0, -3.0),
            Vec3::new(-1.0, 1.0, -1.0),
        ];
        let point = corners[0] * 0.2 + corners[1] * 0.5 + corners[2] * 0.3;
        let dir = V3::<Portable>::splat(point.normalize());
        let w = perspective_barycentrics(opposite_products(corners), dir).to_array()[0];
        assert!(
            (w - Vec3::new(0.2, 0.5, 0.3)).abs().max_element() < 1e-5,
            "{w}"
        );
        // Independent of the corners' orientation.
        let swapped = [corners[0], corners[2], corners[1]];
        let w = perspective_barycentrics(opposite_products(swapped), dir).to_array()[0];
        assert!(
            (w - Vec3::new(0.2, 0.3, 0.5)).abs().max_element() < 1e-5,
            "{w}"
        );
    }
}
