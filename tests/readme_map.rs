//! The newcomer's page and the concept map stay true: every path the README
//! names, every document it links, and every path in the concept map of
//! `docs/architecture.md` exists. (A file moved or renamed without its
//! documents is a failure here.)

use std::path::Path;

/// The paths named in backquotes in `text`: tokens with a `/` that are not
/// commands, URLs or paths outside the project (`../shared/`, `/etc/`).
fn quoted_paths(text: &str) -> Vec<String> {
    let mut paths = Vec::new();
    for (i, chunk) in text.split('`').enumerate() {
        // Odd chunks are inside backquotes.
        if i % 2 == 1
            && chunk.contains('/')
            && !chunk.contains(' ')
            && !chunk.contains("://")
            && !chunk.starts_with("groundcal")
            && !chunk.starts_with("../")
            && !chunk.starts_with('/')
        {
            paths.push(chunk.trim_end_matches(',').to_string());
        }
    }
    paths
}

/// The relative targets of Markdown links, `[text](target)`.
fn linked_paths(text: &str) -> Vec<String> {
    text.split("](")
        .skip(1)
        .filter_map(|rest| rest.split(')').next())
        .filter(|target| !target.contains("://") && !target.starts_with('#'))
        .map(|target| target.split('#').next().unwrap_or_default().to_string())
        .collect()
}

/// The section of `text` under the heading `title`, up to the next `## `.
fn section<'a>(text: &'a str, title: &str) -> Option<&'a str> {
    let after = text.split(title).nth(1)?;
    Some(after.split("\n## ").next().unwrap_or_default())
}

fn missing(root: &Path, paths: &[String]) -> Vec<String> {
    paths
        .iter()
        .filter(|p| !root.join(p).exists())
        .cloned()
        .collect()
}

#[test]
fn every_path_the_readme_names_or_links_exists() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let readme = std::fs::read_to_string(root.join("README.md")).unwrap();
    let quoted = quoted_paths(&readme);
    let linked = linked_paths(&readme);
    assert!(quoted.len() > 15, "only {} paths: {quoted:?}", quoted.len());
    assert!(linked.len() > 10, "only {} links: {linked:?}", linked.len());
    let gone = [missing(root, &quoted), missing(root, &linked)].concat();
    assert!(
        gone.is_empty(),
        "the README names what does not exist: {gone:?}"
    );
}

#[test]
fn every_path_in_the_concept_map_exists() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let architecture = std::fs::read_to_string(root.join("docs/architecture.md")).unwrap();
    let map = section(&architecture, "## Concepts and where they live")
        .expect("docs/architecture.md has its concept map");
    let paths = quoted_paths(map);
    assert!(paths.len() > 30, "only {} paths: {paths:?}", paths.len());
    let gone = missing(root, &paths);
    assert!(
        gone.is_empty(),
        "the concept map names what does not exist: {gone:?}"
    );
}

#[test]
fn every_document_linked_from_the_docs_exists() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut gone = Vec::new();
    for entry in std::fs::read_dir(root.join("docs")).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "md") {
            let text = std::fs::read_to_string(&path).unwrap();
            for target in linked_paths(&text) {
                if !path.parent().unwrap().join(&target).exists() {
                    gone.push(format!("{}: {target}", path.display()));
                }
            }
        }
    }
    assert!(gone.is_empty(), "links to nothing: {gone:?}");
}

#[test]
fn every_test_suite_is_described_in_docs_tests() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let described = std::fs::read_to_string(root.join("docs/tests.md")).unwrap();
    let mut missing = Vec::new();
    for entry in std::fs::read_dir(root.join("tests")).unwrap() {
        let name = entry.unwrap().file_name().to_string_lossy().into_owned();
        if name.ends_with(".rs") && !described.contains(&format!("`tests/{name}`")) {
            missing.push(name);
        }
    }
    assert!(
        missing.is_empty(),
        "docs/tests.md does not describe {missing:?}"
    );
}

#[test]
fn a_missing_path_is_caught() {
    let map = "## Concepts and where they live\n\n| x | `src/no/such/file.rs` |\n\n## Next";
    let paths = quoted_paths(section(map, "## Concepts and where they live").unwrap());
    assert_eq!(paths, ["src/no/such/file.rs"]);
    assert_eq!(missing(Path::new("."), &paths), paths);
    assert_eq!(
        linked_paths("see [a](docs/none.md#x) and [b](https://x/)"),
        ["docs/none.md"]
    );
}
