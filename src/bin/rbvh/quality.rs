//! `--quality` and the flags that adjust it: which RBVH levels a command builds (presets, free
//! parameters, `--sample-all`, `--view`, `--texels`), each validated before anything is loaded.

use anyhow::Result;
use clap::{Args, ValueEnum};

use crate::flags::flag_error;

/// RBVH quality: presets, optionally adjusted by free parameters (which make the level "custom").
#[derive(Args, Clone, Debug)]
pub struct Quality {
    /// Quality preset(s): 0..4 or Q0..Q4 (Q0 coarsest, Q4 finest), comma-separated, or `all`.
    #[arg(long, default_value = "2", value_delimiter = ',')]
    pub quality: Vec<String>,
    /// Free parameter: sampling rate in texels along the scene's bounding-box diagonal.
    #[arg(long)]
    pub texels_per_diagonal: Option<f32>,
    /// Free parameter: each object's least sampling rate, as a fraction of
    /// --texels-per-diagonal along its own box diagonal, 0..=1 (a texel is the finer of the
    /// scene's and the object's, no finer than the object's mean triangle; 0: the scene's alone;
    /// presets: 0.1875).
    #[arg(long)]
    pub object_rate: Option<f32>,
    /// Free parameter: cone-of-normals criterion with this maximum angle to the axis (degrees).
    #[arg(long, conflicts_with = "min_area_ratio")]
    pub max_angle: Option<f32>,
    /// Free parameter: projected-area criterion A⊥/A ≥ this ratio.
    #[arg(long)]
    pub min_area_ratio: Option<f32>,
    /// Free parameter: where to split.
    #[arg(long, value_enum)]
    pub split: Option<SplitArg>,
    /// Free parameter: allow fusing separate parts into one height field.
    #[arg(long)]
    pub no_object_split: bool,
    /// Free parameter: most samples per tile side.
    #[arg(long)]
    pub max_tile: Option<u32>,
    /// Free parameter: unrepresentable sets smaller than this many texels stay triangles.
    #[arg(long)]
    pub min_leaf_texels: Option<f32>,
    /// Free parameter: sets of at most this many texels whose triangles fail the criterion are
    /// judged on their surface as sampled (0: triangles only, the paper's rule; presets: 4).
    #[arg(long)]
    pub sampled_criterion_texels: Option<f32>,
    /// Free parameter: trace exactly every triangle covering at least this many texels of its
    /// object (presets: what its 96 bytes buy, 24 texels, 48 height-only). Lower values narrow
    /// silhouettes that sampling would widen (1.5 made Q2 valid at the paper's scale in the
    /// same bytes); not with --sample-all.
    #[arg(long, conflicts_with = "sample_all")]
    pub exact_from_texels: Option<f32>,
    /// Free parameter: trace exactly every triangle whose longest edge is at least this fraction
    /// of its object's diagonal (presets: 0, none): shapes a mesh states at its own scale, such
    /// as architecture, whose creases and silhouettes sampling would round by a texel (with
    /// --object-rate 1, 0.0078125 made Q0 valid at the paper's scale); not with --sample-all.
    #[arg(long, conflicts_with = "sample_all")]
    pub exact_edge_fraction: Option<f32>,
    /// Free parameter: trace exactly every triangle that meets a neighbour at a crease of at
    /// least this many degrees and spans 2 texels of its object (presets: 30; 0: none): edges
    /// the mesh states, which sampling would round by a texel; not with --sample-all.
    #[arg(
        long = "exact-crease",
        id = "exact_crease",
        value_name = "DEGREES",
        conflicts_with = "sample_all"
    )]
    pub exact_crease_deg: Option<f32>,
    /// Sample every triangle a height field can hold, as the paper does, at every level asked
    /// for; such a level is named with an `s`, e.g. Q2s. Presets trace triangles exactly where
    /// that costs fewer bytes than sampling them (a triangle covering at least 24 texels, 48
    /// height-only, and a set whose tiles would cost more than its triangles) and on a crease
    /// of 30° or more spanning 2 texels.
    #[arg(long)]
    pub sample_all: bool,
    /// Refine every level asked for where the scene's camera looks closely: a triangle it sees
    /// gets a texel at most its distance's share of the field of view over RATE (texels across
    /// the vertical field; without a value 384, a pixel of a 384-pixel-high image on the view's
    /// axis), however coarse its object's; such a level is named with a `v`, e.g. Q0v. With it
    /// every preset is valid for primary rays at the paper's scale, seen from the camera it was
    /// built for. Needs a camera (the scene's, or the one the command's camera flags give); not
    /// with --points, a point cloud, or a scene held in two levels.
    #[arg(long, value_name = "RATE", num_args = 0..=1, default_missing_value = "384")]
    pub view: Option<f32>,
    /// What each atlas texel holds: `normals` (height and normal: 8-, 10-, 12- or 16-bit
    /// heights by tile, and a 16-bit normal where the texel is not a hole) or `height` (height alone, 1 to 2 bytes: facet normals, no colours, no
    /// levels of detail); comma-separate both to build each level in each (a height-only level is
    /// named with an `h`, e.g. Q2h).
    #[arg(long, value_enum, value_delimiter = ',', default_value = "normals")]
    pub texels: Vec<TexelsArg>,
}

/// The presets `--quality` names (0..4, Q0..Q4, or `all`), in the order given: the one parser of
/// every command's `--quality`.
pub fn presets(quality: &[String]) -> Result<Vec<u32>> {
    let mut levels = Vec::new();
    for q in quality {
        let q = q.trim();
        if q.eq_ignore_ascii_case("all") {
            levels.extend(0..5);
            continue;
        }
        let digits = q.strip_prefix(['Q', 'q']).unwrap_or(q);
        let level: u32 = digits.parse().ok().filter(|l| *l <= 4).ok_or_else(|| {
            anyhow::anyhow!("--quality {q:?} is not a preset: use 0..4, Q0..Q4 or all")
        })?;
        levels.push(level);
    }
    anyhow::ensure!(!levels.is_empty(), "--quality names no level");
    // A level named twice (`--quality 2,2`, `all,2`) is built and measured once, as a texel
    // format named twice is.
    let mut seen = [false; 5];
    levels.retain(|&l| !std::mem::replace(&mut seen[l as usize], true));
    Ok(levels)
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum TexelsArg {
    /// Height and normal per texel (the paper's texels).
    Normals,
    /// Height alone: half the atlas; hits report the normal of the cell triangle hit.
    Height,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum SplitArg {
    /// Middle of the longest axis.
    Median,
    /// The paper's modified (surface-area weighted) SAH.
    Sah,
}

impl Quality {
    fn is_custom(&self) -> bool {
        self.texels_per_diagonal.is_some()
            || self.object_rate.is_some()
            || self.max_angle.is_some()
            || self.min_area_ratio.is_some()
            || self.split.is_some()
            || self.no_object_split
            || self.max_tile.is_some()
            || self.min_leaf_texels.is_some()
            || self.sampled_criterion_texels.is_some()
            || self.exact_from_texels.is_some()
            || self.exact_edge_fraction.is_some()
            || self.exact_crease_deg.is_some()
    }

    /// The texel formats asked for, each once, in the order given.
    pub fn texel_formats(&self) -> Vec<rbvh::rbvh::TexelFormat> {
        use rbvh::rbvh::TexelFormat;
        let mut formats = Vec::new();
        for t in &self.texels {
            let f = match t {
                TexelsArg::Normals => TexelFormat::HeightNormal,
                TexelsArg::Height => TexelFormat::Height,
            };
            if !formats.contains(&f) {
                formats.push(f);
            }
        }
        formats
    }

    /// Every requested level in every requested texel format (each named by
    /// `RbvhParams::level_label`: `Q2`, `Q2h`, `Q2s`, `Q2v`, `custom`).
    pub fn levels(&self) -> Result<Vec<rbvh::rbvh::RbvhParams>> {
        let formats = self.texel_formats();
        Ok(self
            .quality_levels()?
            .into_iter()
            .flat_map(|params| {
                formats
                    .iter()
                    .map(move |&texels| rbvh::rbvh::RbvhParams { texels, ..params })
            })
            .collect())
    }

    /// The requested levels (presets, or one preset changed by free parameters), each
    /// validated, with the default texels (see [`Quality::levels`] for the formats), their
    /// triangles all sampled if asked.
    pub fn quality_levels(&self) -> Result<Vec<rbvh::rbvh::RbvhParams>> {
        use rbvh::rbvh::{RbvhParams, Refinement, Subdivision};
        let levels = presets(&self.quality)?;
        anyhow::ensure!(
            !self.is_custom() || levels.len() == 1,
            "free parameters adjust one preset: give a single --quality with them"
        );
        levels
            .into_iter()
            .map(|level| {
                let mut p = RbvhParams::quality(level)?;
                p.exact_when_cheaper = !self.sample_all;
                if let Some(rate) = self.view {
                    anyhow::ensure!(
                        rate != 0.0,
                        "--view 0 refines nothing: give a rate of at least 1, or leave --view out"
                    );
                    p.view_rate = rate;
                }
                if let Some(r) = self.texels_per_diagonal {
                    p.texels_per_diagonal = r;
                }
                if let Some(r) = self.object_rate {
                    p.object_rate = r;
                }
                if let Some(a) = self.max_angle {
                    p.refinement = Refinement::NormalCone { max_angle_deg: a };
                }
                if let Some(r) = self.min_area_ratio {
                    p.refinement = Refinement::ProjectedArea { min_ratio: r };
                }
                if let Some(s) = self.split {
                    p.subdivision = match s {
                        SplitArg::Median => Subdivision::SpatialMedian,
                        SplitArg::Sah => Subdivision::AreaSah,
                    };
                }
                if self.no_object_split {
                    p.object_split = false;
                }
                if let Some(m) = self.max_tile {
                    p.max_tile = m;
                }
                if let Some(m) = self.min_leaf_texels {
                    p.min_leaf_texels = m;
                }
                if let Some(k) = self.sampled_criterion_texels {
                    p.sampled_criterion_texels = k;
                }
                if let Some(e) = self.exact_from_texels {
                    p.exact_from_texels = e;
                }
                if let Some(f) = self.exact_edge_fraction {
                    p.exact_edge_fraction = f;
                }
                if let Some(c) = self.exact_crease_deg {
                    p.exact_crease_deg = c;
                }
                p.validate().map_err(flag_error)?;
                Ok(p)
            })
            .collect()
    }
}
