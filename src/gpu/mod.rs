//! Vulkan compute: a headless context (or an engine's own device), buffers through
//! `gpu-allocator`, compute pipelines whose workgroup size is read from their SPIR-V, timed
//! one-shot submissions, and the tracers built on them.

mod addressing;
mod buffer;
mod compiled;
mod context;
mod painter;
mod pipeline;
pub mod shaders;
pub mod spirv;
mod statistics;
mod submit;
mod tracer;

pub use addressing::{Addressing, Reach};
pub use buffer::Buffer;
pub use compiled::{compile_every_pipeline, CompiledPipeline};
pub use context::{Context, ContextOptions, DeviceLimits, External, Validation};
pub use painter::{PaintParams, PaintRecording, PaintStats, Painter, MAX_BRUSHES_PER_PASS};
pub use pipeline::{ComputePipeline, DescriptorSet};
pub use statistics::{ShaderStatistic, StatisticValue};
pub use submit::Timing;
pub use tracer::{BufferView, Query, TraceBinding, TraceParams, Traced, Tracer, OBSERVED_BATCH};
