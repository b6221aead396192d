//! What quality: the paper's user parameters — a global sampling rate and a local refinement
//! criterion — plus the where-to-split strategy and the practical limits, in one struct with
//! `const` presets `Q0`…`Q4` (coarsest to finest).

use crate::{Error, Result};

/// Whether a set of surfaces may become one height field (Novák & Dachsbacher 2012, "refinement
/// criteria"). Whichever is chosen, the rasterization must also come out single-valued.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Refinement {
    /// Cone of normals: every triangle normal within `max_angle_deg` of the projection axis.
    /// Good for smooth (subdivision) surfaces.
    NormalCone {
        /// Largest angle between a triangle normal and the axis, degrees, in (0, 90).
        max_angle_deg: f32,
    },
    /// Projected surface area: `A⊥ / A ≥ min_ratio`, with `A⊥ = Σ Aᵢ (nᵢ · w)` the area seen along
    /// the projection axis `w`. Good for scanned, noisy surfaces.
    ProjectedArea {
        /// Smallest accepted `A⊥ / A`, in (0, 1]; 1 admits only surfaces facing the axis squarely.
        min_ratio: f32,
    },
}

/// Where to split a set that cannot be one height field. The splits decide the leaves; the tree a
/// ray traverses over them may be built again by the SAH where that is cheaper (`build/flatten.rs`,
/// `upper_tree`), so a strategy is measured by the leaves it makes as much as by its tree.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Subdivision {
    /// The middle of the longest axis of the node's box: fast to build and, per the paper's
    /// measurements, nearly as fast to trace as the SAH variant.
    SpatialMedian,
    /// The paper's modified SAH: child cost = box-area probability × *surface area* of the child's
    /// triangles, 32 candidates per axis.
    AreaSah,
}

/// What each atlas texel holds (issue "The paper's scale", item 5: model only what the scene
/// requires).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum TexelFormat {
    /// The height code and the sample's 8:8 octahedral normal; the device keeps a normal for each
    /// texel that is not a hole alone ([`crate::rbvh::Atlas::device_words`]). A hit reports the
    /// normal of the sample nearest it (the paper's texels).
    #[default]
    HeightNormal,
    /// The height code alone, 8, 10, 12 or 16 bits by tile: about half the bytes a texel. A hit
    /// reports the normal of the cell triangle it hit (a facet normal, exact for the height field
    /// as sampled), so shading shows the facets; for visibility (AO, shadows) the hits are the
    /// same as with normals where every triangle is sampled (`exact_when_cheaper` prices a texel
    /// at its bytes, so a height-only preset samples triangles the normals preset traces
    /// exactly: its atlas may not shrink, and its hits differ there). Carries no
    /// colour channel, and levels of detail (whose columns take their normals from the texels)
    /// are not built for it.
    Height,
}

impl TexelFormat {
    /// Bytes of one texel of 16-bit height with its normal, if any, as the host and the file keep
    /// it, and as the builder prices a texel against exact triangles (`build/exact.rs`; the
    /// device keeps fewer: [`crate::rbvh::Atlas::device_words`]).
    pub fn bytes(self) -> u64 {
        match self {
            TexelFormat::HeightNormal => 4,
            TexelFormat::Height => 2,
        }
    }

    /// What a level's name gets appended for this format: nothing, or `h` for height-only
    /// (`Q2h`), so that both formats of one level tell apart in tables, charts and file names.
    pub fn level_suffix(self) -> &'static str {
        match self {
            TexelFormat::HeightNormal => "",
            TexelFormat::Height => "h",
        }
    }

    /// `"height_normal"` or `"height"`, as the bench records and the CLI name it.
    pub fn name(self) -> &'static str {
        match self {
            TexelFormat::HeightNormal => "height_normal",
            TexelFormat::Height => "height",
        }
    }
}

/// All build parameters of an RBVH.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RbvhParams {
    /// Global sampling rate, in texels along the scene's bounding-box diagonal (so that presets
    /// mean the same on any scale).
    pub texels_per_diagonal: f32,
    /// Each object's least sampling rate, as a fraction of `texels_per_diagonal` taken along the
    /// diagonal of the object's own box, in [0, 1] (0: none). A texel is the finer of the
    /// scene's and the object's, but never finer than the object's mean triangle, so that an
    /// object small beside the scene (a dragon in a courtyard) is sampled for its own features
    /// instead of at a rate its surroundings set (issue "Small and valid at every scale"), and
    /// none gets more texels than it has triangles. An object is a scene object
    /// ([`crate::scene::Scene::object_names`]); a point cloud is one. A fraction rather than a
    /// rate of its own, so that a preset with another `texels_per_diagonal` scales both.
    pub object_rate: f32,
    /// Local criterion for accepting a set of triangles as one height field.
    pub refinement: Refinement,
    /// Where a set that fails `refinement` is split.
    pub subdivision: Subdivision,
    /// Object split: separate connected parts (and scene objects) are never fused into one height
    /// field; a node holding several is split between them first.
    pub object_split: bool,
    /// Most samples along one side of a tile: larger height fields are subdivided so that one
    /// march stays short.
    pub max_tile: u32,
    /// A set that cannot be one height field and whose box diagonal spans fewer texels than this
    /// stays as triangles (hybrid leaf), traced exactly.
    pub min_leaf_texels: f32,
    /// A set whose box diagonal spans at most this many texels, and whose triangles fail
    /// `refinement`, is judged again on its surface *as sampled*: the cells of its rasterized
    /// tile must pass the same criterion (see `raster/judge.rs`). Detail below the sampling rate cannot
    /// be represented anyway, and on a scanned mesh its noise fails the criterion at every size,
    /// so the paper's rule (0: triangles only) cuts a small or distant scan into leaves of a few
    /// texels each, a 64-byte record and a node apiece (issue "The paper's scale", item 6).
    pub sampled_criterion_texels: f32,
    /// What each texel holds: height and normal (the default), or height alone.
    pub texels: TexelFormat,
    /// Triangles are traced exactly where that costs fewer bytes than sampling them: a triangle
    /// covering more texels than its 96 bytes buy, and a set whose tiles (texels, leaf records,
    /// nodes, exact parts) cost more than its triangles would (`build/exact.rs`). Such triangles have
    /// no detail between their corners for texels to sample (walls, floors, a cube's faces, a
    /// mesh coarser than the sampling rate), and a height field of them widens their silhouettes
    /// by its rim. On in the presets (a texel exists because the scene needs it); off (RBVH
    /// files before version 9, `rbvh --sample-all`): every triangle is sampled wherever a height
    /// field can hold it, as the paper does. A point cloud has no triangles: the rule does
    /// nothing there.
    pub exact_when_cheaper: bool,
    /// With `exact_when_cheaper`, the size in texels of its object from which a triangle is
    /// traced exactly; 0 (the presets): what its 96 bytes buy, 24 texels with normals, 48
    /// height-only. A triangle of a few texels costs about its bytes either way, but sampled its
    /// silhouette widens by the rim: on the paper-scale scene tracing every triangle of 1.5
    /// texels or more exactly made Q2 valid in the same bytes (docs/paper-scale.md, "What Q0–Q2
    /// validity would take"). Not the presets' rule: at finer levels the texel shrinks towards a
    /// scan's triangles, and 1.5 texels made the dragon's Q4 30.5 MB instead of 8.5 (ibid.,
    /// "What the view asks of Q0").
    pub exact_from_texels: f32,
    /// With `exact_when_cheaper`, the fraction of its object's box diagonal from which a
    /// triangle's longest edge makes it traced exactly; 0 (the presets): none. A triangle that
    /// long is a shape the mesh states at its own scale (architecture's slivers, mouldings and
    /// arches, a low-poly model) rather than detail below the texel (a scan's): sampled, its
    /// creases and silhouettes are rounded by a texel, which near the camera is many pixels. On
    /// the paper-scale scene, 1/128 with `object_rate` 1 makes Q0 valid (t p99 0.23% of the
    /// diagonal, 46.5 MB), while on the default scene it traces a third of its triangles exactly
    /// and every level takes 4.2 MB, against the presets' 0.36–2.5 (docs/paper-scale.md, "What
    /// the view asks of Q0"). Unlike `exact_from_texels`, a
    /// fraction of the object rather than texels, so that finer levels do not send a scan's
    /// triangles exact as their texel shrinks towards them.
    pub exact_edge_fraction: f32,
    /// With `exact_when_cheaper`, the angle in degrees from which a triangle that meets a
    /// neighbour at a crease, and spans [`crate::rbvh::CREASE_EDGE_TEXELS`] texels of its
    /// object, is traced exactly; 0: none; the presets: 30. Without `exact_when_cheaper` every
    /// triangle is sampled and the angle does nothing, so that a preset's sampled twin (`Q2s`)
    /// differs from it in that flag alone. A crease is an edge the mesh states (a moulding's
    /// step, a column's corner, a cube's edge) and a height field rounds by a texel, which near
    /// the camera is many pixels; smooth tessellations and sub-texel scans keep their texels. On
    /// the paper-scale scene 30° made Q2 valid (t p99 7.43 → 0.81% of the diagonal, 40.2 → 41.5
    /// MB) and on the default scene Q0 2.5 times as accurate for 0.06 MB (docs/paper-scale.md, "What
    /// the view asks of Q0").
    pub exact_crease_deg: f32,
    /// Texels across the view's vertical field of view at a triangle's distance: where the
    /// scene's camera ([`crate::scene::Scene::camera`]) sees a triangle, its texel is at most
    /// that distance × 2·tan(vfov / 2) over this rate, however coarse its object's
    /// (`build/view.rs`); 0 (the presets): none, and a scene without a camera is sampled as
    /// without. A connected part whose triangles then ask texels more than twice apart is split
    /// rather than sampled at its finest throughout. What decides validity at the paper's scale
    /// is the texel against the view, which no rule on the geometry can see: Sponza's courtyard
    /// at 16 cm a texel is 12 pixels at the arcade five metres from the camera
    /// (docs/paper-scale.md, "Levels refined for the view"). [`VIEW_RATE`] is the rate measured
    /// to make every preset valid there. Triangles only: a point cloud's texel is its own. A
    /// level so built is named with [`VIEWED_SUFFIX`] (`Q0v`).
    pub view_rate: f32,
}

/// What a level's name gets appended when its texels are refined for the scene's view
/// ([`RbvhParams::view_rate`] above 0): `Q0v`, so that it tells apart from the preset.
pub const VIEWED_SUFFIX: &str = "v";

/// The [`RbvhParams::view_rate`] that `rbvh --view` asks for: 384 texels across the view's
/// field (a texel at most a pixel of a 384-pixel-high image at its distance, on the view's
/// axis; off it a pixel spans less, down to about 1/1.75 of that in the corners of a 4:3 image
/// of a 55° field). On the paper-scale scene and its scattered arrangement, every preset
/// refined at this rate is valid for primary rays, where 256 left the scattered arrangement's
/// Q0 just invalid (t p99 1.24% of the diagonal) and 128 the paper-scale scene's (10.3%). The
/// presets do not take it: a view as close as the dragon close-up's asks the same texels of Q0
/// to Q2, which it samples finer than they did and which were valid without
/// (docs/paper-scale.md, "Levels refined for the view").
pub const VIEW_RATE: f32 = 384.0;

/// What a level's name gets appended when every triangle a height field can hold is sampled
/// (`exact_when_cheaper` off, the paper's rule): `Q2s`, so that it tells apart from the preset
/// in tables, charts and file names.
pub const SAMPLED_SUFFIX: &str = "s";

/// A level's name, the one rule the CLI, the bench's records and the README's tables name levels
/// by: its quality (`Q2`, `custom`), then [`TexelFormat::level_suffix`] for height-only texels,
/// then [`SAMPLED_SUFFIX`] where every triangle is sampled, then [`VIEWED_SUFFIX`] where its
/// texels are refined for the view: `Q2`, `Q2h`, `Q2s`, `Q2hs`, `Q2v`.
pub fn level_name(quality: &str, height_only: bool, sampled: bool, viewed: bool) -> String {
    let texels = if height_only {
        TexelFormat::Height
    } else {
        TexelFormat::HeightNormal
    };
    let sampled = if sampled { SAMPLED_SUFFIX } else { "" };
    let viewed = if viewed { VIEWED_SUFFIX } else { "" };
    format!("{quality}{}{sampled}{viewed}", texels.level_suffix())
}

/// Quality preset names, coarsest to finest.
pub const QUALITY_NAMES: [&str; 5] = ["Q0", "Q1", "Q2", "Q3", "Q4"];

/// The presets' sampling rates, `256 · √2^level` correctly rounded to f32. A table rather than
/// `powi`: the compiler folds `powi` at compile time where the level is a constant and rounds
/// differently from the same call at run time (724.07733 against 724.0773 for Q3, 512 against
/// 511.99997 for Q2), so one preset built two ways was two RBVHs.
const PRESET_RATES: [f32; QUALITY_NAMES.len()] = [256.0, 362.038_67, 512.0, 724.077_33, 1024.0];

/// The presets' [`RbvhParams::object_rate`]: 3/16 (48 texels along an object's diagonal at Q0,
/// 192 at Q4), so that an object smaller than 3/16 of the scene's diagonal is sampled for its
/// own size and a larger one as before. The default scene's smallest objects are a fifth of its
/// diagonal: its RBVHs are as without. On the paper-scale scene (25 dragons, each about a
/// fourteenth of the courtyard's diagonal) the dragons get 2.6 times finer texels than the
/// scene's, and with the crest rule (`raster::CREST_TEXELS`) Q2 takes 47 MB instead of 144
/// (docs/guarantees.md). The scene's own rate for every object would make the default scene's
/// Q0 5.5 times larger (0.48 → 2.66 MB) for accuracy it did not need (its FLIP 0.008 already).
const PRESET_OBJECT_RATE: f32 = 0.1875;

/// The presets' [`RbvhParams::exact_crease_deg`]: 30°, which on the paper-scale scene made Q2
/// valid (t p99 7.43 → 0.81% of the diagonal) for 3% more bytes, the default scene's Q0 2.5
/// times as accurate (t p99 0.124 → 0.049%) for 0.06 MB, and the dragon's Q4 1.4% larger for the
/// same accuracy (docs/paper-scale.md, "What the view asks of Q0").
const PRESET_CREASE_DEG: f32 = 30.0;

impl RbvhParams {
    /// Preset `level` (0 = Q0, coarsest … 4 = Q4, finest). Each level has √2× the sampling rate of
    /// the previous one, so about twice its texels.
    pub fn quality(level: u32) -> Result<RbvhParams> {
        let rate = PRESET_RATES.get(level as usize).ok_or_else(|| {
            Error::param(
                "quality",
                format!("{level} is not a preset; use 0..=4 (Q0 coarsest … Q4 finest)"),
            )
        })?;
        Ok(Self::preset_at(*rate))
    }

    /// Every preset, Q0 to Q4.
    pub fn presets() -> Vec<RbvhParams> {
        PRESET_RATES
            .iter()
            .map(|&rate| Self::preset_at(rate))
            .collect()
    }

    /// The presets' parameters at sampling rate `rate`.
    fn preset_at(rate: f32) -> RbvhParams {
        RbvhParams {
            texels_per_diagonal: rate,
            object_rate: PRESET_OBJECT_RATE,
            refinement: Refinement::NormalCone {
                max_angle_deg: 60.0,
            },
            subdivision: Subdivision::SpatialMedian,
            object_split: true,
            max_tile: 64,
            min_leaf_texels: 3.0,
            sampled_criterion_texels: 4.0,
            texels: TexelFormat::HeightNormal,
            exact_when_cheaper: true,
            exact_from_texels: 0.0,
            exact_edge_fraction: 0.0,
            exact_crease_deg: PRESET_CREASE_DEG,
            view_rate: 0.0,
        }
    }

    /// The preset these parameters are, if any: the level whose [`RbvhParams::quality`] they equal
    /// in everything but the texel format, `exact_when_cheaper` and `view_rate` (which every
    /// preset can take or leave).
    pub fn preset(&self) -> Option<u32> {
        let level = Self::presets().iter().position(|p| {
            RbvhParams {
                texels: self.texels,
                exact_when_cheaper: self.exact_when_cheaper,
                view_rate: self.view_rate,
                ..*p
            } == *self
        })?;
        Some(level as u32)
    }

    /// `"Q0"`…`"Q4"` for a preset ([`RbvhParams::preset`]), `"custom"` for any other parameters:
    /// the `quality` of benchmark records, and how the CLI names a level.
    pub fn quality_name(&self) -> &'static str {
        self.preset()
            .map_or("custom", |level| QUALITY_NAMES[level as usize])
    }

    /// This level's [`level_name`]: `Q2`, `Q2h`, `Q2s`, `Q2hs`, `Q2v`, `customh`.
    pub fn level_label(&self) -> String {
        level_name(
            self.quality_name(),
            self.texels == TexelFormat::Height,
            !self.exact_when_cheaper,
            self.view_rate > 0.0,
        )
    }

    /// Checks every parameter's range; the error names the parameter and the allowed range.
    pub fn validate(&self) -> Result<()> {
        let rate = self.texels_per_diagonal;
        if !(rate.is_finite() && (1.0..=1.0e6).contains(&rate)) {
            return Err(Error::param(
                "texels_per_diagonal",
                format!("{rate} is outside 1..=1e6"),
            ));
        }
        match self.refinement {
            Refinement::NormalCone { max_angle_deg: a } if !(a > 0.0 && a < 90.0) => {
                return Err(Error::param(
                    "max_angle_deg",
                    format!("{a} is outside (0, 90) degrees"),
                ))
            }
            Refinement::ProjectedArea { min_ratio: r } if !(r > 0.0 && r <= 1.0) => {
                return Err(Error::param("min_ratio", format!("{r} is outside (0, 1]")))
            }
            _ => {}
        }
        if !(4..=4096).contains(&self.max_tile) {
            return Err(Error::param(
                "max_tile",
                format!("{} is outside 4..=4096", self.max_tile),
            ));
        }
        let m = self.min_leaf_texels;
        if !(m.is_finite() && (0.0..=1.0e4).contains(&m)) {
            return Err(Error::param(
                "min_leaf_texels",
                format!("{m} is outside 0..=1e4"),
            ));
        }
        let o = self.object_rate;
        if !(0.0..=1.0).contains(&o) {
            return Err(Error::param(
                "object_rate",
                format!("{o} is outside 0..=1 (a fraction of texels_per_diagonal)"),
            ));
        }
        let ranges = [
            (
                "sampled_criterion_texels",
                self.sampled_criterion_texels,
                1.0e4,
                "1e4",
                "",
            ),
            (
                "exact_from_texels",
                self.exact_from_texels,
                1.0e4,
                "1e4",
                " (0: what 96 bytes of texels buy)",
            ),
            (
                "exact_edge_fraction",
                self.exact_edge_fraction,
                1.0,
                "1",
                " (a fraction of each object's diagonal; 0: none)",
            ),
            (
                "exact_crease_deg",
                self.exact_crease_deg,
                180.0,
                "180",
                " (degrees between neighbouring normals; 0: none)",
            ),
        ];
        for (name, v, most, shown, hint) in ranges {
            if !(v.is_finite() && (0.0..=most).contains(&v)) {
                return Err(Error::param(
                    name,
                    format!("{v} is outside 0..={shown}{hint}"),
                ));
            }
        }
        let view = self.view_rate;
        if !(view == 0.0 || (view.is_finite() && (1.0..=1.0e6).contains(&view))) {
            return Err(Error::param(
                "view_rate",
                format!(
                    "{view} is neither 0 (none) nor in 1..=1e6 (texels across the view's field)"
                ),
            ));
        }
        // The crease angle is not among these: the presets set it, and their sampled twins
        // (`Q2s`) keep it, doing nothing.
        let needing_exact = [
            ("exact_from_texels", self.exact_from_texels),
            ("exact_edge_fraction", self.exact_edge_fraction),
        ];
        for (name, v) in needing_exact {
            if v > 0.0 && !self.exact_when_cheaper {
                return Err(Error::param(
                    name,
                    format!(
                        "{v} sets which triangles are traced exactly, but exact_when_cheaper is \
                         off (every triangle sampled)"
                    ),
                ));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_double_texels_and_validate() {
        for level in 0..5 {
            let p = RbvhParams::quality(level).unwrap();
            p.validate().unwrap();
            if level > 0 {
                let prev = RbvhParams::quality(level - 1).unwrap();
                let ratio = (p.texels_per_diagonal / prev.texels_per_diagonal).powi(2);
                assert!((ratio - 2.0).abs() < 1e-4);
            }
        }
        assert!(RbvhParams::quality(5).is_err());
    }

    #[test]
    fn out_of_range_parameters_are_errors() {
        let q = RbvhParams::quality(2).unwrap();
        let bad = [
            RbvhParams {
                texels_per_diagonal: 0.0,
                ..q
            },
            RbvhParams {
                texels_per_diagonal: f32::NAN,
                ..q
            },
            RbvhParams {
                refinement: Refinement::NormalCone {
                    max_angle_deg: 90.0,
                },
                ..q
            },
            RbvhParams {
                refinement: Refinement::ProjectedArea { min_ratio: 0.0 },
                ..q
            },
            RbvhParams { max_tile: 2, ..q },
            RbvhParams {
                object_rate: 1.5,
                ..q
            },
            RbvhParams {
                object_rate: -0.1,
                ..q
            },
            RbvhParams {
                object_rate: f32::NAN,
                ..q
            },
            RbvhParams {
                min_leaf_texels: -1.0,
                ..q
            },
            RbvhParams {
                sampled_criterion_texels: f32::INFINITY,
                ..q
            },
            RbvhParams {
                sampled_criterion_texels: -0.5,
                ..q
            },
        ];
        for p in bad {
            assert!(p.validate().is_err(), "{p:?}");
        }
    }

    #[test]
    fn presets_are_named_by_their_parameters() {
        for level in 0..5 {
            let p = RbvhParams::quality(level).unwrap();
            assert_eq!(p.preset(), Some(level));
            assert_eq!(p.quality_name(), QUALITY_NAMES[level as usize]);
            let height = RbvhParams {
                texels: TexelFormat::Height,
                ..p
            };
            assert_eq!(height.level_label(), format!("Q{level}h"));
            assert_eq!(p.level_label(), format!("Q{level}"));
            let sampled = RbvhParams {
                exact_when_cheaper: false,
                ..height
            };
            assert_eq!(sampled.preset(), Some(level));
            assert_eq!(sampled.level_label(), format!("Q{level}hs"));
        }
        let q2 = RbvhParams::quality(2).unwrap();
        let custom = RbvhParams {
            texels_per_diagonal: 2048.0,
            ..q2
        };
        assert_eq!(
            (custom.preset(), custom.level_label().as_str()),
            (None, "custom")
        );
        let no_split = RbvhParams {
            object_split: false,
            ..q2
        };
        assert_eq!(no_split.quality_name(), "custom");
    }

    #[test]
    fn preset_rates_are_256_times_powers_of_root_two_correctly_rounded() {
        for level in 0..5u32 {
            let exact = 256.0 * 2f64.powf(f64::from(level) / 2.0);
            let p = RbvhParams::quality(level).unwrap();
            assert_eq!(p.texels_per_diagonal, exact as f32, "Q{level}");
            assert_eq!(p.object_rate, 0.1875, "Q{level}");
            // A level the compiler cannot see gives the same preset.
            let runtime = std::hint::black_box(level);
            assert_eq!(
                RbvhParams::quality(runtime).unwrap(),
                RbvhParams::quality(level).unwrap()
            );
        }
    }
}
