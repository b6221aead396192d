//! The light that arrives from infinitely far away in every direction: an analytic sky, a constant
//! (for closed-form tests), or a measured HDR environment map in latitude–longitude layout.
//!
//! Directions are in world space with **+y up**, like the scenes' cameras and the preview sky of
//! [`crate::output::shade`].

use std::f32::consts::{PI, TAU};
use std::path::Path;

use glam::Vec3;

use crate::{Error, Result};

/// Largest side of an environment map, in texels.
pub const MAX_MAP_SIDE: u32 = 32_768;
/// Largest texel count of an environment map (2²⁶ texels are 768 MiB as RGB `f32`): a bound on
/// what a header may make us allocate before a single texel is read.
pub const MAX_MAP_TEXELS: u64 = 1 << 26;

/// Radiance arriving from every direction.
#[derive(Clone, Debug, PartialEq)]
pub enum Environment {
    /// The built-in analytic sky, see [`Sky`].
    Sky(Sky),
    /// The same radiance from every direction: the "white furnace" of closed-form tests.
    Uniform(Vec3),
    /// A measured environment, see [`LatLongMap`].
    Map(LatLongMap),
}

impl Environment {
    /// Loads an environment map from the EXR file at `path`; see [`LatLongMap::load`].
    #[cfg(feature = "exr")]
    pub fn load(path: &Path) -> Result<Environment> {
        LatLongMap::load(path).map(Environment::Map)
    }

    /// The radiance arriving from direction `dir` (travelling along `-dir`); `dir` need not be
    /// unit length. A zero or non-finite `dir` (from an invalid primary ray) is looked up as the
    /// zero vector, which every variant answers with a finite radiance.
    pub fn radiance(&self, dir: Vec3) -> Vec3 {
        let dir = dir.normalize_or_zero();
        match self {
            Environment::Sky(sky) => sky.radiance(dir),
            Environment::Uniform(l) => *l,
            Environment::Map(map) => map.radiance(dir),
        }
    }
}

/// A procedural clear sky: a vertical gradient with a glow around the sun. It is not a physical
/// sky model (for one, see Hošek & Wilkie, "An Analytic Model for Full Spectral Sky-Dome
/// Radiance", SIGGRAPH 2012); it is smooth, cheap and bounded, so that a few cosine-weighted
/// samples per pixel already give a recognisable, low-noise picture. For a unit direction `d`
/// with height `y = d.y`:
///
/// ```text
/// above the horizon (y ≥ 0):  base = HORIZON + (ZENITH − HORIZON) · √y
/// below the horizon (y < 0):  base = HORIZON + (GROUND − HORIZON) · min(1, −8y)
/// L(d) = base + SUN · max(0, d · sun)^SUN_EXPONENT
/// ```
///
/// Both halves meet at `HORIZON`, so the sky is continuous. The sun is a broad glow rather than a
/// disk: with exponent 16 it carries `2π/18 ≈ 0.35 sr × SUN` of irradiance at normal incidence,
/// about half the sky's, and at most a few times the sky's radiance, so that shading still shows
/// its direction while 16 cosine-weighted samples per pixel stay free of bright speckles (a small
/// bright disk would need importance sampling of the light to converge).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sky {
    /// Unit direction towards the sun.
    pub sun: Vec3,
}

impl Sky {
    /// Linear RGB radiance straight up (`y = 1`): a clear blue.
    pub const ZENITH: Vec3 = Vec3::new(0.25, 0.45, 0.95);
    /// Linear RGB radiance at the horizon (`y = 0`), where sky and ground meet: a pale haze.
    pub const HORIZON: Vec3 = Vec3::new(0.9, 0.9, 0.95);
    /// Linear RGB radiance from below, reached at `y ≤ −1/8`: a dull brown.
    pub const GROUND: Vec3 = Vec3::new(0.35, 0.3, 0.25);
    /// Linear RGB peak radiance of the sun's glow, added towards [`sun`](Sky::sun).
    pub const SUN: Vec3 = Vec3::new(3.0, 2.7, 2.2);
    /// Exponent of the glow's cosine lobe: larger is tighter (see the type's documentation).
    pub const SUN_EXPONENT: i32 = 16;

    /// A sky with its sun towards `sun` (normalised here), or straight up when `sun` is zero or
    /// not finite.
    pub fn towards(sun: Vec3) -> Sky {
        let sun = sun.normalize_or_zero();
        Sky {
            sun: if sun == Vec3::ZERO { Vec3::Y } else { sun },
        }
    }

    /// The radiance from unit direction `dir`, by the formula in the type's documentation.
    pub fn radiance(&self, dir: Vec3) -> Vec3 {
        let y = dir.y.clamp(-1.0, 1.0);
        let base = if y >= 0.0 {
            Sky::HORIZON.lerp(Sky::ZENITH, y.sqrt())
        } else {
            Sky::HORIZON.lerp(Sky::GROUND, (-8.0 * y).min(1.0))
        };
        base + Sky::SUN * dir.dot(self.sun).max(0.0).powi(Sky::SUN_EXPONENT)
    }
}

impl Default for Sky {
    /// The sun where the CLI's default light comes from
    /// ([`crate::rays::DEFAULT_LIGHT`]), so IBL and preview renders are lit alike.
    fn default() -> Sky {
        match crate::rays::DEFAULT_LIGHT {
            crate::scene::Light::Directional { direction } => Sky::towards(-direction),
            crate::scene::Light::Point { position } => Sky::towards(position),
        }
    }
}

/// An RGB radiance map in latitude–longitude (equirectangular) layout, the layout of most HDR
/// environment maps: row `0` looks straight up (+y), the last row straight down, and columns sweep
/// the azimuth so that the image's centre looks along −z and `u` grows towards +x, i.e.
///
/// ```text
/// u = 1/2 + atan2(d.x, −d.z) / 2π,   v = acos(d.y) / π,   texel (x, y) centred at ((x + ½)/w, (y + ½)/h)
/// ```
///
/// Lookups are bilinear, wrapping around in azimuth and clamped at the poles. The radiance a map
/// holds is used as is (no exposure, no solid-angle weighting: cosine sampling needs none).
#[derive(Clone, Debug, PartialEq)]
pub struct LatLongMap {
    width: u32,
    height: u32,
    texels: Vec<Vec3>,
}

impl LatLongMap {
    /// A map of `width × height` texels, row-major, top row first. `source` names where the
    /// texels came from in errors. Every texel must be finite and non-negative: a NaN or an
    /// infinity would spread through every pixel that samples it, and negative radiance has no
    /// meaning.
    pub fn new(width: u32, height: u32, texels: Vec<Vec3>, source: &Path) -> Result<LatLongMap> {
        check_size(width as usize, height as usize, source)?;
        if texels.len() as u64 != u64::from(width) * u64::from(height) {
            return Err(Error::parse(
                source,
                None,
                format!(
                    "{} texels for a {width}×{height} environment map",
                    texels.len()
                ),
            ));
        }
        if let Some(i) = texels
            .iter()
            .position(|t| !t.is_finite() || t.min_element() < 0.0)
        {
            return Err(Error::parse(
                source,
                None,
                format!(
                    "environment texel ({}, {}) is {} (radiance must be finite and non-negative)",
                    i % width as usize,
                    i / width as usize,
                    texels[i]
                ),
            ));
        }
        Ok(LatLongMap {
            width,
            height,
            texels,
        })
    }

    /// Reads the R, G and B channels of the first layer of the EXR file at `path` that has them
    /// (as `f32`, whatever their stored type), at its largest resolution level. Fails with
    /// [`Error::Io`] when the file cannot be opened, and with [`Error::Parse`] naming the file
    /// when it is not a regular file, not a valid EXR, lacks R, G or B, is empty or larger than
    /// [`MAX_MAP_SIDE`] / [`MAX_MAP_TEXELS`], or holds a texel that is not finite and
    /// non-negative. (Feature `exr`; without it, build a map from texels with [`LatLongMap::new`].)
    #[cfg(feature = "exr")]
    pub fn load(path: &Path) -> Result<LatLongMap> {
        use ::exr::prelude::{read, MetaData, ReadChannels, ReadLayers};
        use std::fs::File;
        use std::io::{BufReader, Seek};

        // Checked before opening, a regular file: the EXR reader seeks.
        let metadata = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
        crate::io::input::regular_file(path, &metadata)?;
        let file = File::open(path).map_err(|e| Error::io(path, e))?;
        let mut reader = BufReader::new(file);
        let malformed = |e: ::exr::error::Error| {
            Error::parse(
                path,
                None,
                format!("not a readable OpenEXR image with R, G and B channels: {e}"),
            )
        };
        // The header first, so that a corrupt or hostile size is refused before allocating.
        let meta = MetaData::read_from_buffered(&mut reader, false).map_err(malformed)?;
        for header in meta.headers.iter() {
            check_size(header.layer_size.0, header.layer_size.1, path)?;
        }
        reader.rewind().map_err(|e| Error::io(path, e))?;
        // Each row is allocated when the first of its texels is decoded, not all of them up
        // front: a header of a few hundred bytes may claim MAX_MAP_TEXELS (768 MiB of texels),
        // and only texels that the file really holds should cost memory.
        let image = read()
            .no_deep_data()
            .largest_resolution_level()
            .rgb_channels(
                |size, _| (size.0, vec![Vec::new(); size.1]),
                |(width, rows): &mut (usize, Vec<Vec<Vec3>>), pos, (r, g, b): (f32, f32, f32)| {
                    let row = &mut rows[pos.1];
                    if row.is_empty() {
                        row.resize(*width, Vec3::ZERO);
                    }
                    row[pos.0] = Vec3::new(r, g, b);
                },
            )
            .first_valid_layer()
            .all_attributes()
            .from_buffered(reader)
            .map_err(malformed)?;
        let size = image.layer_data.size;
        let (_, rows) = image.layer_data.channel_data.pixels;
        if let Some(y) = rows.iter().position(Vec::is_empty) {
            return Err(Error::parse(
                path,
                None,
                format!("environment map row {y} has no texels (is the file truncated?)"),
            ));
        }
        let mut texels = Vec::with_capacity(size.0 * size.1);
        for row in rows {
            texels.extend(row);
        }
        // check_size bounded both sides by MAX_MAP_SIDE, so they fit in u32.
        LatLongMap::new(size.0 as u32, size.1 as u32, texels, path)
    }

    /// Texels per row, covering the full 360° of azimuth; 1..=[`MAX_MAP_SIDE`].
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Rows, from straight up (row 0) to straight down; 1..=[`MAX_MAP_SIDE`].
    pub fn height(&self) -> u32 {
        self.height
    }

    /// The bilinearly interpolated radiance from unit direction `dir`.
    pub fn radiance(&self, dir: Vec3) -> Vec3 {
        let u = 0.5 + dir.x.atan2(-dir.z) / TAU;
        let v = dir.y.clamp(-1.0, 1.0).acos() / PI;
        // Continuous texel coordinates, with texel centres at integers.
        let x = u * self.width as f32 - 0.5;
        let y = (v * self.height as f32 - 0.5).clamp(0.0, (self.height - 1) as f32);
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let w = i64::from(self.width);
        let column = |dx: i64| (x0 as i64 + dx).rem_euclid(w) as usize;
        let row = |dy: usize| (y0 as usize + dy).min(self.height as usize - 1);
        let at = |c: usize, r: usize| self.texels[r * self.width as usize + c];
        let (c0, c1, r0, r1) = (column(0), column(1), row(0), row(1));
        let top = at(c0, r0).lerp(at(c1, r0), fx);
        let bottom = at(c0, r1).lerp(at(c1, r1), fx);
        top.lerp(bottom, fy)
    }
}

/// A map must have at least one texel and fit the bounds above.
fn check_size(width: usize, height: usize, source: &Path) -> Result<()> {
    let side = MAX_MAP_SIDE as usize;
    if width == 0 || height == 0 {
        return Err(Error::parse(
            source,
            None,
            format!("the environment map is {width}×{height}: it needs at least one texel"),
        ));
    }
    if width > side || height > side || (width as u64) * (height as u64) > MAX_MAP_TEXELS {
        return Err(Error::parse(
            source,
            None,
            format!(
                "the environment map is {width}×{height}: at most {side} texels a side and \
                 {MAX_MAP_TEXELS} in all"
            ),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn map(width: u32, height: u32, f: impl Fn(u32, u32) -> Vec3) -> LatLongMap {
        let texels = (0..height)
            .flat_map(|y| (0..width).map(move |x| (x, y)))
            .map(|(x, y)| f(x, y))
            .collect();
        LatLongMap::new(width, height, texels, Path::new("in memory")).unwrap()
    }

    #[test]
    fn the_sky_is_continuous_at_the_horizon_and_bright_at_the_sun() {
        let sky = Sky::towards(Vec3::new(0.0, 1.0, 1.0));
        let above = sky.radiance(Vec3::new(-1.0, 1e-6, 0.0).normalize());
        let below = sky.radiance(Vec3::new(-1.0, -1e-6, 0.0).normalize());
        assert!(
            (above - below).abs().max_element() < 1e-2,
            "{above} {below}"
        );
        let sun = sky.radiance(sky.sun);
        assert!((sun - Sky::SUN).min_element() > 0.0, "{sun}");
        assert!(
            sun.max_element() < (Sky::SUN + Sky::HORIZON).max_element(),
            "{sun}"
        );
        assert_eq!(Sky::towards(Vec3::NAN).sun, Vec3::Y);
    }

    #[test]
    fn map_rows_run_from_zenith_to_nadir_and_the_centre_looks_along_minus_z() {
        // Rows: 1 at the top, 3 at the bottom; columns: x index + 1.
        let m = map(4, 2, |x, y| {
            Vec3::new((y * 2 + 1) as f32, x as f32 + 1.0, 0.0)
        });
        assert_eq!(m.radiance(Vec3::Y).x, 1.0);
        assert_eq!(m.radiance(Vec3::NEG_Y).x, 3.0);
        // -z is u = 1/2: halfway between columns 1 and 2 (centres at 3/8 and 5/8).
        let centre = m.radiance(Vec3::NEG_Z);
        assert!((centre.y - 2.5).abs() < 1e-5, "{centre}");
        assert!((centre.x - 2.0).abs() < 1e-5, "{centre}");
        // +z is u = 0 or 1: halfway between the last and the first column, wrapping around.
        assert!((m.radiance(Vec3::Z).y - 2.5).abs() < 1e-5);
        // +x is u = 3/4: the centre of column 2.5 → between columns 2 and 3.
        assert!((m.radiance(Vec3::X).y - 3.5).abs() < 1e-5);
    }

    #[test]
    fn a_constant_map_is_constant_everywhere() {
        let m = map(7, 3, |_, _| Vec3::new(0.5, 1.0, 2.0));
        for d in [Vec3::X, Vec3::NEG_Y, Vec3::new(0.3, 0.9, -0.2), Vec3::Y] {
            assert!(
                (m.radiance(d.normalize()) - Vec3::new(0.5, 1.0, 2.0))
                    .abs()
                    .max_element()
                    < 1e-6
            );
        }
    }

    #[test]
    fn bad_maps_are_refused_with_the_texel_named() {
        let source = Path::new("in memory");
        let err = LatLongMap::new(0, 4, vec![], source)
            .unwrap_err()
            .to_string();
        assert!(err.contains("0×4"), "{err}");
        let mut texels = vec![Vec3::ONE; 6];
        texels[4] = Vec3::new(1.0, f32::NAN, 1.0);
        let err = LatLongMap::new(3, 2, texels, source)
            .unwrap_err()
            .to_string();
        assert!(err.contains("texel (1, 1)"), "{err}");
        let err = LatLongMap::new(3, 2, vec![Vec3::NEG_ONE; 6], source)
            .unwrap_err()
            .to_string();
        assert!(err.contains("non-negative"), "{err}");
        assert!(LatLongMap::new(3, 2, vec![Vec3::ONE; 5], source).is_err());
    }
}
