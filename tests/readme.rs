//! The README's library example is `examples/library.rs` (which `cargo test --all-targets`
//! compiles): the README must quote it verbatim.

#[test]
fn readme_quotes_the_library_example() {
    let readme = include_str!("../README.md");
    let example = include_str!("../examples/library.rs");
    // The README shows the file without its two leading comment lines.
    let body: String = example.lines().skip_while(|l| l.starts_with("//")).map(|l| format!("{l}\n")).collect();
    let quoted = format!("```rust\n{body}```\n");
    assert!(
        readme.contains(&quoted),
        "README.md must quote examples/library.rs (without its leading comment):\n{quoted}"
    );
}
