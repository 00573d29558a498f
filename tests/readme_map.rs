//! The README's map of concepts to files stays true: every path it names
//! exists. (A file moved or renamed without the README is a failure here.)

use std::path::Path;

/// The paths named in backquotes in the "Concepts and where they live"
/// section: tokens with a `/` that are not commands or URLs.
fn mapped_paths(readme: &str) -> Vec<String> {
    let section = readme
        .split("## Concepts and where they live")
        .nth(1)
        .expect("the README has its concept map")
        .split("\n## ")
        .next()
        .unwrap_or_default();
    let mut paths = Vec::new();
    for (i, chunk) in section.split('`').enumerate() {
        // Odd chunks are inside backquotes.
        if i % 2 == 1
            && chunk.contains('/')
            && !chunk.contains(' ')
            && !chunk.contains("://")
            && !chunk.starts_with("groundcal")
        {
            paths.push(chunk.trim_end_matches(',').to_string());
        }
    }
    paths
}

#[test]
fn every_path_in_the_readmes_concept_map_exists() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let readme = std::fs::read_to_string(root.join("README.md")).unwrap();
    let paths = mapped_paths(&readme);
    assert!(
        paths.len() > 30,
        "only {} paths found: {paths:?}",
        paths.len()
    );
    let missing: Vec<&String> = paths.iter().filter(|p| !root.join(p).exists()).collect();
    assert!(
        missing.is_empty(),
        "the README names paths that do not exist: {missing:?}"
    );
}

#[test]
fn a_missing_path_is_caught() {
    let readme = "## Concepts and where they live\n\n| x | `src/no/such/file.rs` |\n\n## Next";
    assert_eq!(mapped_paths(readme), ["src/no/such/file.rs"]);
}
