//! The architecture the README draws holds in the code: data flows one way. No cycle runs
//! through the top-level modules of `src/` (issue 21: `rbvh` ↔ `lod`, `rbvh` ↔ `surface`,
//! `scene` ↔ `output` once did), nor through the files of one module, nor through the GLSL
//! headers' includes; and no source file grows past what one reader holds in mind
//! ([`MAX_LINES`]). A module's
//! imports are the `crate::` and `super::` paths in its code (grouped `{..}` imports included),
//! comments and test modules left out.

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
    out.sort();
    out
}

/// The code of `file` that is the data flow: without its test module and comments.
fn code_of(file: &Path) -> String {
    let text = std::fs::read_to_string(file).unwrap();
    // Test modules may reach anywhere: they are not the data flow.
    let code = text
        .find("#[cfg(test)]\nmod tests")
        .or_else(|| text.find("#[cfg(test)]\npub(super) mod tests"))
        .map_or(text.as_str(), |end| &text[..end]);
    code.lines()
        .map(|line| line.split("//").next().unwrap_or(""))
        .collect::<Vec<_>>()
        .join("\n")
}

/// The first path segment of every path that follows `prefix` in `code`: `a` of `prefix a::b`,
/// and `a`, `b` of `prefix {a::x, b}` (a grouped import, nested groups included).
fn segments_after(code: &str, prefix: &str) -> BTreeSet<String> {
    let ident = |s: &str| -> String {
        s.trim_start()
            .chars()
            .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
            .collect()
    };
    let mut out = BTreeSet::new();
    let mut rest = code;
    while let Some(at) = rest.find(prefix) {
        // `prefix` must start a path, not end another word (`my_crate::`).
        let before = rest[..at].chars().next_back();
        rest = &rest[at + prefix.len()..];
        if before.is_some_and(|c| c.is_ascii_alphanumeric() || c == '_') {
            continue;
        }
        if let Some(group) = rest.strip_prefix('{') {
            let mut depth = 1;
            let mut item = String::new();
            for c in group.chars() {
                match c {
                    '{' => depth += 1,
                    '}' => depth -= 1,
                    ',' if depth == 1 => {
                        out.insert(ident(&item));
                        item.clear();
                        continue;
                    }
                    _ => {}
                }
                if depth == 0 {
                    break;
                }
                if depth == 1 {
                    item.push(c);
                }
            }
            out.insert(ident(&item));
        } else {
            out.insert(ident(rest));
        }
    }
    out.retain(|s| !s.is_empty() && s.starts_with(|c: char| c.is_ascii_lowercase()));
    out
}

/// A cycle of `graph` (its nodes in order, the first repeated at the end), if it has one.
fn cycle(graph: &BTreeMap<String, BTreeSet<String>>) -> Option<Vec<String>> {
    // Depth-first, colouring nodes: on the path (1) or done (2); an edge back to the path closes
    // a cycle.
    fn visit(
        node: &str,
        graph: &BTreeMap<String, BTreeSet<String>>,
        colour: &mut BTreeMap<String, u8>,
        path: &mut Vec<String>,
    ) -> Option<Vec<String>> {
        colour.insert(node.to_string(), 1);
        path.push(node.to_string());
        for next in graph.get(node).into_iter().flatten() {
            match colour.get(next.as_str()) {
                Some(1) => {
                    let start = path.iter().position(|n| n == next).unwrap();
                    let mut found = path[start..].to_vec();
                    found.push(next.clone());
                    return Some(found);
                }
                Some(_) => {}
                None => {
                    if let Some(found) = visit(next, graph, colour, path) {
                        return Some(found);
                    }
                }
            }
        }
        path.pop();
        colour.insert(node.to_string(), 2);
        None
    }
    let mut colour = BTreeMap::new();
    for node in graph.keys() {
        if !colour.contains_key(node.as_str()) {
            if let Some(found) = visit(node, graph, &mut colour, &mut Vec::new()) {
                return Some(found);
            }
        }
    }
    None
}

fn src() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("src")
}

/// The top-level modules of `src/` and the others each one's code names through `crate::`.
fn top_level_graph() -> BTreeMap<String, BTreeSet<String>> {
    let mut graph = BTreeMap::new();
    for entry in std::fs::read_dir(src()).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_stem().unwrap().to_string_lossy().into_owned();
        if name == "lib" || name == "bin" {
            continue;
        }
        let deps = rust_files(&path)
            .iter()
            .flat_map(|f| segments_after(&code_of(f), "crate::"))
            .filter(|d| *d != name)
            .collect();
        graph.insert(name, deps);
    }
    graph
}

#[test]
fn no_cycle_runs_through_the_top_level_modules() {
    let graph = top_level_graph();
    assert!(graph.len() > 20, "modules found: {:?}", graph.keys());
    assert!(graph["rbvh"].contains("bvh") && graph["lod"].contains("rbvh"));
    // Grouped imports count: `use crate::{lod::Cones, ..}` in the tracer.
    assert!(graph["gpu"].contains("structure") && graph["structure"].contains("lod"));
    assert_eq!(cycle(&graph), None, "a cycle among the top-level modules");
}

/// The files (and folders) directly inside module folder `dir` and, per each, the others its
/// code names: through `super::x` (from a file directly in `dir`) or `crate::<module>::x`, and
/// through a name that `dir/mod.rs` re-exports from `x` (`pub use x::{Name, ..}`), since
/// `super::Name` then reaches `x` through the facade. `mod.rs` itself is the facade, not a node.
fn module_graph(dir: &Path) -> BTreeMap<String, BTreeSet<String>> {
    // `rbvh::raster` for src/rbvh/raster/.
    let module = dir
        .strip_prefix(src())
        .unwrap()
        .components()
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect::<Vec<_>>()
        .join("::");
    let mut children = BTreeMap::new();
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_stem().unwrap().to_string_lossy().into_owned();
        if name != "mod" && (path.is_dir() || path.extension().is_some_and(|e| e == "rs")) {
            children.insert(name, path);
        }
    }
    // Names re-exported by the facade, by the child that defines them.
    let facade = code_of(&dir.join("mod.rs"));
    let mut exported: BTreeMap<String, String> = BTreeMap::new();
    for line in facade.split(';') {
        let line = line.trim();
        let Some(path) = line
            .strip_prefix("pub use ")
            .or_else(|| line.strip_prefix("pub(crate) use "))
        else {
            continue;
        };
        let Some((child, names)) = path.split_once("::") else {
            continue;
        };
        if !children.contains_key(child) {
            continue;
        }
        let names = names.trim_start_matches('{').trim_end_matches('}');
        for name in names.split(',') {
            // A group's trailing comma leaves an empty name: nothing is exported by it.
            let Some(name) = name.split_whitespace().last() else {
                continue;
            };
            exported.insert(name.to_string(), child.to_string());
        }
    }
    let mut graph = BTreeMap::new();
    for (name, path) in &children {
        let mut deps = BTreeSet::new();
        for file in rust_files(path) {
            let code = code_of(&file);
            let mut named = segments_after(&code, &format!("crate::{module}::"));
            if file.parent() == Some(dir) {
                named.extend(segments_after(&code, "super::"));
                // Facade names: `super::Name` / `super::{Name, ..}` (upper case).
                for (export, child) in &exported {
                    let direct = format!("super::{export}");
                    let mentioned = code.match_indices(&direct).any(|(at, _)| {
                        !code[at + direct.len()..].starts_with(|c: char| c.is_alphanumeric())
                    }) || code.contains("super::{") && {
                        let groups = code.split("super::{").skip(1);
                        groups
                            .map(|g| g.split('}').next().unwrap_or(""))
                            .any(|g| g.split(',').any(|item| item.trim() == export))
                    };
                    if mentioned {
                        deps.insert(child.clone());
                    }
                }
            }
            deps.extend(named.into_iter().filter(|d| children.contains_key(d)));
        }
        deps.remove(name);
        graph.insert(name.clone(), deps);
    }
    graph
}

/// Every module folder under `dir` (one with a `mod.rs`), nested ones included.
fn module_dirs(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            if path.join("mod.rs").exists() {
                out.push(path.clone());
            }
            out.extend(module_dirs(&path));
        }
    }
    out.sort();
    out
}

#[test]
fn no_cycle_runs_through_the_files_of_a_module() {
    let mut checked = 0;
    let dirs = module_dirs(&src());
    for dir in &dirs {
        let graph = module_graph(dir);
        checked += graph.len();
        assert_eq!(cycle(&graph), None, "a cycle among the files of {dir:?}");
    }
    assert!(
        checked > 90 && dirs.iter().any(|d| d.ends_with("rbvh/march")),
        "{checked} files checked in {dirs:?}"
    );
    // The scene loader reaches its meshes through one file, which reaches no loader back.
    let scene = module_graph(&src().join("scene"));
    assert!(scene["load"].contains("mesh_file") && scene["scene_file"].contains("mesh_file"));
    assert!(scene["obj"].contains("texture") && scene["gltf"].contains("texture"));
    // The march's steps read one leaf's state, which reads none of them.
    let march = module_graph(&src().join("rbvh/march"));
    assert!(
        march["walk"].contains("leaf") && march["cell"].contains("leaf"),
        "{march:?}"
    );
}

/// Longest file under `src/`, its unit tests included: past it a file mixes steps a reader should
/// find apart (issue #44: `raster.rs` had grown to 2,340 lines of six steps).
const MAX_LINES: usize = 1200;

#[test]
fn no_source_file_passes_the_longest_a_reader_holds() {
    let long: Vec<(PathBuf, usize)> = rust_files(&src())
        .into_iter()
        .map(|f| {
            let lines = std::fs::read_to_string(&f).unwrap().lines().count();
            (f, lines)
        })
        .filter(|(_, lines)| *lines > MAX_LINES)
        .collect();
    assert!(long.is_empty(), "over {MAX_LINES} lines: {long:?}");
}

/// The GLSL files and the files each `#include`s.
fn include_graph() -> BTreeMap<String, BTreeSet<String>> {
    let glsl = Path::new(env!("CARGO_MANIFEST_DIR")).join("glsl");
    let mut graph = BTreeMap::new();
    for entry in std::fs::read_dir(glsl).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        let text = std::fs::read_to_string(&path).unwrap();
        let includes = text
            .lines()
            .filter_map(|l| l.trim().strip_prefix("#include"))
            .map(|rest| rest.trim().trim_matches('"').to_string())
            .collect();
        graph.insert(name, includes);
    }
    graph
}

#[test]
fn no_cycle_runs_through_the_glsl_includes() {
    let graph = include_graph();
    assert!(graph.len() > 15, "{:?}", graph.keys());
    for (file, includes) in &graph {
        for include in includes {
            assert!(graph.contains_key(include), "{file} includes {include}");
        }
    }
    // Level of detail builds on the RBVH's march, not the other way round: the main shader
    // includes both.
    assert!(graph["lod.glsl"].contains("rbvh.glsl"));
    assert!(!graph["rbvh.glsl"].contains("lod.glsl"));
    assert_eq!(cycle(&graph), None, "a cycle among the GLSL includes");
}

/// The traversal template lists, in its header comment, every name it takes from its includer
/// (the hook's and those of the headers before it): a new hook finds there all it must provide or
/// include.
#[test]
fn the_traversal_template_lists_the_names_it_uses() {
    let text =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("glsl/traverse.glsl"))
            .unwrap();
    let (header, code): (Vec<&str>, Vec<&str>) =
        text.lines().partition(|l| l.trim_start().starts_with("//"));
    let header = header.join("\n");
    let code = code.join("\n");
    // The names the template defines itself.
    let own = |name: &str| code.contains(&format!("#define {name}"));
    let mut missing = BTreeSet::new();
    for word in code.split(|c: char| !(c.is_ascii_alphanumeric() || c == '_')) {
        let foreign = word.starts_with("rbvh_")
            || word.starts_with("RBVH_")
            || word.starts_with("Bvh")
            || word == "Ray";
        if foreign && !own(word) && !header.contains(word) {
            missing.insert(word.to_string());
        }
    }
    assert!(missing.is_empty(), "used but not listed: {missing:?}");
}

#[test]
fn the_checks_find_what_they_look_for() {
    let grouped = segments_after(
        "use crate::{geom::{Hit, Ray}, lod::Cones};\nlet x = my_crate::nope; crate::io::x()",
        "crate::",
    );
    assert_eq!(
        grouped.into_iter().collect::<Vec<_>>(),
        ["geom", "io", "lod"]
    );
    let mut graph: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for (a, b) in [("a", "b"), ("b", "c"), ("c", "a"), ("c", "d")] {
        graph.entry(a.into()).or_default().insert(b.into());
    }
    assert_eq!(
        cycle(&graph),
        Some(vec!["a".into(), "b".into(), "c".into(), "a".into()])
    );
    graph.get_mut("c").unwrap().remove("a");
    assert_eq!(cycle(&graph), None);
}
