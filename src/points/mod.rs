//! Point clouds: a scan's samples of a surface, the second kind of input the paper's RBVHs take
//! "natively" (Novák & Dachsbacher 2012, abstract) — a height field is sampled from a surface,
//! and a scan's points are such samples.
//!
//! * `ply`: PLY files (ASCII, binary little- and big-endian): positions, optional normals and
//!   colours;
//! * `xyz`: plain text, one point per line (`x y z`, or `x y z nx ny nz`);
//! * `estimate`: what a file may lack — normals (principal component analysis of each point's
//!   nearest neighbours, oriented consistently along a minimum spanning tree, after Hoppe et al.,
//!   "Surface Reconstruction from Unorganized Points", SIGGRAPH 1992) — and what no file says: the
//!   spacing of the samples around each point, from which the builder decides how far a point's
//!   splat reaches and how much surface it stands for.
//!
//! A [`PointCloud`] is checked and complete once made: finite positions, unit normals, a spacing
//! per point. The RBVH builder (`crate::rbvh`) splats it into height fields; a [`crate::Scene`]
//! carries one (from a file, a scene file, or sampled from its own triangles as the referee's
//! input).

mod estimate;
mod ply;
mod xyz;

use std::path::Path;

use glam::{DVec3, Mat4, Vec3};

use crate::geom::Aabb;
use crate::{Error, Result};

/// Fewest points a cloud may have: fewer cannot span a surface (and a normal cannot be estimated).
pub const MIN_POINTS: usize = 3;

/// A checked point cloud: every array has one entry per point.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PointCloud {
    /// World-space positions, finite.
    pub positions: Vec<Vec3>,
    /// Unit normals, pointing to the side the surface faces (from the file, or estimated and
    /// oriented consistently).
    pub normals: Vec<Vec3>,
    /// Per point, its colour packed as [`crate::rgba`] (red in the low byte, RGB sRGB-encoded,
    /// alpha linear), when the input has colours.
    pub colours: Option<Vec<u32>>,
    /// Per point, the local sample spacing: the side of the square of surface the point stands
    /// for (√(π/k)·r_k, with r_k the distance to its k-th nearest neighbour), never 0.
    pub spacing: Vec<f32>,
}

/// What a reader gives: positions, and normals and colours when the file has them. Lengths are
/// the readers' to keep equal; [`PointCloud::from_raw`] checks them anyway.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct RawPoints {
    pub positions: Vec<Vec3>,
    pub normals: Option<Vec<Vec3>>,
    /// Packed as [`PointCloud::colours`].
    pub colours: Option<Vec<u32>>,
}

impl PointCloud {
    /// Loads a point cloud from a `.ply` or `.xyz` file (case-insensitive extension). Normals the
    /// file lacks are estimated; every error names the file.
    pub fn load(path: &Path) -> Result<PointCloud> {
        let ext = path
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase());
        let raw = match ext.as_deref() {
            Some("ply") => ply::read(path)?,
            Some("xyz") => xyz::read(path)?,
            _ => {
                return Err(Error::parse(
                    path,
                    None,
                    "unsupported point-cloud type: expected .ply or .xyz",
                ))
            }
        };
        PointCloud::from_raw(&path.display().to_string(), raw)
    }

    /// A checked cloud of `positions`, with `normals` (unit length after normalizing; estimated
    /// when `None`) and `colours` (packed as [`PointCloud::colours`]). `source` names the input
    /// in errors: a non-finite position or normal (naming the point), a zero normal, lengths that
    /// differ, fewer than [`MIN_POINTS`] distinct points, or all points on one line (no surface to
    /// sample, no normal to estimate).
    pub fn new(
        source: &str,
        positions: Vec<Vec3>,
        normals: Option<Vec<Vec3>>,
        colours: Option<Vec<u32>>,
    ) -> Result<PointCloud> {
        PointCloud::from_raw(
            source,
            RawPoints {
                positions,
                normals,
                colours,
            },
        )
    }

    fn from_raw(source: &str, raw: RawPoints) -> Result<PointCloud> {
        let invalid = |message: String| Error::InvalidGeometry {
            source_name: source.to_owned(),
            message,
        };
        let n = raw.positions.len();
        if let Some(i) = raw.positions.iter().position(|p| !p.is_finite()) {
            return Err(invalid(format!(
                "point {i} has a non-finite position {}",
                raw.positions[i]
            )));
        }
        for (what, len) in [
            ("normals", raw.normals.as_ref().map(Vec::len)),
            ("colours", raw.colours.as_ref().map(Vec::len)),
        ] {
            if let Some(len) = len.filter(|&len| len != n) {
                return Err(invalid(format!("{len} {what} for {n} points")));
            }
        }
        check_spans_a_surface(&raw.positions).map_err(invalid)?;
        let (estimated, spacing) = estimate::estimate(&raw.positions, raw.normals.is_none());
        let normals = match raw.normals {
            Some(given) => given
                .into_iter()
                .enumerate()
                .map(|(i, normal)| {
                    normal.try_normalize().ok_or_else(|| {
                        invalid(format!(
                            "point {i} has the normal {normal}, which has no direction (remove the file's normals to have them estimated)"
                        ))
                    })
                })
                .collect::<Result<Vec<Vec3>>>()?,
            None => estimated.unwrap_or_default(),
        };
        Ok(PointCloud {
            positions: raw.positions,
            normals,
            colours: raw.colours,
            spacing,
        })
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    /// Whether the cloud has no points (only [`PointCloud::default`] does: a checked cloud has at
    /// least [`MIN_POINTS`]).
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// Box of the positions.
    pub fn bounds(&self) -> Aabb {
        Aabb::from_points(self.positions.iter().copied())
    }

    /// The cloud placed by `m`: positions transformed, normals by the inverse transpose (so they
    /// stay normal to the surface, mirrors included), and each spacing by the square root of the
    /// factor by which `m` scales the area of the surface there: `|det M|·|M⁻ᵀn|` for unit
    /// normal `n` (Nanson's formula), so that a cloud squashed along one axis keeps its splats
    /// as wide as its points are apart.
    pub fn transformed(&self, m: Mat4) -> PointCloud {
        let normal_matrix = m.inverse().transpose();
        let det = m.determinant().abs();
        let (normals, spacing) = self
            .normals
            .iter()
            .zip(&self.spacing)
            .map(|(&n, &s)| {
                let turned = normal_matrix.transform_vector3(n);
                let area = det * turned.length();
                (turned.normalize_or(n), s * area.sqrt())
            })
            .unzip();
        PointCloud {
            positions: self
                .positions
                .iter()
                .map(|&p| m.transform_point3(p))
                .collect(),
            normals,
            colours: self.colours.clone(),
            spacing,
        }
    }

    /// Appends `other`'s points. Colours are kept when both have them, or when one side is empty;
    /// otherwise the points without colours get opaque white.
    pub fn append(&mut self, other: &PointCloud) {
        const WHITE: u32 = u32::MAX;
        self.colours = match (self.colours.take(), &other.colours) {
            (None, None) => None,
            (mine, theirs) => {
                let mut colours = mine.unwrap_or_else(|| vec![WHITE; self.len()]);
                match theirs {
                    Some(theirs) => colours.extend_from_slice(theirs),
                    None => colours.extend(std::iter::repeat_n(WHITE, other.len())),
                }
                Some(colours)
            }
        };
        self.positions.extend_from_slice(&other.positions);
        self.normals.extend_from_slice(&other.normals);
        self.spacing.extend_from_slice(&other.spacing);
    }
}

/// Fails, saying why, when `positions` cannot span a surface: fewer than [`MIN_POINTS`] distinct
/// points, or all of them within a millionth of the cloud's extent of one line.
fn check_spans_a_surface(positions: &[Vec3]) -> std::result::Result<(), String> {
    // In f64: squared distances of f32 coordinates overflow near 1e19 and underflow near 1e-19.
    let first = positions.first().map_or(DVec3::ZERO, |p| p.as_dvec3());
    let farthest = |from: DVec3| {
        positions
            .iter()
            .map(|p| p.as_dvec3())
            .max_by(|a, b| {
                a.distance_squared(from)
                    .total_cmp(&b.distance_squared(from))
            })
            .unwrap_or(from)
    };
    let a = farthest(first);
    let b = farthest(a);
    let extent = a.distance(b);
    let distinct = if extent > 0.0 {
        2
    } else {
        positions.len().min(1)
    };
    let axis = (b - a).normalize_or_zero();
    let off_line = positions
        .iter()
        .map(|p| {
            let d = p.as_dvec3() - a;
            (d - d.dot(axis) * axis).length()
        })
        .fold(0.0f64, f64::max);
    if positions.len() < MIN_POINTS || distinct < 2 {
        return Err(format!(
            "{} point(s) at {} distinct position(s): a surface needs at least {MIN_POINTS} points not on one line",
            positions.len(),
            distinct
        ));
    }
    if off_line <= 1e-6 * extent {
        return Err(format!(
            "all {} points lie on one line (from {a} to {b}): they span no surface",
            positions.len()
        ));
    }
    Ok(())
}

/// For the readers' tests: the line and message of the parse error that `result` must be, for
/// the file `path`.
#[cfg(test)]
fn parse_error_of(result: Result<RawPoints>, path: &str) -> (Option<usize>, String) {
    match result {
        Err(Error::Parse {
            path: named,
            line,
            message,
        }) => {
            assert_eq!(named, Path::new(path));
            (line, message)
        }
        other => panic!("expected a parse error, got {other:?}"),
    }
}
