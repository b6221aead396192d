//! What the driver says it compiled a pipeline into (`VK_KHR_pipeline_executable_properties`):
//! registers, spills, instructions, as each driver chooses to report them. On a GPU the register
//! count decides how many rays run at once (occupancy), which is where a larger tracer loses
//! speed that no per-ray counter shows; the bench prints these beside its counters.

use std::fmt;

use ash::vk;
use serde::{Deserialize, Serialize};

/// One statistic of one executable (a compute pipeline has one: its compute shader).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ShaderStatistic {
    /// The driver's name for it (`Register Count`, `Spill Count`, …).
    pub name: String,
    /// Its value.
    pub value: StatisticValue,
}

/// A statistic's value, in the format the driver gave. Read back from JSON (results files), a
/// count that fits `i64` comes back as `Int`: the same number, printed the same.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum StatisticValue {
    /// A yes/no property.
    Bool(bool),
    /// A signed count.
    Int(i64),
    /// An unsigned count.
    UInt(u64),
    /// A measure.
    Float(f64),
}

impl fmt::Display for StatisticValue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            StatisticValue::Bool(b) => write!(f, "{b}"),
            StatisticValue::Int(v) => write!(f, "{v}"),
            StatisticValue::UInt(v) => write!(f, "{v}"),
            StatisticValue::Float(v) => write!(f, "{v:.3}"),
        }
    }
}

impl fmt::Display for ShaderStatistic {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} {}", self.name, self.value)
    }
}

/// The statistics of `pipeline`'s executables, in the driver's order; empty where a query fails
/// (the statistics explain speed and are never needed to trace).
///
/// # Safety
/// `pipeline` was created on `device` with `VK_PIPELINE_CREATE_CAPTURE_STATISTICS_BIT_KHR`, and
/// `device` enabled the extension with its `pipelineExecutableInfo` feature.
pub(crate) unsafe fn query(
    instance: &ash::Instance,
    device: &ash::Device,
    pipeline: vk::Pipeline,
) -> Vec<ShaderStatistic> {
    let loader = ash::khr::pipeline_executable_properties::Device::new(instance, device);
    let info = vk::PipelineInfoKHR::default().pipeline(pipeline);
    let count = unsafe { loader.get_pipeline_executable_properties(&info) }
        .map(|executables| executables.len())
        .unwrap_or(0);
    (0..count as u32)
        .flat_map(|index| {
            let executable = vk::PipelineExecutableInfoKHR::default()
                .pipeline(pipeline)
                .executable_index(index);
            unsafe { loader.get_pipeline_executable_statistics(&executable) }.unwrap_or_default()
        })
        .map(|s| ShaderStatistic {
            name: s
                .name_as_c_str()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default(),
            // SAFETY: `format` says which member of the union the driver wrote.
            value: unsafe {
                match s.format {
                    vk::PipelineExecutableStatisticFormatKHR::BOOL32 => {
                        StatisticValue::Bool(s.value.b32 == vk::TRUE)
                    }
                    vk::PipelineExecutableStatisticFormatKHR::INT64 => {
                        StatisticValue::Int(s.value.i64)
                    }
                    vk::PipelineExecutableStatisticFormatKHR::FLOAT64 => {
                        StatisticValue::Float(s.value.f64)
                    }
                    _ => StatisticValue::UInt(s.value.u64),
                }
            },
        })
        .collect()
}
