//! `rbvh tables`: writes every generated table of a repository's documents (README.md,
//! scenes/README.md, docs/*.md) from the results files their blocks name (`rbvh::bench::markdown`;
//! docs/results/README.md describes both), or with `--check` says which differ.

use std::path::PathBuf;

use anyhow::{Context as _, Result};
use rbvh::bench::markdown;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// The repository whose documents to write (their paths and the results files' are relative
    /// to it).
    #[arg(long, default_value = ".")]
    root: PathBuf,
    /// Change nothing: fail, naming each block, where a table is not what its file makes or a
    /// table outside a block is not marked `<!-- not a measurement -->`.
    #[arg(long)]
    check: bool,
}

pub fn run(a: Args) -> Result<()> {
    let documents = markdown::documents(&a.root)?;
    anyhow::ensure!(
        !documents.is_empty(),
        "no README.md, scenes/README.md or docs/*.md under {}: give the repository with --root",
        a.root.display()
    );
    let stale = markdown::update(&a.root, a.check)?;
    let mut unmarked = Vec::new();
    for document in documents {
        let path = a.root.join(&document);
        let text = std::fs::read_to_string(&path)
            .with_context(|| format!("reading {}", path.display()))?;
        for line in markdown::unmarked_tables(&text) {
            unmarked.push(format!("{}:{line}", document.display()));
        }
    }
    for s in &stale {
        for line in &s.lines {
            let verb = if a.check {
                "differs from its file"
            } else {
                "written"
            };
            eprintln!("{}:{line}: table {verb}", s.document.display());
        }
    }
    for place in &unmarked {
        eprintln!(
            "{place}: a table outside a generated block and not marked {}",
            markdown::NOT_A_MEASUREMENT
        );
    }
    if a.check && !stale.is_empty() {
        anyhow::bail!("tables differ from their results files: run rbvh tables");
    }
    anyhow::ensure!(
        unmarked.is_empty(),
        "tables typed by hand: make each a block over a results file (docs/results/README.md)"
    );
    if !a.check && stale.is_empty() {
        eprintln!("every table is what its results file makes");
    }
    Ok(())
}
