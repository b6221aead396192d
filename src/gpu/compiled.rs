//! A compute pipeline as the driver compiled it: its name (the shader and the variant) and what
//! the driver turned it into (registers, spills, code size, scratch, waves per SIMD). On a GPU the
//! registers decide how many rays run at once, which no per-ray counter shows. Every pipeline the
//! library makes is described so by [`super::compile_every_pipeline`].

use serde::Serialize;

use super::{ComputePipeline, Reach, ShaderStatistic};

/// One pipeline the library makes, as the driver compiled it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CompiledPipeline {
    /// Its name: the shader and the variant (`trace_rbvh height jumps`, `trace_exact counting
    /// device-addresses`).
    pub pipeline: String,
    /// The shader (`glsl/<shader>.comp`, or its `_bda` twin).
    pub shader: &'static str,
    /// `"bindings"` or `"device_addresses"`: how the structure's arrays reach the shader.
    pub reach: &'static str,
    /// The specialization constants set, by their GLSL names, as 0 or 1 (JSON: an object).
    #[serde(serialize_with = "as_map")]
    pub specialization: Vec<(&'static str, u32)>,
    /// Whether a tracer uses this variant by default on this device for the structure it suits
    /// (block jumps off on CPU devices, on elsewhere; not counting; each texel format for RBVHs
    /// built with it): the ones whose speed the bench times.
    pub default_variant: bool,
    /// In the driver's order and words; empty where the device does not report them.
    pub statistics: Vec<ShaderStatistic>,
}

/// `(name, value)` pairs as a JSON object, which reads better than a list of pairs.
fn as_map<S: serde::Serializer>(
    pairs: &[(&'static str, u32)],
    serializer: S,
) -> std::result::Result<S::Ok, S::Error> {
    serializer.collect_map(pairs.iter().map(|(k, v)| (k, v)))
}

/// `shader` followed by the constants set (by their meaning, not their ids) and the reach:
/// `trace_rbvh jumps height device-addresses`.
pub(crate) fn variant_name(shader: &str, constants: &[(&str, u32, u32)], reach: Reach) -> String {
    let mut name = shader.to_string();
    for &(constant, _, value) in constants {
        let word = match (constant, value) {
            ("rbvh_count", 1) => "counting",
            ("rbvh_block_jumps", 1) => "jumps",
            ("rbvh_block_jumps", _) => "no-jumps",
            ("rbvh_height_only", 1) => "height",
            ("rbvh_height_only", _) => "height-normal",
            _ => continue,
        };
        name = format!("{name} {word}");
    }
    if reach == Reach::DeviceAddresses {
        name += " device-addresses";
    }
    name
}

impl CompiledPipeline {
    /// `pipeline`, made from `shader` reaching its arrays by `reach` with `constants` (GLSL
    /// name, id, value), described.
    pub(crate) fn of(
        pipeline: &ComputePipeline,
        shader: &'static str,
        reach: Reach,
        constants: &[(&'static str, u32, u32)],
        default_variant: bool,
    ) -> CompiledPipeline {
        CompiledPipeline {
            pipeline: pipeline.name().to_string(),
            shader,
            reach: match reach {
                Reach::Bindings => "bindings",
                Reach::DeviceAddresses => "device_addresses",
            },
            specialization: constants.iter().map(|&(n, _, v)| (n, v)).collect(),
            default_variant,
            statistics: pipeline.statistics().to_vec(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn variant_names_say_what_is_set() {
        assert_eq!(
            variant_name(
                "trace_rbvh",
                &[
                    ("rbvh_count", 0, 0),
                    ("rbvh_block_jumps", 1, 1),
                    ("rbvh_height_only", 2, 1)
                ],
                Reach::DeviceAddresses
            ),
            "trace_rbvh jumps height device-addresses"
        );
        assert_eq!(
            variant_name("trace_exact", &[("rbvh_count", 0, 1)], Reach::Bindings),
            "trace_exact counting"
        );
    }
}
