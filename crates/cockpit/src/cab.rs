//! The cab shell (walls with the window openings, floor, roof) and the
//! emissive panels outside the openings that stand in for sky, landscape and
//! the bright view through the driver's door window. There are no glass
//! sheets in the openings: rays leave the cab and meet the panels.

use glam::{Vec2, Vec3};

use crate::builder::{SceneBuilder, emitter, matte};
use crate::layout::{
    CAB_MAX, CAB_MIN, GROUND_Y, SIDE_WINDOW_Y, SIDE_WINDOW_Z, WINDSHIELD_X, WINDSHIELD_Y,
};
use crate::mesh::{Frame, Mesh};
use crate::{Detail, GROUND_CD_M2, SHADED_WINDOW_CD_M2, SKY_CD_M2, SUNLIT_WINDOW_CD_M2};

/// Wall, floor and roof cell size at detail 1.
const WALL_CELL: f32 = 0.047;

/// The panel outside the left door window: its plane (x) and extent. It
/// stops low enough that the (steep) sun passes over it into the cab, since
/// shadow rays treat every surface as opaque.
const LEFT_PANEL_X: f32 = -1.45;
const LEFT_PANEL_Y: Vec2 = Vec2::new(0.6, 2.0);
const LEFT_PANEL_Z: Vec2 = Vec2::new(-1.8, 1.2);

/// The sky and landscape ahead lie on the plane z = FRONT_PANEL_Z; the
/// landscape strip ends at the horizon height, the sky above it.
const FRONT_PANEL_Z: f32 = -4.0;
const FRONT_PANEL_X: Vec2 = Vec2::new(-6.0, 6.0);
const HORIZON_Y: f32 = 0.9;
const SKY_TOP_Y: f32 = 4.0;

/// A flat rectangle with corner `origin`, spanning `size` along the unit
/// axes `u` and `v` and facing u × v, optionally with an opening given in
/// metres along u and v.
fn wall(origin: Vec3, u: Vec3, v: Vec3, size: Vec2, hole: Option<[Vec2; 2]>, cell: f32) -> Mesh {
    Mesh::rect(size, hole, cell).placed(&Frame::from_axes(origin, u, v))
}

pub(crate) fn build(builder: &mut SceneBuilder, detail: Detail) {
    let (lo, hi) = (CAB_MIN, CAB_MAX);
    let size = hi - lo;
    let cell = detail.cell(WALL_CELL);

    // Each wall faces into the cab; openings are given along the wall axes.
    let mut walls = Mesh::default();
    let side_hole = |z_along: Vec2| {
        Some([
            Vec2::new(z_along.x, SIDE_WINDOW_Y.x),
            Vec2::new(z_along.y, SIDE_WINDOW_Y.y),
        ])
    };
    // Left wall: u runs from the back towards the front (u × v = +X).
    let left_hole = side_hole(Vec2::new(hi.z - SIDE_WINDOW_Z.y, hi.z - SIDE_WINDOW_Z.x));
    walls.merge(&wall(
        Vec3::new(lo.x, lo.y, hi.z),
        -Vec3::Z,
        Vec3::Y,
        Vec2::new(size.z, size.y),
        left_hole,
        cell,
    ));
    // Right wall: u runs from the front towards the back (u × v = -X).
    let right_hole = side_hole(SIDE_WINDOW_Z - Vec2::splat(lo.z));
    walls.merge(&wall(
        Vec3::new(hi.x, lo.y, lo.z),
        Vec3::Z,
        Vec3::Y,
        Vec2::new(size.z, size.y),
        right_hole,
        cell,
    ));
    let windshield = Some([
        Vec2::new(WINDSHIELD_X.x - lo.x, WINDSHIELD_Y.x),
        Vec2::new(WINDSHIELD_X.y - lo.x, WINDSHIELD_Y.y),
    ]);
    walls.merge(&wall(
        lo,
        Vec3::X,
        Vec3::Y,
        Vec2::new(size.x, size.y),
        windshield,
        cell,
    ));
    walls.merge(&wall(
        Vec3::new(hi.x, lo.y, hi.z),
        -Vec3::X,
        Vec3::Y,
        Vec2::new(size.x, size.y),
        None,
        cell,
    ));
    builder.add(
        "cab_walls",
        matte("cab_wall_trim", Vec3::new(0.22, 0.21, 0.2)),
        &walls,
    );

    let floor = wall(lo, Vec3::Z, Vec3::X, Vec2::new(size.z, size.x), None, cell);
    builder.add("floor", matte("floor_rubber", Vec3::splat(0.07)), &floor);
    let roof = wall(
        Vec3::new(lo.x, hi.y, lo.z),
        Vec3::X,
        Vec3::Z,
        Vec2::new(size.x, size.z),
        None,
        cell,
    );
    builder.add(
        "roof",
        matte("roof_headliner", Vec3::new(0.42, 0.41, 0.39)),
        &roof,
    );

    outside(builder);
}

/// The emissive stand-ins for the world outside. They are few large quads:
/// only their colour matters.
fn outside(builder: &mut SceneBuilder) {
    let coarse = 100.0;
    let front_width = FRONT_PANEL_X.y - FRONT_PANEL_X.x;
    let sky = wall(
        Vec3::new(FRONT_PANEL_X.x, HORIZON_Y, FRONT_PANEL_Z),
        Vec3::X,
        Vec3::Y,
        Vec2::new(front_width, SKY_TOP_Y - HORIZON_Y),
        None,
        coarse,
    );
    builder.add(
        "windshield_sky",
        emitter("sky_light", Vec3::new(2.0, 2.2, 2.6), SKY_CD_M2),
        &sky,
    );

    let left = wall(
        Vec3::new(LEFT_PANEL_X, LEFT_PANEL_Y.x, LEFT_PANEL_Z.y),
        -Vec3::Z,
        Vec3::Y,
        Vec2::new(
            LEFT_PANEL_Z.y - LEFT_PANEL_Z.x,
            LEFT_PANEL_Y.y - LEFT_PANEL_Y.x,
        ),
        None,
        coarse,
    );
    builder.add(
        "side_window_left",
        emitter(
            "side_window_left_light",
            Vec3::new(3.0, 3.0, 2.8),
            SUNLIT_WINDOW_CD_M2,
        ),
        &left,
    );

    // The right door window is far from the driver: one dimmer panel that
    // covers everything seen through it.
    let right = wall(
        Vec3::new(1.6, 0.2, -2.2),
        Vec3::Z,
        Vec3::Y,
        Vec2::new(3.6, 3.3),
        None,
        coarse,
    );
    builder.add(
        "side_window_right",
        emitter(
            "side_window_right_light",
            Vec3::new(1.5, 1.65, 1.9),
            SHADED_WINDOW_CD_M2,
        ),
        &right,
    );

    // The road and fields below, plus the landscape strip ahead under the sky.
    let mut ground = wall(
        Vec3::new(-8.0, GROUND_Y, FRONT_PANEL_Z),
        Vec3::Z,
        Vec3::X,
        Vec2::new(10.0, 16.0),
        None,
        coarse,
    );
    ground.merge(&wall(
        Vec3::new(FRONT_PANEL_X.x, GROUND_Y, FRONT_PANEL_Z),
        Vec3::X,
        Vec3::Y,
        Vec2::new(front_width, HORIZON_Y - GROUND_Y),
        None,
        coarse,
    ));
    builder.add(
        "ground",
        emitter("ground_landscape", Vec3::new(0.3, 0.32, 0.24), GROUND_CD_M2),
        &ground,
    );
}
