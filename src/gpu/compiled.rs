//! Every compute pipeline the library makes, compiled and never run: what the driver turns each
//! into (registers, spills, code size, scratch, waves per SIMD). On a GPU the registers decide how
//! many rays run at once, which no per-ray counter shows; RADV's null device
//! ([`super::DeviceLimits::compile_only`]) reports them for AMD GPUs on a machine without one.

use serde::Serialize;

use super::tracer::{make_pipeline, shader_name, shader_spirv, specialization};
use super::{shaders, ComputePipeline, Context, Reach, ShaderStatistic};
use crate::rbvh::TexelFormat;
use crate::structure::Kind;
use crate::Result;

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

/// Compiles every pipeline the library has on `ctx`'s device — the trace shaders of the three
/// structures (both texel formats of the RBVH, block jumps on and off, timed and counting), the
/// painter, each reading its arrays through bindings and, where the context has device addresses,
/// through them — and returns what the driver made of each. Allocates and submits nothing, so it
/// runs on a device that only compiles.
pub fn compile_every_pipeline(ctx: &Context) -> Result<Vec<CompiledPipeline>> {
    let mut reaches = vec![Reach::Bindings];
    if ctx.limits().buffer_device_address {
        reaches.push(Reach::DeviceAddresses);
    }
    let default_jumps = !ctx.limits().cpu;
    let mut compiled = Vec::new();
    for &reach in &reaches {
        for kind in [Kind::Exact, Kind::Rbvh, Kind::RbvhLod] {
            let texel_formats: &[TexelFormat] = if kind == Kind::Rbvh {
                &[TexelFormat::HeightNormal, TexelFormat::Height]
            } else {
                &[TexelFormat::HeightNormal]
            };
            let jump_choices: &[bool] = if kind == Kind::Exact {
                &[false]
            } else {
                &[default_jumps, !default_jumps]
            };
            for &texels in texel_formats {
                for &jumps in jump_choices {
                    let default = kind == Kind::Exact || jumps == default_jumps;
                    // Counting pipelines with the default jumps only, as the bench counts.
                    let countings: &[bool] = if default { &[false, true] } else { &[false] };
                    for &counting in countings {
                        let shader = (kind, texels);
                        let spirv = shader_spirv(kind, reach);
                        let pipeline = make_pipeline(ctx, shader, reach, spirv, jumps, counting)?;
                        compiled.push(CompiledPipeline::of(
                            &pipeline,
                            shader_name(kind),
                            reach,
                            &specialization(shader, jumps, counting),
                            default && !counting,
                        ));
                    }
                }
            }
        }
        let (paint, bindings): (&[u8], &[u32]) = match reach {
            Reach::Bindings => (shaders::PAINT, &[0, 1, 2]),
            Reach::DeviceAddresses => (shaders::PAINT_BDA, &[1]),
        };
        let name = variant_name("paint", &[], reach);
        let push = std::mem::size_of::<super::PaintParams>() as u32;
        let pipeline = ComputePipeline::new(ctx, &name, paint, bindings, push)?;
        compiled.push(CompiledPipeline::of(&pipeline, "paint", reach, &[], true));
    }
    Ok(compiled)
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
