//! Headless image regression: render a fixed set of scenes with the exact BVH and RBVH levels, and
//! compare each render with a golden image blessed earlier — so that a change to a shader, the
//! builder or the shading that alters what users see fails a test, with a picture of where.
//!
//! A case ([`Case`]) is a scene traced by one [`Method`]. Its goldens live in one folder as
//! `<case>.png` (the shaded image, 8-bit sRGB, as `rbvh render` writes it) and
//! `<case>_depth.exr` (the primary hit distances, channel `Z`). A render passes when ꟻLIP finds
//! its image close to the golden's and its hit distances agree; [`Tolerance`] gives the limits
//! and why they are what they are. A failing case leaves `<case>_render.png`, the ꟻLIP error
//! picture `<case>_diff.png`, the three side by side with the error's colour bar
//! (`<case>_compare.png`: golden, render, error) and, when the depths disagree,
//! `<case>_depth_diff.png` in the output folder; the names never collide with goldens, so the two
//! folders may be one.
//!
//! ```no_run
//! use rbvh::{gpu::{Context, ContextOptions}, regress};
//!
//! let ctx = Context::new(&ContextOptions::default())?;
//! let report = regress::run(&ctx, &regress::Config::new("tests/golden", "regress-out"))?;
//! print!("{}", report.table());
//! assert!(report.passed());
//! # Ok::<(), rbvh::Error>(())
//! ```
//!
//! [`run_with`] lets the caller make each case's tracer — to check that a modified shader
//! (through [`Tracer::with_shader`]) still renders the goldens, or that the suite catches a
//! broken one.

mod cases;
mod compare;
mod golden;
mod report;

use std::path::{Path, PathBuf};

pub use cases::{cross, Case, Method, Structure};
pub use compare::{DepthScore, ImageScore, Tolerance};
pub use report::{CaseResult, Check, Report};

use self::golden::{Depth, Rgb8};
use crate::gpu::{Context, Tracer};
use crate::output::write_png;
use crate::scene::Scene;
use crate::{Error, Result};

/// The built-in scenes of the shipped suite: the showcase (several objects, flat and curved, with
/// hybrid leaves), a smooth sphere (one curved surface, analytic) and the bunny-like blob (bumps
/// and concave parts).
pub const SCENES: [&str; 3] = ["default", "sphere", "blob"];

/// The methods of the shipped suite: the exact BVH, and RBVH levels from coarsest to finest,
/// every other one, so that a change in how the sampling rate scales shows, without and with level
/// of detail (the default of `rbvh regress`).
pub const METHODS: [Method; 7] = [
    Method::EXACT,
    Method::rbvh(0),
    Method::rbvh(2),
    Method::rbvh(4),
    Method::rbvh_lod(0),
    Method::rbvh_lod(2),
    Method::rbvh_lod(4),
];

/// Image size of the shipped suite: large enough that an RBVH's texel-sized steps cover several
/// pixels, small enough that the 21 cases render in about a second on lavapipe and the
/// goldens stay small.
pub const WIDTH: u32 = 160;
/// Image height of the shipped suite, in pixels (4:3 with [`WIDTH`]).
pub const HEIGHT: u32 = 120;

/// The shipped goldens, relative to the repository root.
pub const GOLDEN_DIR: &str = "tests/golden";

/// The largest image side accepted: regression images are meant to be small.
const MAX_SIDE: u32 = 4096;

/// Whether a run judges renders or replaces the goldens with them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// Compare every render with its golden.
    Compare,
    /// Write every render as its golden (creating the folder), comparing nothing: after a change
    /// that is meant to alter the pictures, and to create goldens for new cases.
    Bless,
}

/// What to render and where the goldens and failure pictures are.
#[derive(Clone, Debug, PartialEq)]
pub struct Config {
    /// The cases to run, in order; at least one, no two with the same [`Case::name`].
    pub cases: Vec<Case>,
    /// Where the goldens are read from (compare: must exist) or written to (bless).
    pub golden_dir: PathBuf,
    /// Where a failing case's render and error pictures go (created when needed).
    pub out_dir: PathBuf,
    /// Render width in pixels, 1..=4096; must match the goldens'.
    pub width: u32,
    /// Render height in pixels, 1..=4096; must match the goldens'.
    pub height: u32,
    /// The pass/fail limits of each comparison.
    pub tolerance: Tolerance,
    /// Compare with the goldens, or write new ones.
    pub mode: Mode,
}

impl Config {
    /// The shipped suite ([`SCENES`] × [`METHODS`] at [`WIDTH`] × [`HEIGHT`], default
    /// tolerance), compared against the goldens in `golden_dir`.
    pub fn new(golden_dir: impl Into<PathBuf>, out_dir: impl Into<PathBuf>) -> Config {
        let scenes: Vec<String> = SCENES.iter().map(|s| s.to_string()).collect();
        Config {
            cases: cross(&scenes, &METHODS),
            golden_dir: golden_dir.into(),
            out_dir: out_dir.into(),
            width: WIDTH,
            height: HEIGHT,
            tolerance: Tolerance::default(),
            mode: Mode::Compare,
        }
    }

    /// Checks the size, the tolerances and the cases (at least one; RBVH levels that are presets;
    /// no two sharing a golden), naming what is wrong.
    pub fn validate(&self) -> Result<()> {
        for (name, side) in [("width", self.width), ("height", self.height)] {
            if !(1..=MAX_SIDE).contains(&side) {
                return Err(Error::param(
                    name,
                    format!("{side} is outside 1..={MAX_SIDE}"),
                ));
            }
        }
        self.tolerance.validate()?;
        if self.cases.is_empty() {
            return Err(Error::param("cases", "no case to run"));
        }
        for case in &self.cases {
            if let Some(level) = case.method.level() {
                crate::rbvh::RbvhParams::quality(level)?;
            }
        }
        // Comparing against a folder that is not there would fail every case alone; say it once.
        if self.mode == Mode::Compare && !self.golden_dir.is_dir() {
            return Err(Error::param(
                "golden",
                format!(
                    "no golden folder {}: run from the repository (whose goldens are in {GOLDEN_DIR}), \
                     give the folder with --golden, or --bless to make goldens there",
                    self.golden_dir.display()
                ),
            ));
        }
        // Found out only at the first failing case, an unusable output folder would end the run
        // there, without the report of the other cases.
        if self.mode == Mode::Compare && self.out_dir.exists() && !self.out_dir.is_dir() {
            return Err(Error::param(
                "out",
                format!(
                    "{} is not a folder: give --out a folder for the failing cases' pictures",
                    self.out_dir.display()
                ),
            ));
        }
        cases::check_unique_names(&self.cases)
    }
}

/// Runs `config` with the crate's own shaders.
pub fn run(ctx: &Context, config: &Config) -> Result<Report> {
    run_with(ctx, config, Tracer::new)
}

/// Runs `config`, tracing each case through the tracer `make_tracer` makes from the case's built
/// structure — e.g. an RBVH through [`Tracer::with_shader`] with a modified shader.
///
/// A golden that is missing, unreadable or of another size fails its case (with a message saying
/// what to do) and the run goes on, so one report lists every problem. Errors that make the run
/// itself meaningless — an invalid config, a scene that does not load, a device error, an output
/// file that cannot be written — are returned.
pub fn run_with(
    ctx: &Context,
    config: &Config,
    mut make_tracer: impl FnMut(&Context, &Structure) -> Result<Tracer>,
) -> Result<Report> {
    config.validate()?;
    let mut loaded: Option<Scene> = None;
    let mut loaded_spec = "";
    let mut results = Vec::with_capacity(config.cases.len());
    for case in &config.cases {
        let scene = match loaded.take() {
            Some(scene) if loaded_spec == case.scene => scene,
            _ => Scene::load(&case.scene)?,
        };
        loaded_spec = &case.scene;
        let structure = case.method.build(&scene)?;
        let tracer = make_tracer(ctx, &structure)?;
        let render = cases::render(&tracer, &structure, &scene, config.width, config.height)?;
        results.push(match config.mode {
            Mode::Compare => compare_case(config, &case.name(), &render)?,
            Mode::Bless => bless_case(config, &case.name(), &render)?,
        });
        loaded = Some(scene);
    }
    Ok(Report {
        cases: results,
        tolerance: config.tolerance,
    })
}

/// What a failing case writes into the output folder, `<case>_<suffix>.png`.
const PICTURES: [&str; 4] = ["render", "diff", "compare", "depth_diff"];

fn golden_png(dir: &Path, name: &str) -> PathBuf {
    dir.join(format!("{name}.png"))
}

fn golden_depth(dir: &Path, name: &str) -> PathBuf {
    dir.join(format!("{name}_depth.exr"))
}

fn missing(path: &Path) -> String {
    format!(
        "no golden {}; run with --bless to create it",
        path.display()
    )
}

fn bless_case(config: &Config, name: &str, render: &cases::Render) -> Result<CaseResult> {
    let depth = Depth::of_hits(&render.hits, config.width, config.height);
    // A NaN distance is neither a hit nor a miss: blessed, it would fail every later compare of
    // the same render, so the tracer's fault is named here instead.
    let nan = depth.z.iter().filter(|z| z.is_nan()).count();
    if nan > 0 {
        return Err(Error::param(
            "bless",
            format!("{name}: {nan} pixels have a NaN hit distance; not blessed"),
        ));
    }
    let dir = &config.golden_dir;
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let png = golden_png(dir, name);
    write_png(&png, &render.image)?;
    let exr = golden_depth(dir, name);
    golden::write_depth(&exr, &depth)?;
    Ok(CaseResult {
        name: name.into(),
        image: Check::Blessed,
        depth: Check::Blessed,
        written: vec![png, exr],
    })
}

fn compare_case(config: &Config, name: &str, render: &cases::Render) -> Result<CaseResult> {
    let tol = &config.tolerance;
    let png = golden_png(&config.golden_dir, name);
    let (image, flip_map) = match golden::read_png(&png) {
        Ok(Some(golden)) => {
            match compare::compare_images(&golden, &Rgb8::from_linear(&render.image), tol) {
                Ok((score, map)) => (
                    Check::Compared {
                        score,
                        pass: score.passes(tol),
                    },
                    Some((golden, map)),
                ),
                Err(e) => (Check::Unusable(format!("{}: {e}", png.display())), None),
            }
        }
        Ok(None) => (Check::Unusable(missing(&png)), None),
        Err(e) => (Check::Unusable(e.to_string()), None),
    };
    let exr = golden_depth(&config.golden_dir, name);
    let rendered = Depth::of_hits(&render.hits, config.width, config.height);
    let (depth, depth_map) = match golden::read_depth(&exr) {
        Ok(Some(golden)) => match compare::compare_depth(&golden, &rendered, tol) {
            Ok((score, map)) => {
                let pass = score.passes(tol);
                (Check::Compared { score, pass }, (!pass).then_some(map))
            }
            Err(e) => (Check::Unusable(format!("{}: {e}", exr.display())), None),
        },
        Ok(None) => (Check::Unusable(missing(&exr)), None),
        Err(e) => (Check::Unusable(e.to_string()), None),
    };
    let mut result = CaseResult {
        name: name.into(),
        image,
        depth,
        written: Vec::new(),
    };
    // An earlier run's pictures of this case would sit beside this run's as if they were its.
    let out = &config.out_dir;
    for suffix in PICTURES {
        let path = out.join(format!("{name}_{suffix}.png"));
        match std::fs::remove_file(&path) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => return Err(Error::io(&path, e)),
            _ => {}
        }
    }
    if !result.passed() {
        std::fs::create_dir_all(out).map_err(|e| Error::io(out, e))?;
        let mut write = |suffix: &str, picture: &crate::output::Image| -> Result<()> {
            let path = out.join(format!("{name}_{suffix}.png"));
            write_png(&path, picture)?;
            result.written.push(path);
            Ok(())
        };
        write("render", &render.image)?;
        if let Some((golden, map)) = flip_map {
            let diff = map.picture()?;
            write("diff", &diff)?;
            // Golden, render and the FLIP error (0 to 1 on its colour bar), side by side.
            let diff = crate::output::with_colour_bar(&diff, 1);
            let pictures = [&golden.to_linear(), &render.image, &diff];
            write("compare", &crate::output::side_by_side(&pictures, 4)?)?;
        }
        if let Some(map) = depth_map {
            write("depth_diff", &map.picture()?)?;
        }
    }
    Ok(result)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::Hit;
    use crate::output::Image;

    /// A render with a NaN distance is not blessed (every later compare of it would fail) and
    /// writes nothing.
    #[test]
    fn a_nan_distance_is_not_blessed() {
        let dir = tempfile::tempdir().unwrap();
        let golden = dir.path().join("golden");
        let config = Config {
            width: 2,
            height: 1,
            mode: Mode::Bless,
            ..Config::new(&golden, dir.path().join("out"))
        };
        let hit = |t| Hit {
            t,
            id: 7,
            ..Hit::MISS
        };
        let render = cases::Render {
            image: Image {
                width: 2,
                height: 1,
                pixels: vec![glam::Vec3::ZERO; 2],
            },
            hits: vec![hit(1.0), hit(f32::NAN)],
        };
        let e = bless_case(&config, "x_exact", &render)
            .unwrap_err()
            .to_string();
        assert!(e.contains("x_exact") && e.contains("NaN"), "{e}");
        assert!(!golden.exists());
        let render = cases::Render {
            hits: vec![hit(1.0), Hit::MISS],
            ..render
        };
        bless_case(&config, "x_exact", &render).unwrap();
        assert!(golden.join("x_exact.png").exists());
    }
}
