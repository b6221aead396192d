//! `rbvh shaders`: compiles every pipeline the library has on a device, runs nothing, and prints
//! what the driver compiled each into (registers, spills, code size, scratch, waves per SIMD) —
//! with `--amd FAMILY`, on RADV's null device: AMD's compiler with no AMD GPU.

use std::path::PathBuf;

use anyhow::{Context as _, Result};
use rbvh::bench::{shader_report, shader_report_table, write_shader_json};
use rbvh::gpu::Context;

use crate::outputs::{self, output};
use crate::prepare::context_options;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Compile for this AMD GPU family on RADV's null device (Mesa's, installed with
    /// mesa-vulkan-drivers): sets RADV_FORCE_FAMILY (and MESA_SHADER_CACHE_DISABLE, so that
    /// every pipeline is compiled) and picks that device. Families Mesa 22.3 knows include
    /// navi21, navi10, vega10 and rembrandt; navi21 is the project's reference.
    #[arg(long, value_name = "FAMILY")]
    amd: Option<String>,
    /// With --amd: compile compute shaders for wave32 (adds cswave32 to RADV_PERFTEST) instead of
    /// wave64.
    #[arg(long, requires = "amd")]
    wave32: bool,
    /// Compile on the first device whose name contains this (default: RBVH_DEVICE, else the
    /// device a render would use; with --amd, the null device).
    #[arg(long, conflicts_with = "amd")]
    device: Option<String>,
    /// Also write every pipeline's statistics, with the run's provenance, as JSON.
    #[arg(long, value_name = "FILE")]
    json: Option<PathBuf>,
    /// Require the Vulkan validation layers (else RBVH_VALIDATION decides).
    #[arg(long)]
    validate: bool,
}

/// The families RADV's null device can pretend to be (`RADV_FORCE_FAMILY`, compared without
/// case): Mesa 22.3.6's `ac_get_family_name`, Debian 12's. RADV aborts the process on any other
/// name, so it is refused here first.
const AMD_FAMILIES: [&str; 41] = [
    "TAHITI",
    "PITCAIRN",
    "VERDE",
    "OLAND",
    "HAINAN",
    "BONAIRE",
    "KAVERI",
    "KABINI",
    "HAWAII",
    "TONGA",
    "ICELAND",
    "CARRIZO",
    "FIJI",
    "STONEY",
    "POLARIS10",
    "POLARIS11",
    "POLARIS12",
    "VEGAM",
    "VEGA10",
    "VEGA12",
    "VEGA20",
    "RAVEN",
    "RAVEN2",
    "RENOIR",
    "ARCTURUS",
    "ALDEBARAN",
    "NAVI10",
    "NAVI12",
    "NAVI14",
    "NAVI21",
    "NAVI22",
    "NAVI23",
    "NAVI24",
    "VANGOGH",
    "GFX1036",
    "GFX1100",
    "GFX1101",
    "GFX1102",
    "REMBRANDT",
    "GFX1103_R1",
    "GFX1103_R2",
];

pub fn run(a: Args) -> Result<()> {
    outputs::check(&[output("--json", a.json.as_deref(), "json")], &[])?;
    let device = match &a.amd {
        Some(family) => {
            anyhow::ensure!(
                AMD_FAMILIES
                    .iter()
                    .any(|known| known.eq_ignore_ascii_case(family)),
                "--amd {family:?}: not a family RADV knows; one of {}",
                AMD_FAMILIES.join(", ").to_lowercase()
            );
            // Read by Mesa when the instance enumerates devices, which is after this; nothing
            // else runs yet.
            std::env::set_var("RADV_FORCE_FAMILY", family);
            std::env::set_var("MESA_SHADER_CACHE_DISABLE", "true");
            // Kept as the user set it (the report records it), with cswave32 added for --wave32.
            if a.wave32 {
                let perftest = std::env::var("RADV_PERFTEST").unwrap_or_default();
                let flags: Vec<&str> = perftest
                    .split(',')
                    .filter(|f| !f.is_empty())
                    .chain(["cswave32"])
                    .collect();
                std::env::set_var("RADV_PERFTEST", flags.join(","));
            }
            Some("RADV".to_string())
        }
        None => a.device.clone(),
    };
    let ctx = Context::new(&context_options(device.as_deref(), a.validate)?).with_context(|| {
        match &a.amd {
            Some(f) => format!(
                "creating RADV's null device for {f} (is mesa-vulkan-drivers installed, and is {f} a family this Mesa knows?)"
            ),
            None => "creating the Vulkan device".into(),
        }
    })?;
    if a.amd.is_some() && !ctx.limits().compile_only {
        anyhow::bail!(
            "--amd: the device chosen, {}, is not RADV's null device",
            ctx.device_name()
        );
    }
    let report = shader_report(&ctx)?;
    print!("{}", shader_report_table(&report));
    if let Some(path) = &a.json {
        write_shader_json(path, &report).with_context(|| format!("writing {}", path.display()))?;
        eprintln!("wrote {}", path.display());
    }
    Ok(())
}
