//! `rbvh upgrade`: a flat `.rbvh` file of any version rewritten as the current one. Every version
//! loads as it is (upgraded in memory on each load), but a painted colour channel lives only in
//! its file and no scene rebuilds it, so an old file is worth keeping in a form that later builds
//! read without the old readers' conversions, and that says what each of its sections is.

use std::path::PathBuf;

use anyhow::Result;
use rbvh::rbvh::file::{file_version, section_table, Section, VERSION};
use rbvh::rbvh::Rbvh;

use crate::outputs::{self, output};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// The flat RBVH file to read, of any version.
    input: PathBuf,
    /// Where to write it as the current version. It may be the input itself: the file is
    /// replaced only once the new one is complete, so a failure leaves the old one whole.
    #[arg(long, short)]
    out: PathBuf,
}

pub fn run(a: Args) -> Result<()> {
    // The input may be the output: the file is read whole before the new one replaces it.
    outputs::check(&[output("--out", Some(&a.out), "rbvh")], &[])?;
    let bytes = rbvh::io::input::read(&a.input)?;
    let version = file_version(&bytes, &a.input)?;
    let rbvh = Rbvh::from_bytes(&bytes, &a.input)?;
    let written = rbvh.to_bytes();
    rbvh.save(&a.out)?;

    let sections = section_table(&written, &a.out)?;
    // A current file's optional sections that this build does not know are not written again.
    let dropped: Vec<Section> = if version == VERSION {
        section_table(&bytes, &a.input)?
            .into_iter()
            .filter(|s| !sections.iter().any(|w| w.tag == s.tag))
            .collect()
    } else {
        Vec::new()
    };
    let names: Vec<String> = sections
        .iter()
        .map(|s| format!("{} v{}", s.name(), s.version))
        .collect();
    println!(
        "{} (version {version}) → {} (version {VERSION}): {} nodes, {} triangles, {} height-field \
         leaves, {} texels{}; sections {}",
        a.input.display(),
        a.out.display(),
        rbvh.nodes.len(),
        rbvh.triangles.len(),
        rbvh.heightfields.len(),
        rbvh.atlas.texels.len(),
        if rbvh.colours.is_some() {
            " and their colours"
        } else {
            ""
        },
        names.join(", ")
    );
    if version < 5 {
        println!("its 64-byte nodes were quantized to 48 bytes, each box only growing");
    }
    if version < 6 {
        println!(
            "its height codes were marked sampled or extrapolated, each moving by one code at \
             most, as loading a version {version} file always does"
        );
    }
    for s in dropped {
        println!(
            "dropped: optional section {} (version {}, {} bytes), which this build does not know",
            s.name(),
            s.version,
            s.length
        );
    }
    Ok(())
}
