//! The instrument cluster in front of the driver: a dark panel with three
//! dials (light faces, dark tick marks, red needles), warning lamps, the
//! curved cover glass in front of them (front and back surface) and the hood
//! that frames the glass.
//!
//! Everything is built in the glass frame ([`glass_frame`]): x to the
//! driver's right, y up along the glass, z the glass normal at its centre,
//! pointing at the driver.

use std::f32::consts::PI;

use glam::{Vec2, Vec3};
use vtfarm_scene::{Material, photometry};

use crate::builder::{SceneBuilder, backlit, emitter, glossy, matte};
use crate::layout::{ABSORBER, EYE, GLASS_CENTER, glass_frame};
use crate::mesh::{Frame, Mesh};
use crate::{
    COVER_GLASS, COVER_GLASS_BACK, DIAL_FACE_CD_M2, Detail, GLARE_ABSORBER, GLASS_MATERIAL,
    GlassDesign, MARKING_CD_M2, NEEDLE_CD_M2, WARNING_LAMP_CD_M2,
};

/// Chord width and height of the cover glass.
const GLASS_SIZE: Vec2 = Vec2::new(0.46, 0.21);
/// Semi-axes of the ellipsoid the glass is cut from; its centre lies `c` in
/// front of the glass, so the glass is concave towards the driver with radii
/// of curvature a²/c = 1.25 m across and b²/c = 0.45 m up.
const ELLIPSOID: Vec3 = Vec3::new(1.0, 0.6, 0.8);
const GLASS_THICKNESS: f32 = 0.003;
/// The dial panel lies this far behind the glass centre.
const PANEL_DEPTH: f32 = 0.05;
/// Width of the hood's bezel around the glass and length of its visor.
const BEZEL: f32 = 0.015;
const VISOR: f32 = 0.045;
/// Bezel lift off the glass surface, so the two never coincide.
const BEZEL_LIFT: f32 = 0.001;

/// A dial: centre on the panel, radius, tick count and needle position as a
/// fraction of the scale.
struct Dial {
    center: Vec2,
    radius: f32,
    ticks: u32,
    needle: f32,
}

const DIALS: [Dial; 3] = [
    // Rev counter, speedometer, fuel gauge.
    Dial {
        center: Vec2::new(-0.145, 0.01),
        radius: 0.058,
        ticks: 31,
        needle: 0.4,
    },
    Dial {
        center: Vec2::new(0.0, 0.012),
        radius: 0.068,
        ticks: 41,
        needle: 0.55,
    },
    Dial {
        center: Vec2::new(0.15, 0.01),
        radius: 0.045,
        ticks: 21,
        needle: 0.7,
    },
];

/// The dial scales sweep 270° clockwise from lower left to lower right.
const SCALE_START: f32 = 1.25 * PI;
const SCALE_SWEEP: f32 = 1.5 * PI;

/// The cover glass surface in the glass frame: today's ellipsoid patch or,
/// for the other designs, a height field over the frame's xy plane.
#[derive(Clone, Copy, Debug)]
enum CoverShape {
    Curved {
        radii: Vec3,
        /// Patch coordinates (s, t) = (±1, ±1) are the glass edges; these
        /// are the matching unit-ellipsoid coordinates.
        extent: Vec2,
    },
    /// z = h(x, y) with x = s · half.x, y = t · half.y.
    Field { half: Vec2, surface: Surface },
}

/// Height fields through the frame origin with normal +z there (except the
/// tilted plane), in the glass frame.
#[derive(Clone, Copy, Debug)]
enum Surface {
    /// z = -y tan(tilt).
    Plane { tan: f32 },
    /// Axis along x through (0, 0, radius).
    Cylinder { radius: f32 },
    /// The spheroid with centre `centre`, unit major axis `axis` and
    /// semi-axes `a` (major) and `b`; the sheet nearest the origin.
    Spheroid {
        centre: glam::DVec3,
        axis: glam::DVec3,
        a: f64,
        b: f64,
    },
}

impl Surface {
    /// Height and unit normal (towards +z) at (x, y).
    fn at(&self, x: f32, y: f32) -> (f32, Vec3) {
        match *self {
            Surface::Plane { tan } => (-y * tan, Vec3::new(0.0, tan, 1.0).normalize()),
            Surface::Cylinder { radius } => {
                let z = radius - (radius * radius - y * y).max(0.0).sqrt();
                (z, Vec3::new(0.0, -y, radius - z).normalize())
            }
            Surface::Spheroid { centre, axis, a, b } => {
                use glam::DVec3;
                // Quadratic form of the spheroid: q(v) = 1 on its surface.
                let (ia, ib) = (1.0 / (a * a), 1.0 / (b * b));
                let form = |u: DVec3, v: DVec3| {
                    let (ue, ve) = (u.dot(axis), v.dot(axis));
                    ue * ve * ia + (u.dot(v) - ue * ve) * ib
                };
                let d0 = DVec3::new(x as f64, y as f64, 0.0) - centre;
                let (qa, qb, qc) = (
                    form(DVec3::Z, DVec3::Z),
                    2.0 * form(d0, DVec3::Z),
                    form(d0, d0) - 1.0,
                );
                let root = (qb * qb - 4.0 * qa * qc).max(0.0).sqrt();
                let (l1, l2) = ((-qb - root) / (2.0 * qa), (-qb + root) / (2.0 * qa));
                let z = if l1.abs() < l2.abs() { l1 } else { l2 };
                let d = d0 + DVec3::Z * z;
                let de = d.dot(axis);
                // The gradient points outwards; the driver is inside.
                let gradient = axis * (de * ia) + (d - axis * de) * ib;
                let n = -gradient.normalize();
                let n = if n.z < 0.0 { -n } else { n };
                (z as f32, n.as_vec3())
            }
        }
    }
}

impl CoverShape {
    fn new(design: GlassDesign) -> Self {
        let half = GLASS_SIZE * 0.5;
        let field = |surface| CoverShape::Field { half, surface };
        match design {
            GlassDesign::Current => CoverShape::Curved {
                radii: ELLIPSOID,
                extent: GLASS_SIZE * 0.5 / ELLIPSOID.truncate(),
            },
            GlassDesign::Flat => field(Surface::Plane { tan: 0.0 }),
            GlassDesign::FlatTilted { degrees } => {
                let angle = clamp_or(degrees, -60.0, 60.0, 0.0).to_radians();
                CoverShape::Field {
                    // The chord along the tilted glass keeps its height.
                    half: Vec2::new(half.x, half.y * angle.cos()),
                    surface: Surface::Plane { tan: angle.tan() },
                }
            }
            GlassDesign::Cylindrical { radius } => field(Surface::Cylinder {
                radius: clamp_or(radius, MIN_CYLINDER_RADIUS, 1000.0, 1000.0),
            }),
            GlassDesign::Ellipsoidal => {
                let frame = ellipsoid_frame();
                let local = |p: Vec3| {
                    let d = p - frame.origin;
                    glam::DVec3::new(
                        d.dot(frame.x) as f64,
                        d.dot(frame.y) as f64,
                        d.dot(frame.z) as f64,
                    )
                };
                let (f1, f2) = (local(ABSORBER), local(EYE));
                // The glass centre (the frame origin) lies on the surface.
                let a = 0.5 * (f1.length() + f2.length());
                let c = 0.5 * f1.distance(f2);
                field(Surface::Spheroid {
                    centre: (f1 + f2) * 0.5,
                    axis: (f2 - f1).normalize(),
                    a,
                    b: (a * a - c * c).sqrt(),
                })
            }
        }
    }

    /// Point and exact unit normal (towards the driver) at (s, t). The glass
    /// centre is the origin; the ellipsoid's centre is at z = c.
    fn at(&self, s: f32, t: f32) -> (Vec3, Vec3) {
        match *self {
            CoverShape::Curved { radii, extent } => {
                let (x, y) = (s * extent.x, t * extent.y);
                let z = (1.0 - x * x - y * y).sqrt();
                let r = radii;
                let position = Vec3::new(r.x * x, r.y * y, r.z * (1.0 - z));
                // The gradient of the ellipsoid's implicit equation, pointing inwards.
                let normal = Vec3::new(-x / r.x, -y / r.y, z / r.z).normalize();
                (position, normal)
            }
            CoverShape::Field { half, surface } => {
                let (x, y) = (s * half.x, t * half.y);
                let (z, n) = surface.at(x, y);
                (Vec3::new(x, y, z), n)
            }
        }
    }

    /// The surface's derivatives along s and along t at (s, t).
    fn tangents(&self, s: f32, t: f32) -> (Vec3, Vec3) {
        match *self {
            CoverShape::Curved { radii, extent } => {
                let (x, y) = (s * extent.x, t * extent.y);
                let z = (1.0 - x * x - y * y).sqrt();
                let r = radii;
                (
                    Vec3::new(r.x, 0.0, r.z * x / z) * extent.x,
                    Vec3::new(0.0, r.y, r.z * y / z) * extent.y,
                )
            }
            CoverShape::Field { half, .. } => {
                // A height field's slopes follow from its normal.
                let (_, n) = self.at(s, t);
                (
                    Vec3::new(1.0, 0.0, -n.x / n.z) * half.x,
                    Vec3::new(0.0, 1.0, -n.y / n.z) * half.y,
                )
            }
        }
    }

    /// Patch coordinates per metre of x and of y in the glass frame.
    fn per_metre(&self) -> Vec2 {
        match *self {
            CoverShape::Curved { radii, extent } => Vec2::ONE / (extent * radii.truncate()),
            CoverShape::Field { half, .. } => Vec2::ONE / half,
        }
    }

    /// How far the glass with its bezel reaches behind the frame's xy
    /// plane (0 for today's glass, which lies wholly in front of it).
    fn recess(&self) -> f32 {
        match self {
            CoverShape::Curved { .. } => 0.0,
            CoverShape::Field { .. } => {
                let margin = self.per_metre() * BEZEL;
                let (os, ot) = (1.0 + margin.x, 1.0 + margin.y);
                let mut deepest = 0.0_f32;
                for s in [-os, 0.0, os] {
                    for t in [-ot, 0.0, ot] {
                        deepest = deepest.max(-self.at(s, t).0.z);
                    }
                }
                deepest
            }
        }
    }

    /// The height of the glass (with bezel) nearest to the driver.
    fn nearest(&self) -> f32 {
        let margin = self.per_metre() * BEZEL;
        let (os, ot) = (1.0 + margin.x, 1.0 + margin.y);
        match self {
            // The corners, by symmetry (kept as is for bit-identical scenes).
            CoverShape::Curved { .. } => self.at(os, ot).0.z,
            CoverShape::Field { .. } => {
                let mut nearest = f32::MIN;
                for s in [-os, 0.0, os] {
                    for t in [-ot, 0.0, ot] {
                        nearest = nearest.max(self.at(s, t).0.z);
                    }
                }
                nearest
            }
        }
    }

    /// The grid over the patch coordinates `ss` × `ts`, lifted `lift` along
    /// the normal; `flip` turns the normals away from the driver.
    fn grid(&self, ss: &[f32], ts: &[f32], lift: f32, flip: bool) -> Mesh {
        let sign = if flip { -1.0 } else { 1.0 };
        Mesh::grid(ss.len() as u32 - 1, ts.len() as u32 - 1, |i, j| {
            let (p, n) = self.at(ss[i as usize], ts[j as usize]);
            (p + n * lift, n * sign)
        })
    }
}

/// The smallest radius of the cylindrical glass (its edges then stand at
/// about 45° to its centre).
const MIN_CYLINDER_RADIUS: f32 = 0.15;

/// `value` clamped to [lo, hi], or `fallback` when it is not a number.
fn clamp_or(value: f32, lo: f32, hi: f32, fallback: f32) -> f32 {
    if value.is_nan() {
        fallback
    } else {
        value.clamp(lo, hi)
    }
}

/// The frame of the ellipsoidal glass: its normal at the centre bisects the
/// directions to the two foci (the eye and the absorber).
fn ellipsoid_frame() -> Frame {
    let normal = (EYE - GLASS_CENTER).normalize() + (ABSORBER - GLASS_CENTER).normalize();
    Frame::facing(GLASS_CENTER, normal, Vec3::Y)
}

/// The cluster frame for a design: today's turned frame, one facing the eye,
/// or the ellipsoid's tangent frame.
fn design_frame(design: GlassDesign) -> Frame {
    match design {
        GlassDesign::Current => glass_frame(),
        GlassDesign::Flat | GlassDesign::FlatTilted { .. } | GlassDesign::Cylindrical { .. } => {
            Frame::facing(GLASS_CENTER, EYE - GLASS_CENTER, Vec3::Y)
        }
        GlassDesign::Ellipsoidal => ellipsoid_frame(),
    }
}

/// `n` equal steps from `a` to `b` (n + 1 values).
fn steps(a: f32, b: f32, n: u32) -> Vec<f32> {
    (0..=n).map(|k| a + (b - a) * k as f32 / n as f32).collect()
}

pub(crate) fn build(
    builder: &mut SceneBuilder,
    detail: Detail,
    glass_segments: u32,
    design: GlassDesign,
) {
    let frame = design_frame(design);
    let shape = CoverShape::new(design);
    // The dial panel moves back as far as a tilted glass reaches behind
    // its centre.
    let panel_depth = PANEL_DEPTH + shape.recess();
    let place = |mesh: Mesh| mesh.placed(&frame);

    // Just larger than the hood's walls (a rectangle in x, y), so it closes
    // them without showing outside the hood.
    let panel_size = GLASS_SIZE + Vec2::splat(2.0 * BEZEL + 0.006);
    let panel = Mesh::rect(panel_size, None, detail.cell(0.01))
        .placed(&Frame::at((-panel_size * 0.5).extend(-panel_depth)));
    builder.add(
        "instrument_panel",
        matte("instrument_panel_black", Vec3::splat(0.02)),
        &place(panel),
    );

    let segments = detail.segments(64, 12);
    let face_z = -panel_depth + 0.002;
    let mut faces = Mesh::default();
    let mut markings = Mesh::default();
    let mut needles = Mesh::default();
    for dial in &DIALS {
        let centre = dial.center.extend(face_z);
        faces.append(&Mesh::disc(dial.radius, segments), &Frame::at(centre));
        markings.append(&dial_ticks(dial), &Frame::at(centre + Vec3::Z * 0.0005));
        needles.append(
            &needle(dial, segments / 2),
            &Frame::at(centre + Vec3::Z * 0.0015),
        );
    }
    builder.add(
        "dial_faces",
        backlit(
            "dial_face_black",
            Vec3::splat(0.04),
            Vec3::ONE,
            DIAL_FACE_CD_M2,
        ),
        &place(faces),
    );
    builder.add(
        "dial_markings",
        backlit(
            "dial_marking_white",
            Vec3::splat(0.8),
            Vec3::new(1.0, 0.97, 0.9),
            MARKING_CD_M2,
        ),
        &place(markings),
    );
    let needle_red = Material {
        emission: photometry::emission(Vec3::new(1.0, 0.1, 0.05), NEEDLE_CD_M2)
            .expect("red has luminance"),
        ..glossy("needle_red", Vec3::new(0.8, 0.05, 0.03), 0.2, 30.0)
    };
    builder.add("needles", needle_red, &place(needles));

    warning_lamps(builder, &frame, face_z, detail);
    glass(builder, &shape, &frame, glass_segments);
    builder.add(
        "cluster_hood",
        glossy("cluster_hood_plastic", Vec3::splat(0.04), 0.05, 20.0),
        &place(hood(&shape, glass_segments, panel_depth)),
    );
    if design == GlassDesign::Ellipsoidal {
        let absorber = Mesh::cuboid(Vec3::splat(ABSORBER_HALF), detail.cell(0.01))
            .placed(&Frame::at(ABSORBER));
        builder.add(
            GLARE_ABSORBER,
            matte("glare_absorber_black", Vec3::splat(0.01)),
            &absorber,
        );
    }
}

/// Half the edge of the glare absorber cube around the ellipsoid's focus.
const ABSORBER_HALF: f32 = 0.012;

/// Tick marks as thin quads on a dial face (local to the dial centre);
/// every fifth is a long, wide major tick.
fn dial_ticks(dial: &Dial) -> Mesh {
    let mut ticks = Mesh::default();
    for k in 0..dial.ticks {
        let major = k % 5 == 0;
        let angle = SCALE_START - SCALE_SWEEP * k as f32 / (dial.ticks - 1) as f32;
        let (inner, width) = if major {
            (0.78, 0.0035)
        } else {
            (0.86, 0.0018)
        };
        let dir = Vec2::from_angle(angle);
        let across = dir.perp();
        let start = dir * (dial.radius * inner) - across * (width * 0.5);
        let length = dial.radius * (0.95 - inner);
        let tick = Mesh::rect(Vec2::new(length, width), None, f32::INFINITY);
        ticks.append(
            &tick,
            &Frame::from_axes(start.extend(0.0), dir.extend(0.0), across.extend(0.0)),
        );
    }
    ticks
}

/// A tapered needle from just behind the dial centre to 85% of its radius,
/// plus a round cap over its pivot (local to the dial centre).
fn needle(dial: &Dial, cap_segments: u32) -> Mesh {
    let dir = Vec2::from_angle(SCALE_START - SCALE_SWEEP * dial.needle);
    let across = dir.perp();
    let (tail, tip) = (dir * (-0.15 * dial.radius), dir * (0.85 * dial.radius));
    let (tail_half, tip_half) = (0.0028, 0.0008);
    let mut mesh = Mesh::default();
    let corners = [
        tail - across * tail_half,
        tip - across * tip_half,
        tip + across * tip_half,
        tail + across * tail_half,
    ];
    let [a, b, c, d] = corners.map(|p| mesh.vertex(p.extend(0.0), Vec3::Z));
    mesh.quad(a, b, c, d);
    mesh.append(
        &Mesh::disc(0.008, cap_segments),
        &Frame::at(Vec3::Z * 0.0005),
    );
    mesh
}

/// A row of small emissive lamp discs under the speedometer.
fn warning_lamps(builder: &mut SceneBuilder, frame: &Frame, face_z: f32, detail: Detail) {
    let colors = [
        ("warning_lamp_amber", Vec3::new(2.0, 1.1, 0.1)),
        ("warning_lamp_red", Vec3::new(2.0, 0.15, 0.1)),
        ("warning_lamp_green", Vec3::new(0.2, 1.6, 0.3)),
        ("warning_lamp_blue", Vec3::new(0.2, 0.5, 2.0)),
    ];
    let object = builder.object("warning_lamps");
    let lamp = Mesh::disc(0.006, detail.segments(24, 8));
    for (k, x) in steps(-0.075, 0.075, 5).into_iter().enumerate() {
        let (name, color) = colors[k % colors.len()];
        let material = builder.material(emitter(name, color, WARNING_LAMP_CD_M2));
        let at = frame.compose(&Frame::at(Vec3::new(x, -0.082, face_z)));
        builder.push(object, material, &lamp.placed(&at));
    }
}

/// The glass material: nearly no local shading, a weak mirror, mostly
/// transmitting.
fn glass_material() -> Material {
    Material {
        name: GLASS_MATERIAL.to_owned(),
        ambient: Vec3::splat(0.005),
        diffuse: Vec3::splat(0.005),
        specular: Vec3::splat(0.05),
        shininess: 200.0,
        emission: Vec3::ZERO,
        reflectance: Vec3::splat(0.12),
        transmittance: Vec3::splat(0.85),
        ior: 1.5,
        ..Default::default()
    }
}

/// The glass's two surfaces. The back one is offset along the exact normal
/// (an offset surface keeps its normals) and its normals point away from
/// the driver, so both bound the glass with outward normals as refraction
/// needs to tell entering from leaving.
fn glass(builder: &mut SceneBuilder, shape: &CoverShape, frame: &Frame, segments: u32) {
    let ss = steps(-1.0, 1.0, segments.max(2));
    let ts = steps(-1.0, 1.0, (segments / 2).max(1));
    builder.add(
        COVER_GLASS,
        glass_material(),
        &shape.grid(&ss, &ts, 0.0, false).placed(frame),
    );
    let back = shape.grid(&ss, &ts, -GLASS_THICKNESS, true);
    builder.add(COVER_GLASS_BACK, glass_material(), &back.placed(frame));
}

/// The hood framing the glass: a bezel just in front of the glass surface
/// around its edge, walls from the bezel back past the dial panel (what the
/// driver sees of the cluster's sides through the glass), and a short visor
/// over the top edge shading the glass.
fn hood(shape: &CoverShape, segments: u32, panel_depth: f32) -> Mesh {
    let margin = shape.per_metre() * BEZEL;
    let (os, ot) = (1.0 + margin.x, 1.0 + margin.y);
    let mut across = steps(-1.0, 1.0, segments.max(2));
    across.insert(0, -os);
    across.push(os);
    let up = steps(-1.0, 1.0, (segments / 2).max(1));
    let mut hood = Mesh::default();
    // Bezel: top and bottom strips run over the corners, sides in between.
    hood.merge(&shape.grid(&across, &[1.0, ot], BEZEL_LIFT, false));
    hood.merge(&shape.grid(&across, &[-ot, -1.0], BEZEL_LIFT, false));
    hood.merge(&shape.grid(&[-os, -1.0], &up, BEZEL_LIFT, false));
    hood.merge(&shape.grid(&[1.0, os], &up, BEZEL_LIFT, false));

    // The bezel's outer edge, one side at a time (the corners are hard).
    let top = edge(shape, across.iter().map(|&s| (s, ot)), true);
    let bottom = edge(shape, across.iter().map(|&s| (s, -ot)), true);
    let mut up_outer = up.clone();
    up_outer.insert(0, -ot);
    up_outer.push(ot);
    let left = edge(shape, up_outer.iter().map(|&t| (-os, t)), false);
    let right = edge(shape, up_outer.iter().map(|&t| (os, t)), false);
    // The walls reach a little past the dial panel from the bezel's points
    // nearest to the driver.
    let back = Vec3::Z * -(panel_depth + shape.nearest() + 0.005);
    for side in [&top, &bottom, &left, &right] {
        let inwards = |n: Vec3, p: Vec3| n.dot(Vec3::new(-p.x, -p.y, 0.0)) > 0.0;
        hood.merge(&Mesh::sweep(
            &sweep_normals(side, back, inwards),
            back,
            2,
            false,
        ));
    }
    let visor = Vec3::new(0.0, 0.4, 1.0).normalize() * VISOR;
    hood.merge(&Mesh::sweep(
        &sweep_normals(&top, visor, |n, _| n.y > 0.0),
        visor,
        2,
        false,
    ));
    hood
}

/// Points of the bezel's outer edge at the patch coordinates `coords`,
/// with the edge's exact tangent (along s, or along t).
fn edge(
    shape: &CoverShape,
    coords: impl Iterator<Item = (f32, f32)>,
    along_s: bool,
) -> Vec<(Vec3, Vec3)> {
    coords
        .map(|(s, t)| {
            let (p, n) = shape.at(s, t);
            let (ds, dt) = shape.tangents(s, t);
            (p + n * BEZEL_LIFT, if along_s { ds } else { dt })
        })
        .collect()
}

/// Sweep sections for an edge (points with tangents) swept along `offset`:
/// the normal of such a generalised cylinder is perpendicular to both the
/// edge and the sweep, turned so that `keep(normal, point)` holds.
fn sweep_normals(
    edge: &[(Vec3, Vec3)],
    offset: Vec3,
    keep: impl Fn(Vec3, Vec3) -> bool,
) -> Vec<(Vec3, Vec3)> {
    edge.iter()
        .map(|&(p, tangent)| {
            let n = tangent.cross(offset).normalize();
            (p, if keep(n, p) { n } else { -n })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn glass_patch_has_the_chord_size() {
        let shape = CoverShape::new(GlassDesign::Current);
        let width = shape.at(1.0, 0.0).0.x - shape.at(-1.0, 0.0).0.x;
        let height = shape.at(0.0, 1.0).0.y - shape.at(0.0, -1.0).0.y;
        assert!((width - GLASS_SIZE.x).abs() < 1e-6 && (height - GLASS_SIZE.y).abs() < 1e-6);
        assert_eq!(shape.at(0.0, 0.0), (Vec3::ZERO, Vec3::Z));
    }

    #[test]
    fn normals_are_exact_and_tangents_match_the_surface() {
        let shape = CoverShape::new(GlassDesign::Current);
        let h = 1e-3;
        for (s, t) in [(0.3, -0.7), (-1.0, 1.0), (1.07, -1.14), (0.0, 0.5)] {
            let (p, n) = shape.at(s, t);
            let (ds, dt) = shape.tangents(s, t);
            assert!(
                n.dot(ds).abs() < 1e-5 && n.dot(dt).abs() < 1e-5,
                "({s}, {t})"
            );
            let fd_s = (shape.at(s + h, t).0 - shape.at(s - h, t).0) / (2.0 * h);
            let fd_t = (shape.at(s, t + h).0 - shape.at(s, t - h).0) / (2.0 * h);
            assert!(
                (fd_s - ds).length() < 1e-3 && (fd_t - dt).length() < 1e-3,
                "({s}, {t})"
            );
            // The point lies on the ellipsoid centred at z = c.
            let q = (p - Vec3::Z * ELLIPSOID.z) / ELLIPSOID;
            assert!((q.length() - 1.0).abs() < 1e-5);
        }
    }
}
