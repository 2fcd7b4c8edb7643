//! The cab's furniture: dashboard, A-pillars, steering wheel, driver's seat
//! and centre console. Most of the triangle budget lives here (rounded
//! profiles swept across the cab, the wheel's torus), scaled by the detail.

use glam::{Vec2, Vec3};

use crate::Detail;
use crate::builder::{SceneBuilder, glossy, matte};
use crate::layout::{CAB_MAX, CAB_MIN, DRIVER_X, WINDSHIELD_X};
use crate::mesh::{Frame, Mesh, rounded_polygon};

/// Centre of the steering wheel rim: low enough that the driver looks over
/// its upper rim at the instruments.
const WHEEL_CENTER: Vec3 = Vec3::new(DRIVER_X, 0.84, -0.27);
/// Elevation of the wheel's axis (towards the driver) above the horizontal:
/// a truck wheel lies well back.
const WHEEL_TILT_DEG: f32 = 38.0;
const WHEEL_RADIUS: f32 = 0.22;
const WHEEL_GRIP: f32 = 0.017;

pub(crate) fn build(builder: &mut SceneBuilder, detail: Detail) {
    builder.add(
        "dashboard",
        glossy("dashboard_plastic", Vec3::new(0.1, 0.1, 0.11), 0.08, 24.0),
        &dashboard(detail),
    );
    for (name, sign) in [("a_pillar_left", -1.0), ("a_pillar_right", 1.0)] {
        let material = matte(&format!("{name}_trim"), Vec3::new(0.2, 0.19, 0.18));
        builder.add(name, material, &a_pillar(sign, detail));
    }
    let wheel = steering_wheel(detail);
    builder.add(
        "steering_wheel",
        glossy("steering_wheel_leather", Vec3::splat(0.05), 0.15, 16.0),
        &wheel,
    );
    builder.add(
        "seat",
        matte("seat_fabric", Vec3::new(0.16, 0.16, 0.18)),
        &seat(detail),
    );
    let console = center_console(detail);
    builder.add(
        "center_console",
        glossy("center_console_plastic", Vec3::splat(0.12), 0.06, 20.0),
        &console,
    );
}

/// A profile (corners with their rounding radii, in the local xy plane)
/// swept along local +z over `length`, placed with `frame`. Arcs and the
/// sweep get finer with the detail.
fn rounded_prism(
    corners: &[(Vec2, f32)],
    length: f32,
    frame: &Frame,
    arcs: u32,
    steps: u32,
    detail: Detail,
) -> Mesh {
    let profile = rounded_polygon(corners, detail.segments(arcs, 2), detail.cell(0.04));
    Mesh::prism(&profile, length, detail.segments(steps, 1)).placed(frame)
}

/// A frame that maps a profile drawn in world (z, y) coordinates and swept
/// along local +z to a sweep towards -X starting at `x`.
fn across_cab(x: f32) -> Frame {
    Frame::from_axes(Vec3::new(x, 0.0, 0.0), Vec3::Z, Vec3::Y)
}

/// The dashboard across the whole cab: a rounded profile in (z, y) that
/// rises towards the windshield, its rear face under the instrument cluster.
fn dashboard(detail: Detail) -> Mesh {
    let front = CAB_MIN.z - 0.05;
    let corners = [
        (Vec2::new(-0.6, 0.35), 0.03),
        (Vec2::new(-0.6, 0.9), 0.09),
        (Vec2::new(front, 1.07), 0.05),
        (Vec2::new(front, 0.35), 0.03),
    ];
    let inset = 0.01;
    let width = CAB_MAX.x - CAB_MIN.x - 2.0 * inset;
    rounded_prism(
        &corners,
        width,
        &across_cab(CAB_MAX.x - inset),
        16,
        100,
        detail,
    )
}

/// An A-pillar box at the windshield's left (`side` -1) or right (+1) edge.
fn a_pillar(side: f32, detail: Detail) -> Mesh {
    let half = Vec3::new(0.06, 0.5, 0.06);
    let x = side * (CAB_MAX.x - half.x);
    debug_assert!(
        x.abs() - half.x < WINDSHIELD_X.y,
        "the pillar frames the windshield"
    );
    let centre = Vec3::new(x, CAB_MAX.y - half.y, CAB_MIN.z + half.z);
    Mesh::cuboid(half, detail.cell(0.04)).placed(&Frame::at(centre))
}

/// The wheel frame: origin at the rim centre, z along the wheel axis
/// towards the driver, y "up" in the wheel plane.
fn wheel_frame() -> Frame {
    let (sin, cos) = WHEEL_TILT_DEG.to_radians().sin_cos();
    Frame::facing(WHEEL_CENTER, Vec3::new(0.0, sin, cos), Vec3::Y)
}

/// Rim (torus), hub, three spokes (left, right, down) and the column into
/// the dashboard.
fn steering_wheel(detail: Detail) -> Mesh {
    let frame = wheel_frame();
    let around = detail.segments(24, 6);
    let mut wheel = Mesh::torus(
        WHEEL_RADIUS,
        WHEEL_GRIP,
        detail.segments(240, 12),
        detail.segments(32, 6),
    );
    let hub_radius = 0.055;
    wheel.append(
        &Mesh::cylinder(hub_radius, 0.05, detail.segments(48, 8), 2),
        &Frame::at(Vec3::Z * -0.02),
    );
    for angle in [0.0_f32, 180.0, 270.0] {
        let (sin, cos) = angle.to_radians().sin_cos();
        // Spokes start inside the hub and end inside the rim.
        let spoke = Frame::facing(
            Vec3::new(cos, sin, 0.0) * (hub_radius * 0.5),
            Vec3::new(cos, sin, 0.0),
            Vec3::Z,
        );
        wheel.append(
            &Mesh::tube(
                0.012,
                WHEEL_RADIUS - hub_radius * 0.5,
                around,
                detail.segments(4, 1),
            ),
            &spoke,
        );
    }
    let column = Frame::from_axes(Vec3::Z * -0.02, Vec3::X, -Vec3::Y);
    wheel.append(
        &Mesh::tube(0.03, 0.5, around, detail.segments(4, 1)),
        &column,
    );
    wheel.placed(&frame)
}

/// Cushion, backrest, headrest (rounded profiles swept across the seat's
/// width) on a box pedestal, behind the driver's eye.
fn seat(detail: Detail) -> Mesh {
    let (width, head_width) = (0.52, 0.28);
    let right = DRIVER_X + width * 0.5;
    let mut seat = Mesh::default();
    let cushion = [
        (Vec2::new(-0.18, 0.42), 0.05),
        (Vec2::new(0.38, 0.42), 0.05),
        (Vec2::new(0.38, 0.6), 0.06),
        (Vec2::new(-0.18, 0.63), 0.06),
    ];
    seat.merge(&rounded_prism(
        &cushion,
        width,
        &across_cab(right),
        12,
        46,
        detail,
    ));
    let backrest = [
        (Vec2::new(0.3, 0.55), 0.05),
        (Vec2::new(0.46, 0.55), 0.05),
        (Vec2::new(0.56, 1.3), 0.06),
        (Vec2::new(0.4, 1.32), 0.06),
    ];
    seat.merge(&rounded_prism(
        &backrest,
        width,
        &across_cab(right),
        12,
        46,
        detail,
    ));
    let headrest = [
        (Vec2::new(0.41, 1.37), 0.04),
        (Vec2::new(0.53, 1.37), 0.04),
        (Vec2::new(0.56, 1.6), 0.05),
        (Vec2::new(0.44, 1.62), 0.05),
    ];
    let head_right = DRIVER_X + head_width * 0.5;
    seat.merge(&rounded_prism(
        &headrest,
        head_width,
        &across_cab(head_right),
        12,
        24,
        detail,
    ));
    let pedestal = Mesh::cuboid(Vec3::new(0.17, 0.21, 0.2), detail.cell(0.04));
    seat.append(&pedestal, &Frame::at(Vec3::new(DRIVER_X, 0.21, 0.16)));
    seat
}

/// The console between the seats: a rounded profile in (x, y) swept from
/// the dashboard backwards.
fn center_console(detail: Detail) -> Mesh {
    let corners = [
        (Vec2::new(-0.17, 0.0), 0.02),
        (Vec2::new(0.17, 0.0), 0.02),
        (Vec2::new(0.17, 0.62), 0.06),
        (Vec2::new(-0.17, 0.62), 0.06),
    ];
    let front = -0.95;
    rounded_prism(
        &corners,
        1.25,
        &Frame::at(Vec3::new(0.0, 0.0, front)),
        12,
        50,
        detail,
    )
}
