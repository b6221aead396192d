//! The command line's flags: which were given (as opposed to left at their defaults), their
//! names, the groups that say how a structure is built, and the library's errors reworded to
//! name the flag that set the parameter.

/// The flags given on the command line, by their clap ids, as opposed to those left at their
/// defaults: what the refusals of flags that would have no effect look at, since a default
/// value cannot tell whether the user asked for it.
#[derive(Clone, Debug, Default)]
pub struct Given(Vec<String>);

impl Given {
    /// The flags given in `matches` (a subcommand's).
    pub fn of(matches: &clap::ArgMatches) -> Given {
        Given(
            matches
                .ids()
                .filter(|id| {
                    matches.value_source(id.as_str())
                        == Some(clap::parser::ValueSource::CommandLine)
                })
                .map(|id| id.as_str().to_string())
                .collect(),
        )
    }

    /// Whether the flag with clap id `id` (its field's name) was given.
    pub fn has(&self, id: &str) -> bool {
        self.0.iter().any(|given| given == id)
    }

    /// The first of `ids` that was given, as its flag (`--texels-per-diagonal`).
    pub fn first(&self, ids: &[&str]) -> Option<String> {
        ids.iter().find(|id| self.has(id)).map(|id| flag(id))
    }
}

/// The long flag of clap id `id`: `--` and the field's name in kebab case.
pub fn flag(id: &str) -> String {
    format!("--{}", id.replace('_', "-"))
}

/// The clap ids of the flags that say how an RBVH is built ([`crate::quality::Quality`]).
pub const BUILD_FLAGS: [&str; 16] = [
    "quality",
    "texels_per_diagonal",
    "object_rate",
    "max_angle",
    "min_area_ratio",
    "split",
    "no_object_split",
    "max_tile",
    "min_leaf_texels",
    "sampled_criterion_texels",
    "exact_from_texels",
    "exact_edge_fraction",
    "exact_crease",
    "sample_all",
    "view",
    "texels",
];

/// The clap ids of the flags that say how levels of detail are built and chosen
/// ([`crate::prepare::LodBuildArgs`]).
pub const LOD_FLAGS: [&str; 3] = ["lod_columns", "lod_min_leaves", "lod_bias"];

/// The library's error about a parameter, reworded to name the command-line flag that set it
/// (the library names its fields: `texels_per_diagonal`, `lod columns`, `flip_mean`, ...); any
/// other error as it is.
pub fn flag_error(e: rbvh::Error) -> anyhow::Error {
    const FLAGS: [(&str, &str); 24] = [
        ("texels_per_diagonal", "--texels-per-diagonal"),
        ("object_rate", "--object-rate"),
        ("max_angle_deg", "--max-angle"),
        ("min_ratio", "--min-area-ratio"),
        ("max_tile", "--max-tile"),
        ("min_leaf_texels", "--min-leaf-texels"),
        ("sampled_criterion_texels", "--sampled-criterion-texels"),
        ("exact_from_texels", "--exact-from-texels"),
        ("exact_edge_fraction", "--exact-edge-fraction"),
        ("exact_crease_deg", "--exact-crease"),
        ("view_rate", "--view"),
        ("lod columns", "--lod-columns"),
        ("lod min leaves", "--lod-min-leaves"),
        ("lod bias", "--lod-bias"),
        ("lod", "--method rbvh-lod"),
        ("width", "--width"),
        ("height", "--height"),
        ("runs", "--runs"),
        ("min_run_ms", "--min-run-ms"),
        ("ao_radius", "--ao-radius"),
        ("flip_mean", "--max-flip-mean"),
        ("outlier_fraction", "--max-outliers"),
        ("depth_relative", "--depth-tolerance"),
        ("depth_outlier_fraction", "--max-depth-off"),
    ];
    if let rbvh::Error::InvalidParameter { name, message } = &e {
        if let Some((_, flag)) = FLAGS.iter().find(|(field, _)| field == name) {
            return anyhow::anyhow!("{flag}: {message}");
        }
    }
    e.into()
}
