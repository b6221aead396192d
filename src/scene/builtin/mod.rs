//! Procedural scenes that need no files: deterministic, so tests, benchmarks and regression
//! images can rely on them anywhere, and some come with the exact surface they approximate
//! ([`analytic()`]) as an oracle for hit distances and normals.

mod analytic;
mod shapes;

use std::f32::consts::FRAC_PI_2;

use glam::{DVec3, Mat4, Quat, Vec3};

pub use analytic::Analytic;
use shapes::Shape;

use super::{Instance, InstancedScene, Scene};

/// The built-in scene names, in the order help texts list them.
pub const NAMES: &[&str] = &[
    "default",
    "plane",
    "sphere",
    "torus",
    "cube",
    "cylinder",
    "cone",
    "bumpy-sphere",
    "blob",
    "grove",
    "grove-instanced",
    "hall",
];

/// Subdivision level of the "sphere" scene: 20·4⁵ = 20480 triangles.
const SPHERE_LEVEL: u32 = 5;

/// The exact surface behind built-in scene `name`, for those that have one ("plane", "sphere").
pub fn analytic(name: &str) -> Option<Analytic> {
    match name {
        "plane" => Some(Analytic::Plane {
            point: Vec3::ZERO,
            normal: Vec3::Y,
            half_extent: 1.0,
        }),
        "sphere" => {
            let s = sphere();
            Some(Analytic::Sphere {
                center: Vec3::ZERO,
                radius: 1.0,
                max_chord_error: analytic::sphere_chord_error(
                    &s.positions,
                    &s.triangles,
                    Vec3::ZERO,
                    1.0,
                ),
            })
        }
        _ => None,
    }
}

/// The built-in scenes that place a mesh held once ([`InstancedScene`]): "grove-instanced".
pub(super) fn build_instanced(name: &str) -> Option<InstancedScene> {
    match name {
        "grove-instanced" => Some(grove_instanced()),
        _ => None,
    }
}

/// Builds built-in scene `name`, or `None` when there is no such scene (one with instances
/// flattened).
pub(super) fn build(name: &str) -> Option<Scene> {
    let parts: Vec<(&str, Shape)> = match name {
        "default" => showcase(),
        "plane" => vec![("plane", shapes::grid_plane(1.0, 8))],
        "sphere" => vec![("sphere", sphere())],
        "torus" => vec![("torus", torus())],
        "cube" => vec![("cube", shapes::cube(8))],
        "cylinder" => vec![("cylinder", shapes::cylinder(96, 4))],
        "cone" => vec![("cone", shapes::cone(96))],
        "bumpy-sphere" => vec![("bumpy-sphere", bumpy_sphere())],
        "blob" => vec![("blob", blob())],
        "grove" => return Some(grove()),
        "grove-instanced" => return Some(grove_instanced().into_flat()),
        "hall" => return Some(hall()),
        _ => return None,
    };
    let mut scene = Scene::new(name);
    for (part, shape) in parts {
        scene.push_object(part, &shape.positions, &shape.triangles);
    }
    Some(scene)
}

/// The unit sphere at the origin.
fn sphere() -> Shape {
    shapes::displaced_sphere(SPHERE_LEVEL, |_| 1.0)
}

/// A ring torus around the y axis, major radius 1, tube radius 0.35 (12288 triangles).
fn torus() -> Shape {
    shapes::torus(1.0, 0.35, 128, 48)
}

/// Amplitude of the bumps on "bumpy-sphere", relative to its radius 1.
const BUMP: f64 = 0.07;

/// A unit sphere covered in egg-box bumps: smooth, but with detail at a scale a coarse height
/// field cannot hold (81920 triangles).
fn bumpy_sphere() -> Shape {
    shapes::displaced_sphere(6, |d| {
        1.0 + BUMP * (12.0 * d.x).sin() * (12.0 * d.y).sin() * (12.0 * d.z).sin()
    })
}

/// A smooth lopsided blob, roughly the size and shape of a crouching bunny: a sphere displaced
/// by a few low-frequency sinusoids and stretched (20480 triangles). Smooth everywhere, so the
/// error of a height-field approximation depends only on resolution.
fn blob() -> Shape {
    shapes::displaced_sphere(5, blob_radius).transformed(Mat4::from_scale(Vec3::new(1.1, 0.9, 0.8)))
}

/// The radius of "blob" in direction `d`.
fn blob_radius(d: DVec3) -> f64 {
    1.0 + 0.20 * (2.0 * d.x + 0.5).sin()
        + 0.12 * (3.0 * d.y + 1.0).sin() * (2.0 * d.z).cos()
        + 0.08 * (4.0 * d.z + 2.0 * d.x).sin()
}

/// Copies across and along "grove".
const GROVE_ACROSS: usize = 10;
const GROVE_ALONG: usize = 40;
/// Spacing of the copies in "grove".
const GROVE_SPACING: f32 = 3.0;

/// The level-of-detail scene: a grove of 400 blobs (1280 triangles each, about 510k in all) in a
/// 10 × 40 grid on a ground plane, jittered and turned, seen from one end at eye height, so that
/// the same mesh appears at every distance from a few units to 120 and distant copies crowd the
/// upper half of the image. Its camera looks along the grove. Flat, each blob copied in place: its
/// level of detail is measured on it ([`grove_instanced`] holds the blob once).
fn grove() -> Scene {
    let (ground, blob, placements) = grove_parts();
    let mut scene = Scene::new("grove");
    scene.push_object("ground", &ground.positions, &ground.triangles);
    let mut copy = Scene::new("");
    copy.push_object("blob", &blob.positions, &blob.triangles);
    for (name, transform) in placements {
        copy.name = name;
        scene.append(&copy, transform);
    }
    scene.camera = Some(grove_camera());
    scene
}

/// "grove-instanced": the grove with the blob held once and placed 400 times (issue "Instances");
/// flattened, the same triangles at the same places as "grove".
pub(super) fn grove_instanced() -> InstancedScene {
    let (ground, blob, placements) = grove_parts();
    let mut ground_mesh = Scene::new("");
    ground_mesh.push_object("ground", &ground.positions, &ground.triangles);
    let mut blob_mesh = Scene::new("blob");
    blob_mesh.push_object("blob", &blob.positions, &blob.triangles);
    let mut instances = vec![Instance {
        mesh: 0,
        transform: Mat4::IDENTITY,
    }];
    instances.extend(
        placements
            .into_iter()
            .map(|(_, transform)| Instance { mesh: 1, transform }),
    );
    InstancedScene {
        name: "grove-instanced".into(),
        meshes: vec![ground_mesh, blob_mesh],
        instances,
        camera: Some(grove_camera()),
        light: None,
    }
}

/// The grove's ground (placed), its blob (in its own space) and where each copy of the blob goes,
/// named by its row and column.
fn grove_parts() -> (Shape, Shape, Vec<(String, Mat4)>) {
    let (width, depth) = (
        GROVE_ACROSS as f32 * GROVE_SPACING,
        GROVE_ALONG as f32 * GROVE_SPACING,
    );
    let ground = shapes::grid_plane(1.0, 32).transformed(Mat4::from_scale_rotation_translation(
        Vec3::new(0.5 * width + 2.0, 1.0, 0.5 * depth + 2.0),
        Quat::IDENTITY,
        Vec3::new(0.0, 0.0, -0.5 * depth + GROVE_SPACING),
    ));
    let blob = shapes::displaced_sphere(3, blob_radius)
        .transformed(Mat4::from_scale(Vec3::new(1.1, 0.9, 0.8)));
    let mut placements = Vec::with_capacity(GROVE_ALONG * GROVE_ACROSS);
    for row in 0..GROVE_ALONG {
        for col in 0..GROVE_ACROSS {
            // A fixed hash of the cell, for jitter and turn: deterministic, no RNG needed.
            let h = ((row * 131 + col * 71) as u32).wrapping_mul(2_654_435_761);
            let unit = |shift: u32| ((h >> shift) & 0xFF) as f32 / 255.0 - 0.5;
            let at = Vec3::new(
                (col as f32 - 0.5 * (GROVE_ACROSS - 1) as f32 + unit(0)) * GROVE_SPACING,
                0.72,
                -(row as f32 + unit(8)) * GROVE_SPACING,
            );
            let turn = Quat::from_rotation_y(unit(16) * std::f32::consts::TAU);
            placements.push((
                format!("r{row}c{col}"),
                Mat4::from_scale_rotation_translation(Vec3::splat(0.8), turn, at),
            ));
        }
    }
    (ground, blob, placements)
}

/// The grove's camera: at one end, at eye height, looking along it.
fn grove_camera() -> super::Camera {
    super::Camera {
        eye: Vec3::new(0.0, 2.2, 8.0),
        target: Vec3::new(0.0, 0.0, -60.0),
        up: Vec3::Y,
        vfov_deg: 50.0,
    }
}

/// Side of the "hall"'s square floor and height of its walls.
const HALL_SIDE: f32 = 48.0;
const HALL_HEIGHT: f32 = 12.0;
/// Pieces across and along the "hall", and their spacing.
const HALL_PIECES: usize = 5;
const HALL_SPACING: f32 = 8.0;

/// The guard of issue "Small and valid at every scale": the shape of the paper's scene (a large
/// room, many small, detailed, closed objects) with no files. A 48 × 48 floor walled 12 high on
/// every side, open above, and 25 pieces in a 5 × 5 grid, each a thirtieth to a twentieth of
/// the room's diagonal across (as the paper-scale scene's dragons are of its courtyard): spiky
/// critters (horns a fifth of their size), bumpy spheres and tori, turned and scaled by a fixed
/// hash, about 370k triangles. Its camera stands inside at one end, looking over the pieces.
/// A texel tied to the room's size is larger than the pieces' features; each piece's own size
/// is what its texel must follow.
fn hall() -> Scene {
    let mut scene = Scene::new("hall");
    let (half, height) = (0.5 * HALL_SIDE, HALL_HEIGHT);
    let floor =
        shapes::grid_plane(1.0, 24).transformed(Mat4::from_scale(Vec3::new(half, 1.0, half)));
    scene.push_object("floor", &floor.positions, &floor.triangles);
    // Each wall is a grid stood up to face into the room: the x turns make the grid's z its
    // height, the z turns its x.
    let (along_x, along_z) = (
        Vec3::new(half, 1.0, 0.5 * height),
        Vec3::new(0.5 * height, 1.0, half),
    );
    let up = 0.5 * height;
    let walls = [
        (
            "back wall",
            along_x,
            Quat::from_rotation_x(FRAC_PI_2),
            Vec3::new(0.0, up, -half),
        ),
        (
            "front wall",
            along_x,
            Quat::from_rotation_x(-FRAC_PI_2),
            Vec3::new(0.0, up, half),
        ),
        (
            "left wall",
            along_z,
            Quat::from_rotation_z(-FRAC_PI_2),
            Vec3::new(-half, up, 0.0),
        ),
        (
            "right wall",
            along_z,
            Quat::from_rotation_z(FRAC_PI_2),
            Vec3::new(half, up, 0.0),
        ),
    ];
    for (name, scale, turn, at) in walls {
        let wall = shapes::grid_plane(1.0, 12)
            .transformed(Mat4::from_scale_rotation_translation(scale, turn, at));
        scene.push_object(name, &wall.positions, &wall.triangles);
    }
    let critter = shapes::displaced_sphere(5, |d| {
        let s = (6.0 * d.x).sin() * (6.0 * d.y + 0.5).sin() * (6.0 * d.z + 1.0).sin();
        1.0 + 0.45 * s.max(0.0).powi(4)
    });
    let bumpy = shapes::displaced_sphere(5, |d| {
        1.0 + BUMP * (10.0 * d.x).sin() * (10.0 * d.y).sin() * (10.0 * d.z).sin()
    });
    let ring = shapes::torus(1.0, 0.3, 96, 32);
    let kinds = [("critter", &critter), ("bumpy", &bumpy), ("ring", &ring)];
    for row in 0..HALL_PIECES {
        for col in 0..HALL_PIECES {
            let k = row * HALL_PIECES + col;
            let h = (k as u32 + 1).wrapping_mul(2_654_435_761);
            let unit = |shift: u32| ((h >> shift) & 0xFF) as f32 / 255.0;
            let (kind, shape) = kinds[k % kinds.len()];
            let size = 0.8 + 0.6 * unit(0);
            let centre = |i: usize| (i as f32 - 0.5 * (HALL_PIECES - 1) as f32) * HALL_SPACING;
            let at = Vec3::new(centre(col), 1.5 * size, centre(row));
            let turn = Quat::from_rotation_y(unit(8) * std::f32::consts::TAU)
                * Quat::from_rotation_x(0.5 * unit(16));
            let piece = (*shape)
                .clone()
                .transformed(Mat4::from_scale_rotation_translation(
                    Vec3::splat(size),
                    turn,
                    at,
                ));
            scene.push_object(
                format!("{kind} {row},{col}"),
                &piece.positions,
                &piece.triangles,
            );
        }
    }
    scene.camera = Some(super::Camera {
        eye: Vec3::new(0.0, 5.0, half - 3.0),
        target: Vec3::new(0.0, 1.0, -4.0),
        up: Vec3::Y,
        vfov_deg: 60.0,
    });
    scene
}

/// The "default" scene: smooth, flat and sharp-edged solids standing on a ground square, close
/// together so that the framing camera shows them large, with contact points, occlusion and
/// shadows for the approximations to get wrong (about 120k triangles).
fn showcase() -> Vec<(&'static str, Shape)> {
    let place = |shape: Shape, scale: Vec3, turn_deg: f32, at: Vec3| {
        shape.transformed(Mat4::from_scale_rotation_translation(
            scale,
            Quat::from_rotation_y(turn_deg.to_radians()),
            at,
        ))
    };
    let bump_radius = 0.5;
    let bump_lift = bump_radius * (1.0 + BUMP as f32);
    let stand_up = Mat4::from_rotation_x(90f32.to_radians());
    let (major, minor) = (0.45, 0.16);
    vec![
        ("ground", shapes::grid_plane(2.2, 48)),
        (
            "sphere",
            place(sphere(), Vec3::splat(0.7), 0.0, Vec3::new(0.0, 0.7, 0.0)),
        ),
        (
            "torus",
            shapes::torus(major, minor, 128, 48).transformed(
                Mat4::from_translation(Vec3::new(0.5, (major + minor) as f32, -1.45))
                    * Mat4::from_rotation_y(35f32.to_radians())
                    * stand_up,
            ),
        ),
        (
            "cube",
            place(
                shapes::cube(8),
                Vec3::splat(0.4),
                25.0,
                Vec3::new(0.05, 0.4, 1.4),
            ),
        ),
        (
            "cylinder",
            place(
                shapes::cylinder(96, 4),
                Vec3::new(0.28, 0.55, 0.28),
                0.0,
                Vec3::new(-1.6, 0.55, -0.6),
            ),
        ),
        (
            "cone",
            place(
                shapes::cone(96),
                Vec3::new(0.35, 0.45, 0.35),
                0.0,
                Vec3::new(1.35, 0.45, 0.35),
            ),
        ),
        (
            "bumpy-sphere",
            place(
                bumpy_sphere(),
                Vec3::splat(bump_radius),
                0.0,
                Vec3::new(-1.3, bump_lift, 1.0),
            ),
        ),
    ]
}
