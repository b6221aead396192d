//! Every compute pipeline the library makes, compiled and never run: the trace shaders of each
//! structure and the painter, in every variant a tracer may choose. RADV's null device
//! ([`super::DeviceLimits::compile_only`]) reports their registers for AMD GPUs on a machine
//! without one (`rbvh shaders --amd navi21`).

use super::compiled::{variant_name, CompiledPipeline};
use super::tracer::{make_pipeline, shader_name, shader_spirv, specialization};
use super::{bindings, painter, ComputePipeline, Context, PaintParams, Reach};
use crate::rbvh::TexelFormat;
use crate::structure::Kind;
use crate::Result;

/// Compiles every pipeline the library has on `ctx`'s device — the trace shaders of the five
/// structures (both texel formats of the RBVH, flat and in two levels, block jumps on and off,
/// timed and counting), the
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
        for kind in Kind::ALL {
            let texel_formats: &[TexelFormat] = if matches!(kind, Kind::Rbvh | Kind::RbvhInstanced)
            {
                &[TexelFormat::HeightNormal, TexelFormat::Height]
            } else {
                &[TexelFormat::HeightNormal]
            };
            let jump_choices: &[bool] = if kind.is_exact() {
                &[false]
            } else {
                &[default_jumps, !default_jumps]
            };
            for &texels in texel_formats {
                for &jumps in jump_choices {
                    let default = kind.is_exact() || jumps == default_jumps;
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
        let name = variant_name("paint", &[], reach);
        let push = std::mem::size_of::<PaintParams>() as u32;
        let paint = painter::shader_spirv(reach);
        let pipeline = ComputePipeline::new(ctx, &name, paint, bindings::paint(reach), push)?;
        compiled.push(CompiledPipeline::of(&pipeline, "paint", reach, &[], true));
    }
    Ok(compiled)
}
