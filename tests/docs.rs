//! The README and `docs/` stay true to the repository: every relative link and image they hold
//! names a file that exists, and every `#anchor` a heading of that file (GitHub's anchors).
//! Links inside code (fenced blocks, inline spans) are not links and are skipped.

use std::collections::HashSet;
use std::path::{Path, PathBuf};

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// The markdown files a reader of the repository opens (those `rbvh tables` writes into).
fn documents() -> Vec<PathBuf> {
    rbvh::bench::markdown::documents(root())
        .unwrap()
        .into_iter()
        .map(|d| root().join(d))
        .collect()
}

/// The text's lines with fenced code blocks emptied and inline code spans removed.
fn prose_lines(text: &str) -> Vec<String> {
    let mut fenced = false;
    text.lines()
        .map(|line| {
            if line.trim_start().starts_with("```") {
                fenced = !fenced;
                return String::new();
            }
            if fenced {
                return String::new();
            }
            // Odd-numbered pieces between backticks are code.
            line.split('`').step_by(2).collect::<Vec<_>>().join("")
        })
        .collect()
}

/// GitHub's anchor of a heading: a link's text only, lower case, punctuation other than `-` and
/// `_` dropped, spaces as hyphens.
fn slug(heading: &str) -> String {
    let mut text = String::new();
    let mut rest = heading;
    while let Some(start) = rest.find("](") {
        let end = rest[start..]
            .find(')')
            .map_or(rest.len(), |e| start + e + 1);
        text.push_str(&rest[..start]);
        rest = &rest[end..];
    }
    text.push_str(rest);
    text.trim()
        .to_lowercase()
        .chars()
        .filter(|c| c.is_alphanumeric() || matches!(c, '-' | '_' | ' '))
        .map(|c| if c == ' ' { '-' } else { c })
        .collect()
}

/// Every heading anchor of `path`, repeated headings numbered `-1`, `-2`, … as GitHub does.
fn anchors(path: &Path) -> HashSet<String> {
    let mut found = HashSet::new();
    let mut seen = std::collections::HashMap::new();
    for line in prose_lines(&std::fs::read_to_string(path).unwrap()) {
        let hashes = line.chars().take_while(|&c| c == '#').count();
        if (1..=6).contains(&hashes) && line[hashes..].starts_with(' ') {
            let base = slug(line[hashes..].trim().trim_end_matches('#'));
            let n = seen.entry(base.clone()).or_insert(0);
            found.insert(if *n == 0 {
                base.clone()
            } else {
                format!("{base}-{n}")
            });
            *n += 1;
        }
    }
    found
}

/// The targets of the `[text](target)` and `![alt](target)` links in a line.
fn link_targets(line: &str) -> Vec<&str> {
    line.match_indices("](")
        .filter_map(|(i, _)| {
            let rest = &line[i + 2..];
            let end = rest.find([')', ' '])?;
            Some(&rest[..end])
        })
        .collect()
}

#[test]
fn every_relative_link_and_anchor_resolves() {
    let mut broken = Vec::new();
    let mut checked = 0;
    for doc in documents() {
        let text = std::fs::read_to_string(&doc).unwrap();
        for (number, line) in prose_lines(&text).iter().enumerate() {
            for target in link_targets(line) {
                let external = target
                    .split_once(':')
                    .is_some_and(|(scheme, _)| scheme.chars().all(|c| c.is_ascii_alphabetic()));
                if external || target.is_empty() {
                    continue;
                }
                checked += 1;
                let (file, anchor) = target.split_once('#').unwrap_or((target, ""));
                let dest = if file.is_empty() {
                    doc.clone()
                } else {
                    doc.parent().unwrap().join(file)
                };
                let place = format!(
                    "{}:{}: {target}",
                    doc.strip_prefix(root()).unwrap().display(),
                    number + 1
                );
                if !dest.exists() {
                    broken.push(format!("{place}: no such file"));
                } else if !anchor.is_empty() && !anchors(&dest).contains(anchor) {
                    broken.push(format!("{place}: no heading with that anchor"));
                }
            }
        }
    }
    assert!(
        checked > 50,
        "only {checked} links found: is the parser still right?"
    );
    assert!(broken.is_empty(), "broken links:\n{}", broken.join("\n"));
}

#[test]
fn anchors_follow_github() {
    assert_eq!(
        slug("Benchmarks: the speed/accuracy trade"),
        "benchmarks-the-speedaccuracy-trade"
    );
    assert_eq!(
        slug("Speed: where a ray's work and memory traffic go"),
        "speed-where-a-rays-work-and-memory-traffic-go"
    );
    assert_eq!(slug("[Linked](x.md) heading"), "linked-heading");
    assert_eq!(
        link_targets("see [a](b.md#c) and ![i](d.png)"),
        ["b.md#c", "d.png"]
    );
}

/// CI runs exactly the README's test command (and then the lints), so that what a user runs is
/// what lands: the command under the README's "Run the whole test suite" comment is a line of
/// `.ci/run`, which also denies clippy's warnings and checks the formatting.
#[test]
fn ci_runs_the_readme_test_command_and_the_lints() {
    let readme = std::fs::read_to_string(root().join("README.md")).unwrap();
    let lines: Vec<&str> = readme.lines().collect();
    let comment = lines
        .iter()
        .position(|l| l.starts_with("# Run the whole test suite"))
        .expect("the README's test command comment");
    let command = lines[comment..]
        .iter()
        .find(|l| !l.starts_with('#'))
        .expect("a command after the comment");
    let ci = std::fs::read_to_string(root().join(".ci/run")).unwrap();
    let ci_lines: Vec<&str> = ci.lines().collect();
    assert!(
        ci_lines.contains(command),
        "README test command {command:?} is not a line of .ci/run"
    );
    for lint in [
        "cargo clippy --release --all-targets -- -D warnings",
        "cargo fmt --check",
    ] {
        assert!(ci_lines.contains(&lint), ".ci/run does not run {lint:?}");
    }
}

/// Every measured table of the README and docs/ is what `rbvh tables` makes of its results file
/// (docs/results/README.md): a table edited by hand, or a results file changed without rerunning
/// the command, fails here.
#[test]
fn every_table_is_what_its_results_file_makes() {
    let stale = rbvh::bench::markdown::update(root(), true).unwrap();
    let places: Vec<String> = stale
        .iter()
        .flat_map(|s| {
            s.lines
                .iter()
                .map(move |l| format!("{}:{l}", s.document.display()))
        })
        .collect();
    assert!(
        places.is_empty(),
        "tables that differ from their results files (run `cargo run --release -- tables`):\n{}",
        places.join("\n")
    );
}

/// No table of measurements is typed by hand: each is a generated block, or marked as holding no
/// measurement.
#[test]
fn no_table_is_typed_by_hand() {
    let mut unmarked = Vec::new();
    let mut blocks = 0;
    for document in rbvh::bench::markdown::documents(root()).unwrap() {
        let text = std::fs::read_to_string(root().join(&document)).unwrap();
        blocks += text.matches(rbvh::bench::markdown::OPEN).count();
        for line in rbvh::bench::markdown::unmarked_tables(&text) {
            unmarked.push(format!("{}:{line}", document.display()));
        }
    }
    assert!(
        blocks > 40,
        "only {blocks} generated tables: is the scan right?"
    );
    assert!(
        unmarked.is_empty(),
        "tables outside a generated block and not marked `<!-- not a measurement -->`:\n{}",
        unmarked.join("\n")
    );
}

/// Every results file says where it was measured: raw results carry the host (its CPU at least)
/// and the commit; transcribed ones their source, commit (or null), host and device.
#[test]
fn every_results_file_names_its_host() {
    let dir = root().join("docs/results");
    let mut checked = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "json") {
            continue;
        }
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&path).unwrap())
                .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let name = path.display();
        if let Some(t) = json.get("transcribed") {
            for key in ["source", "host", "device"] {
                assert!(
                    t[key].as_str().is_some_and(|s| !s.is_empty()),
                    "{name}: transcribed.{key}"
                );
            }
            assert!(
                t["commit"].is_null() || t["commit"].is_string(),
                "{name}: transcribed.commit"
            );
        } else {
            assert!(json["host"]["cpu"].is_string(), "{name}: host.cpu");
            assert!(json["git"].is_string(), "{name}: git");
            assert!(
                json["device"].is_string() && json["driver"].is_string(),
                "{name}"
            );
        }
        checked += 1;
    }
    assert!(checked > 40, "only {checked} results files");
}
