//! Vulkan compute: a headless context (or an engine's own device), buffers through
//! `gpu-allocator`, compute pipelines whose workgroup size is read from their SPIR-V, timed
//! one-shot submissions, and the tracers built on them.

mod buffer;
mod context;
mod exact_tracer;
mod pipeline;
pub mod shaders;
pub mod spirv;
mod submit;

pub use buffer::Buffer;
pub use context::{Context, ContextOptions, Validation};
pub use exact_tracer::{ExactTracer, Query, Traced};
pub use pipeline::ComputePipeline;
pub use submit::Timing;
