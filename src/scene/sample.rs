//! Points sampled from a scene's own triangles: the point-cloud input whose exact surface is
//! known. Tests and the benchmark build an RBVH from such a cloud and referee it against the
//! exact BVH of the very mesh it was sampled from, which measures what building from points
//! costs in accuracy, apart from everything a real scan adds.

use std::path::PathBuf;

use glam::{DVec3, Vec3};
use rayon::prelude::*;

use super::Scene;
use crate::points::{PointCloud, MIN_POINTS};
use crate::random::{mix64, SplitMix64};
use crate::{rgba, Error, Result};

/// Where the points come from when a mesh's RBVH is to be built from points, to be refereed by
/// the exact BVH of the mesh's own triangles ([`Scene::add_points`]).
#[derive(Clone, Debug, PartialEq)]
pub enum PointSource {
    /// This many points sampled over the triangles ([`Scene::sample_points`]).
    Sampled(usize),
    /// A scan of the same object, from a point-cloud file (`.ply`, `.xyz`), such as the vertices
    /// of the PLY the mesh was reconstructed from.
    File(PathBuf),
}

/// How far, as a fraction of the mesh's box diagonal, a scan's box may lie from the mesh's on
/// any side and still be taken as a scan of it: loose enough for a scan's stray points and a
/// mesh's hole filling, tight enough to catch a scan of another object, or in other units.
pub const SCAN_MATCH: f32 = 0.05;

impl PointSource {
    /// "437645 points" or "points of dragon.ply": what a benchmark row adds to its scene's name.
    pub fn label(&self) -> String {
        match self {
            PointSource::Sampled(count) => format!("{count} points"),
            PointSource::File(path) => format!(
                "points of {}",
                path.file_name()
                    .unwrap_or(path.as_os_str())
                    .to_string_lossy()
            ),
        }
    }
}

/// Host bytes a sampled point takes while the cloud is made: its sample (triangle and point, 24)
/// beside the cloud's position, normal, spacing and colour (32).
const SAMPLE_BYTES: u64 = 56;

impl Scene {
    /// Sets [`Scene::points`] from `source` (sampled with `seed`), so that an RBVH of the scene
    /// is built from them while the exact BVH stays on the triangles, its referee. A scan from a
    /// file must lie where the triangles do: its box within [`SCAN_MATCH`] of the diagonal of
    /// theirs on every side, or it is an error naming both.
    pub fn add_points(&mut self, source: &PointSource, seed: u64) -> Result<()> {
        if self.triangle_count() == 0 {
            return Err(Error::param(
                "points",
                format!(
                    "{} has no triangles to sample points from or to compare a scan with: points \
                     are added to a mesh",
                    self.name
                ),
            ));
        }
        let cloud = match source {
            PointSource::Sampled(count) => self.sample_points(*count, seed)?,
            PointSource::File(path) => {
                let cloud = PointCloud::load(path)?;
                let mesh = self.bounds();
                let scan = cloud.bounds();
                let off = (scan.min - mesh.min)
                    .abs()
                    .max((scan.max - mesh.max).abs())
                    .max_element();
                if off.is_nan() || off > SCAN_MATCH * mesh.diagonal() {
                    return Err(Error::param(
                        "points",
                        format!(
                            "{} spans {:?}..{:?} but {} spans {:?}..{:?}: a scan must cover the mesh it is \
                             compared with (each side within {}% of its diagonal)",
                            path.display(),
                            scan.min,
                            scan.max,
                            self.name,
                            mesh.min,
                            mesh.max,
                            SCAN_MATCH * 100.0
                        ),
                    ));
                }
                cloud
            }
        };
        self.points = Some(cloud);
        Ok(())
    }

    /// `count` points spread uniformly by area over the scene's triangles, as a scan of the
    /// scene would give, to build an RBVH from points that the exact BVH of the same triangles
    /// then referees. Each point carries its triangle's geometric normal as wound (`(b − a) ×
    /// (c − a)`, normalized: the convention of [`crate::geom::Hit::normal`]) and, when the
    /// scene has materials, the triangle's colour there ([`Scene::colour_at`], packed by
    /// [`crate::rgba::pack`]). The spacing is estimated as for a scan.
    ///
    /// A triangle is chosen with probability proportional to its area, by binary search in the
    /// cumulative area table, and a point in it uniformly by the square-root mapping of two
    /// uniform numbers to barycentrics (Osada, Funkhouser, Chazelle & Dobkin, "Shape
    /// Distributions", ACM TOG 2002, §4.2; Pharr, Jakob & Humphreys, *Physically Based
    /// Rendering*, 3rd ed., §13.6.5). Zero-area triangles get no points. Point `i` draws from its
    /// own [`SplitMix64`] stream, a hash of `seed` and `i`, so the cloud is the same for a seed
    /// on any number of threads.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] (`points`) when `count` is below [`MIN_POINTS`], when the
    /// cloud would not fit the host's available memory, or when no triangle has an area; the errors of [`Scene::validate`] for a scene that is not well formed.
    pub fn sample_points(&self, count: usize, seed: u64) -> Result<PointCloud> {
        if count < MIN_POINTS {
            return Err(Error::param(
                "points",
                format!("{count} point(s) asked for: a point cloud needs at least {MIN_POINTS}"),
            ));
        }
        // Refused up front where they cannot fit, rather than aborted on by the allocator (the
        // system's MemAvailable: a cgroup's own limit is not seen).
        let needed = (count as u64).saturating_mul(SAMPLE_BYTES);
        if let Some(available) = super::instances::available_memory() {
            if needed > available {
                return Err(Error::param(
                    "points",
                    format!(
                        "{count} points would take about {:.1} GB of host memory to sample, and \
                         {:.1} GB are available",
                        needed as f64 / 1e9,
                        available as f64 / 1e9
                    ),
                ));
            }
        }
        self.validate()?;
        // Areas and normals in f64: a cross product of f32 edges can overflow f32, and a
        // sliver's can underflow where f64's does not.
        let crosses: Vec<DVec3> = (0..self.triangle_count())
            .map(|t| {
                let [a, b, c] = self.triangle(t).map(Vec3::as_dvec3);
                (b - a).cross(c - a)
            })
            .collect();
        let mut total = 0.0f64;
        let cumulative: Vec<f64> = crosses
            .iter()
            .map(|cross| {
                total += 0.5 * cross.length();
                total
            })
            .collect();
        let Some(last) = crosses.iter().rposition(|cross| cross.length() > 0.0) else {
            return Err(Error::param(
                "points",
                format!(
                    "{}: none of its {} triangle(s) has an area to sample points from",
                    self.name,
                    self.triangle_count()
                ),
            ));
        };
        let samples: Vec<(usize, Vec3)> = (0..count)
            .into_par_iter()
            .map(|i| {
                let mut rng = SplitMix64::new(mix64(seed ^ mix64(i as u64)));
                // The first triangle whose cumulative area exceeds the target has a positive
                // area; `min` catches a target that rounds up to the total.
                let target = unit(&mut rng) * total;
                let t = cumulative.partition_point(|&c| c <= target).min(last);
                let (r1, r2) = (unit(&mut rng), unit(&mut rng));
                let s = r1.sqrt();
                let [a, b, c] = self.triangle(t).map(Vec3::as_dvec3);
                let p = (1.0 - s) * a + (s * (1.0 - r2)) * b + (s * r2) * c;
                (t, p.as_vec3())
            })
            .collect();
        let positions = samples.iter().map(|&(_, p)| p).collect();
        let normals = samples
            .iter()
            .map(|&(t, _)| crosses[t].normalize().as_vec3())
            .collect();
        // `colour_at` has a colour for every triangle of a validated scene with materials; were
        // one missing, the cloud would go without colours rather than with invented ones.
        let colours = self.surface.as_ref().and_then(|_| {
            samples
                .par_iter()
                .map(|&(t, p)| self.colour_at(t, p).map(rgba::pack))
                .collect::<Option<Vec<u32>>>()
        });
        PointCloud::new(&self.name, positions, Some(normals), colours)
    }
}

/// Uniform in `[0, 1)` from the top 53 bits of the stream: finer than `next_f32`'s 24, so that a
/// table of millions of triangles is resolved.
fn unit(rng: &mut SplitMix64) -> f64 {
    (rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64
}

#[cfg(test)]
mod tests {
    use glam::Vec4;

    use super::*;
    use crate::scene::{Material, ObjectSurface};

    /// The unit square in the xy plane as two triangles wound counter-clockwise seen from +z,
    /// the first below the diagonal y = x, the second above.
    fn square() -> Scene {
        let mut scene = Scene::new("square");
        scene.push_object(
            "square",
            &[Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y],
            &[[0, 1, 2], [0, 2, 3]],
        );
        scene
    }

    /// More points than the host's memory could hold are refused before any is sampled, where
    /// the system says what is available (`MemAvailable`; a cgroup's own limit is not seen).
    #[test]
    fn points_beyond_the_hosts_memory_are_refused_up_front() {
        if crate::scene::available_memory().is_none() {
            return;
        }
        let e = square().sample_points(1 << 40, 1).unwrap_err().to_string();
        assert!(e.contains("host memory") && e.contains("points"), "{e}");
    }

    #[test]
    fn points_cover_the_square_uniformly_with_wound_normals() {
        let count = 4000;
        let cloud = square()
            .sample_points(count, 1)
            .expect("the square has area");
        assert_eq!(cloud.len(), count);
        assert!(cloud.colours.is_none());
        for (p, n) in cloud.positions.iter().zip(&cloud.normals) {
            assert!(
                (0.0..=1.0).contains(&p.x) && (0.0..=1.0).contains(&p.y) && p.z == 0.0,
                "{p} outside the square"
            );
            assert_eq!(*n, Vec3::Z);
        }
        // Pearson's χ² over the four quadrants, 3 degrees of freedom: 16.27 is its 99.9th
        // percentile.
        let mut quadrants = [0usize; 4];
        for p in &cloud.positions {
            quadrants[usize::from(p.x >= 0.5) + 2 * usize::from(p.y >= 0.5)] += 1;
        }
        let expected = count as f64 / 4.0;
        let chi2: f64 = quadrants
            .iter()
            .map(|&o| (o as f64 - expected).powi(2) / expected)
            .sum();
        assert!(chi2 < 16.27, "quadrants {quadrants:?}: χ² = {chi2}");
    }

    #[test]
    fn normals_follow_the_winding() {
        let mut scene = Scene::new("flipped");
        scene.push_object("flipped", &[Vec3::ZERO, Vec3::Y, Vec3::X], &[[0, 1, 2]]);
        let cloud = scene.sample_points(100, 0).expect("the triangle has area");
        assert!(cloud.normals.iter().all(|&n| n == -Vec3::Z));
    }

    #[test]
    fn a_seed_gives_one_cloud() {
        let scene = square();
        let a = scene.sample_points(500, 9).expect("the square has area");
        assert_eq!(a, scene.sample_points(500, 9).expect("the square has area"));
        assert_ne!(
            a.positions,
            scene
                .sample_points(500, 10)
                .expect("the square has area")
                .positions
        );
    }

    #[test]
    fn zero_area_triangles_get_no_points() {
        let mut scene = square();
        // A degenerate triangle far away: a point there would widen the cloud's bounds.
        let far = Vec3::splat(100.0);
        scene.push_object("sliver", &[far, far, far + Vec3::X], &[[0, 1, 2]]);
        let cloud = scene.sample_points(1000, 2).expect("the square has area");
        assert!(cloud.positions.iter().all(|p| p.x <= 1.0 && p.y <= 1.0));
    }

    #[test]
    fn colours_come_from_the_materials() {
        let mut scene = Scene::new("coloured");
        let red = scene.add_material(Material::constant("red", Vec4::new(1.0, 0.0, 0.0, 1.0)));
        let blue = scene.add_material(Material::constant("blue", Vec4::new(0.0, 0.0, 1.0, 1.0)));
        let plain = square();
        scene.push_textured_object(
            "square",
            &plain.positions,
            &plain.triangles,
            ObjectSurface {
                material_of_triangle: vec![red, blue],
                uv_of_triangle: vec![[glam::Vec2::ZERO; 3]; 2],
                colour_of_triangle: None,
            },
        );
        let cloud = scene.sample_points(200, 3).expect("the square has area");
        let colours = cloud.colours.expect("a scene with materials gives colours");
        for (p, &c) in cloud.positions.iter().zip(&colours) {
            // Points on the diagonal belong to either triangle.
            if (p.x - p.y).abs() > 1e-6 {
                let expected = if p.x > p.y {
                    Vec4::new(1.0, 0.0, 0.0, 1.0)
                } else {
                    Vec4::new(0.0, 0.0, 1.0, 1.0)
                };
                assert_eq!(c, rgba::pack(expected), "at {p}");
            }
        }
    }

    #[test]
    fn too_few_points_or_no_area_is_an_error() {
        let message = |e: Error| e.to_string();
        let err = square()
            .sample_points(0, 0)
            .expect_err("no points asked for");
        assert!(
            matches!(&err, Error::InvalidParameter { name, .. } if name == "points"),
            "{err}"
        );
        assert!(message(err).contains("at least 3"));
        let mut flat = Scene::new("flat");
        flat.push_object(
            "line",
            &[Vec3::ZERO, Vec3::X, Vec3::X * 2.0],
            &[[0, 1, 2], [0, 0, 1]],
        );
        let err = flat.sample_points(100, 0).expect_err("no area");
        assert!(
            matches!(&err, Error::InvalidParameter { name, .. } if name == "points"),
            "{err}"
        );
        assert!(message(err).contains("none of its 2 triangle(s) has an area"));
        let empty = Scene::new("empty");
        assert!(empty.sample_points(100, 0).is_err());
    }
}
