//! Vulkan compute: a headless context (or an engine's own device), buffers through
//! `gpu-allocator`, compute pipelines whose workgroup size is read from their SPIR-V and whose
//! bindings are numbered in one table ([`bindings`]), timed one-shot submissions, and the tracers
//! built on them.

mod addressing;
pub mod bindings;
mod buffer;
mod compiled;
mod context;
mod every_pipeline;
mod painter;
mod parts;
mod pipeline;
pub mod shaders;
pub mod spirv;
mod statistics;
mod submit;
mod tracer;

pub use addressing::{Addressing, Reach};
pub use buffer::Buffer;
pub use compiled::CompiledPipeline;
pub use context::{Context, ContextOptions, DeviceLimits, External, Validation};
pub use every_pipeline::compile_every_pipeline;
pub use painter::{PaintParams, PaintRecording, PaintStats, Painter, MAX_BRUSHES_PER_PASS};
pub use parts::TraceParams;
pub use pipeline::{ComputePipeline, DescriptorSet};
pub use statistics::{ShaderStatistic, StatisticValue};
pub use submit::Timing;
pub use tracer::{BufferView, Placement, Query, TraceBinding, Traced, Tracer, OBSERVED_BATCH};
