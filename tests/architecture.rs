//! The architecture the README draws holds in the code: data flows one way, so no two top-level
//! modules of `src/` import each other (issue 21: `rbvh` ↔ `lod`, `rbvh` ↔ `surface`, `scene` ↔
//! `output` once did). A module's imports are the `crate::<module>` paths in its code, comments
//! and test modules left out.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// Every `.rs` file under `dir` (or `dir` itself when it is a file).
fn rust_files(dir: &Path) -> Vec<PathBuf> {
    if dir.is_file() {
        return vec![dir.to_path_buf()];
    }
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            out.extend(rust_files(&path));
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
    out
}

/// The top-level modules that the code of `file` names through `crate::`.
fn imports(file: &Path) -> BTreeSet<String> {
    let text = std::fs::read_to_string(file).unwrap();
    // Test modules may reach anywhere: they are not the data flow.
    let code = text
        .find("#[cfg(test)]\nmod tests")
        .or_else(|| text.find("#[cfg(test)]\npub(super) mod tests"))
        .map_or(text.as_str(), |end| &text[..end]);
    let mut out = BTreeSet::new();
    for line in code.lines() {
        let line = line.split("//").next().unwrap_or("");
        let mut rest = line;
        while let Some(at) = rest.find("crate::") {
            rest = &rest[at + "crate::".len()..];
            let name: String = rest
                .chars()
                .take_while(|c| c.is_ascii_lowercase() || *c == '_')
                .collect();
            if !name.is_empty() {
                out.insert(name);
            }
        }
    }
    out
}

#[test]
fn no_two_top_level_modules_import_each_other() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut graph: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for entry in std::fs::read_dir(&src).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_stem().unwrap().to_string_lossy().into_owned();
        if name == "lib" || name == "bin" {
            continue;
        }
        let deps = rust_files(&path)
            .iter()
            .flat_map(|f| imports(f))
            .filter(|d| *d != name)
            .collect();
        graph.insert(name, deps);
    }
    assert!(graph.len() > 20, "modules found: {:?}", graph.keys());
    assert!(graph["rbvh"].contains("bvh") && graph["lod"].contains("rbvh"));
    let mutual: Vec<(String, String)> = graph
        .iter()
        .flat_map(|(a, deps)| {
            deps.iter()
                .filter(|b| a < *b && graph.get(*b).is_some_and(|d| d.contains(a)))
                .map(|b| (a.clone(), b.clone()))
                .collect::<Vec<_>>()
        })
        .collect();
    assert!(
        mutual.is_empty(),
        "modules importing each other: {mutual:?}"
    );
}
