//! The README says what is true: its library example is `examples/library.rs` (which `cargo test
//! --all-targets` compiles), its flag tables list every flag of every command and no other, its
//! speed tables are `tools/speed-table`'s output on the JSON kept in docs/speed/, and its first
//! command and its CBbunny line run as written. (Its Python examples: python/tests/test_readme.py;
//! the Slurm loop of docs/more-than-one-machine.md: tests/slurm_array.rs; `bash tools/test` and
//! `pip install .`: .ci/run.)

mod common;

use std::collections::BTreeSet;
use std::path::Path;
use std::process::Command;

const README: &str = include_str!("../README.md");

#[test]
fn readme_quotes_the_library_example() {
    let example = include_str!("../examples/library.rs");
    // The README shows the file without its two leading comment lines.
    let body: String = example.lines().skip_while(|l| l.starts_with("//")).map(|l| format!("{l}\n")).collect();
    let quoted = format!("```rust\n{body}```\n");
    assert!(
        README.contains(&quoted),
        "README.md must quote examples/library.rs (without its leading comment):\n{quoted}"
    );
}

/// The flags `raypack CMD --help` defines (short and long, aliases included), without `--help`.
fn help_flags(cmd: &str) -> BTreeSet<String> {
    let out = Command::new(env!("CARGO_BIN_EXE_raypack")).args([cmd, "--help"]).output().expect("raypack runs");
    assert!(out.status.success(), "raypack {cmd} --help failed");
    let help = String::from_utf8(out.stdout).unwrap();
    let mut flags = BTreeSet::new();
    for line in help.lines() {
        // Aliases are listed in brackets, on a line of their own or after the description.
        if let Some(at) = line.find("[alias: ").or_else(|| line.find("[aliases: ")) {
            let list = &line[at..];
            let list = &list[list.find(": ").unwrap() + 2..list.find(']').unwrap()];
            flags.extend(list.split(", ").map(str::to_string));
        }
        // An option's line is indented and starts with its flags: `-s, --samples <SAMPLES>`.
        let t = line.trim_start();
        if !(t.starts_with('-') && line.len() > t.len()) {
            continue;
        }
        for word in t.split([' ', ',']).filter(|w| !w.is_empty()) {
            if !word.starts_with('-') && !word.starts_with('<') {
                break; // the description starts
            }
            let flag = word.split(['<', '=']).next().unwrap();
            if flag.len() > 1 {
                flags.insert(flag.to_string());
            }
        }
    }
    flags.remove("-h");
    flags.remove("--help");
    flags
}

/// The README's text about `raypack CMD`: from its bold name to the next command's or section.
fn readme_block(cmd: &str) -> &'static str {
    let start = format!("**`raypack {cmd}`**");
    let at = README.find(&start).unwrap_or_else(|| panic!("the README has no {start}"));
    let rest = &README[at + start.len()..];
    let end = [rest.find("**`raypack "), rest.find("\n## ")].into_iter().flatten().min().unwrap_or(rest.len());
    &rest[..end]
}

/// The flags a README block names in code spans: `` `--flag ``, `` `-x` `` or `` `-x `` ….
fn readme_flags(block: &str) -> BTreeSet<String> {
    let mut flags = BTreeSet::new();
    for span in block.split('`').skip(1).step_by(2) {
        let first = span.split(' ').next().unwrap();
        let is_long = first.starts_with("--")
            && first[2..].chars().all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '-');
        let is_short = first.len() == 2 && first.starts_with('-') && first.as_bytes()[1].is_ascii_alphabetic();
        if is_long || is_short {
            flags.insert(first.to_string());
        }
    }
    flags
}

#[test]
fn the_flag_tables_list_every_flag_and_no_other() {
    for cmd in ["render", "info", "bench", "merge", "report"] {
        let help = help_flags(cmd);
        let readme = readme_flags(readme_block(cmd));
        let missing: Vec<_> = help.difference(&readme).collect();
        assert!(
            missing.is_empty(),
            "README.md's `raypack {cmd}` table lacks {missing:?} (raypack {cmd} --help has them)"
        );
        // A flag the README names that the command does not have is stale; the render block's
        // prose names the box's `-s -l -m` defaults, which are render flags too.
        let unknown: Vec<_> = readme.difference(&help).collect();
        assert!(
            unknown.is_empty(),
            "README.md's `raypack {cmd}` text names {unknown:?}, which raypack {cmd} does not have"
        );
    }
}

#[test]
fn the_speed_tables_are_the_generators_output() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let out = Command::new("python3")
        .arg(root.join("tools/speed-table"))
        .arg(root.join("docs/speed"))
        .output()
        .expect("python3 runs tools/speed-table");
    let (stdout, stderr) = (String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "tools/speed-table docs/speed failed: {stderr}");
    let begin = README.find("<!-- speed-table:").expect("the README marks its speed tables");
    let body = &README[begin..];
    let body =
        &body[body.find("-->\n").unwrap() + 4..body.find("<!-- /speed-table -->").expect("the tables' end marker")];
    assert_eq!(
        body, stdout,
        "README.md's speed tables are not `tools/speed-table docs/speed`'s output: regenerate them, never edit by hand"
    );
}

#[test]
fn the_readme_cbbunny_command_runs_as_written() {
    let Some(scenes) = common::scenes_dir("the_readme_cbbunny_command_runs_as_written") else {
        return;
    };
    let at = README.find("`raypack render $RAYPACK_SCENES/cs184/sky/CBbunny.dae").expect("the README's CBbunny line");
    let line = &README[at + 1..];
    let line = &line[..line.find('`').unwrap()];
    let dir = std::env::temp_dir().join(format!("raypack-readme-bunny-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let args: Vec<String> =
        line.split_whitespace().skip(1).map(|w| w.replace("$RAYPACK_SCENES", scenes.to_str().unwrap())).collect();
    let out = Command::new(env!("CARGO_BIN_EXE_raypack")).args(&args).current_dir(&dir).output().unwrap();
    assert!(out.status.success(), "{line}: {}", String::from_utf8_lossy(&out.stderr));
    // The image and, with -a, the sample-rate image the README mentions.
    for name in ["bunny.png", "bunny_rate.png"] {
        assert!(std::fs::metadata(dir.join(name)).map(|m| m.len() > 0).unwrap_or(false), "{line}: no {name}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn the_readme_first_command_renders_the_built_in_box() {
    // The first ```sh block: `cargo run --release -- ARGS`, run here as the built binary.
    let section = README.split("## Two commands for a fresh machine").nth(1).expect("the section");
    let block = section.split("```sh\n").nth(1).unwrap().split("```").next().unwrap().trim();
    let args = block.strip_prefix("cargo run --release -- ").unwrap_or_else(|| panic!("not `cargo run`: {block}"));
    let dir = std::env::temp_dir().join(format!("raypack-readme-first-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let out =
        Command::new(env!("CARGO_BIN_EXE_raypack")).args(args.split_whitespace()).current_dir(&dir).output().unwrap();
    assert!(out.status.success(), "{block}: {}", String::from_utf8_lossy(&out.stderr));
    let png = std::fs::read(dir.join("cornell.png")).expect("the README's command writes cornell.png");
    assert!(png.starts_with(b"\x89PNG"), "{block}: not a PNG");
    std::fs::remove_dir_all(&dir).unwrap();
}
