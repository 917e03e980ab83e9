//! Every flag a message names is one of conesight's (issue 39: a PnP warning told users to
//! "raise the inlier threshold", a setting no command has). The string literals of every
//! crate's and service's sources are read; each `--flag` in them must be a long flag (or
//! alias) of `conesight`, one of its subcommands or a service binary, and a literal that asks
//! to raise or lower something must name the flag that does it.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use clap::{Args, CommandFactory};

/// Flags of other tools that messages name on purpose.
const OTHER_TOOLS: &[&str] = &[
    // cargo: building Zenoh's optional authentication (conesight-bus security).
    "--features",
    // ONNX Runtime's build script, for a GPU library (conesight-onnx).
    "--use_cuda",
    "--use_tensorrt",
];

/// Every long flag and alias of `command` and its subcommands.
fn flags_of(command: &clap::Command, flags: &mut BTreeSet<String>) {
    for arg in command.get_arguments() {
        if let Some(long) = arg.get_long() {
            flags.insert(format!("--{long}"));
        }
        for alias in arg.get_long_and_visible_aliases().into_iter().flatten() {
            flags.insert(format!("--{alias}"));
        }
        for alias in arg.get_all_aliases().into_iter().flatten() {
            flags.insert(format!("--{alias}"));
        }
    }
    for sub in command.get_subcommands() {
        flags_of(sub, flags);
    }
}

/// The contents of the string literals of a Rust source file (comments skipped; escapes and
/// line continuations kept as written, which is enough to find flags in them).
fn string_literals(source: &str) -> Vec<String> {
    let mut literals = Vec::new();
    let mut chars = source.chars().peekable();
    while let Some(c) = chars.next() {
        match c {
            '/' if chars.peek() == Some(&'/') => {
                for c in chars.by_ref() {
                    if c == '\n' {
                        break;
                    }
                }
            }
            '\'' => {
                // A char literal ('"', '\'') or a lifetime: skip a quoted char.
                let rest: String = chars.clone().take(3).collect();
                if rest.starts_with('\\') {
                    chars.nth(2);
                } else if rest.chars().nth(1) == Some('\'') {
                    chars.nth(1);
                }
            }
            '"' => {
                let mut literal = String::new();
                while let Some(c) = chars.next() {
                    match c {
                        '\\' => {
                            if let Some(next) = chars.next() {
                                literal.push('\\');
                                literal.push(next);
                            }
                        }
                        '"' => break,
                        _ => literal.push(c),
                    }
                }
                literals.push(literal);
            }
            _ => {}
        }
    }
    literals
}

/// `--name` tokens of `text`.
fn mentioned_flags(text: &str) -> Vec<String> {
    let bytes = text.as_bytes();
    let mut flags = Vec::new();
    let mut i = 0;
    while i + 2 < bytes.len() {
        let starts = bytes[i] == b'-'
            && bytes[i + 1] == b'-'
            && bytes[i + 2].is_ascii_lowercase()
            && (i == 0 || !(bytes[i - 1].is_ascii_alphanumeric() || bytes[i - 1] == b'-'));
        if starts {
            let end = (i + 2..bytes.len())
                .find(|&j| {
                    !(bytes[j].is_ascii_alphanumeric() || bytes[j] == b'-' || bytes[j] == b'_')
                })
                .unwrap_or(bytes.len());
            flags.push(text[i..end].trim_end_matches('-').to_owned());
            i = end;
        } else {
            i += 1;
        }
    }
    flags
}

fn rust_files(dir: &Path, files: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let path = entry.path();
        if path.is_dir() {
            rust_files(&path, files);
        } else if path.extension().is_some_and(|e| e == "rs") {
            files.push(path);
        }
    }
}

#[test]
fn every_flag_a_message_names_exists() {
    let mut known = BTreeSet::new();
    flags_of(&crate::Cli::command(), &mut known);
    for command in [
        conesight_camera_service::CameraArgs::augment_args(clap::Command::new("camera")),
        conesight_detector_service::DetectorArgs::augment_args(clap::Command::new("detector")),
        conesight_keypoints_service::KeypointsArgs::augment_args(clap::Command::new("keypoints")),
        conesight_localiser_service::LocaliserArgs::augment_args(clap::Command::new("localiser")),
    ] {
        flags_of(&command, &mut known);
    }
    known.extend(OTHER_TOOLS.iter().map(|f| (*f).to_owned()));
    // clap's own, on every command (not among the arguments it lists before a build).
    known.insert("--help".to_owned());
    assert!(known.contains("--camera-info") && known.contains("--dashboard-addr"));

    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let mut files = Vec::new();
    for top in ["crates", "services"] {
        let Ok(entries) = std::fs::read_dir(root.join(top)) else {
            continue;
        };
        for entry in entries.flatten() {
            rust_files(&entry.path().join("src"), &mut files);
        }
    }
    assert!(files.len() > 50, "{} source files", files.len());
    let mut unknown = Vec::new();
    let mut no_flag = Vec::new();
    for file in &files {
        let source = std::fs::read_to_string(file).unwrap_or_default();
        // The tests of a module feed wrong flags on purpose.
        let source = source.split("#[cfg(test)]").next().unwrap_or_default();
        for literal in string_literals(source) {
            let flags = mentioned_flags(&literal);
            for flag in &flags {
                if !known.contains(flag) {
                    unknown.push(format!("{}: {flag} in {literal:?}", file.display()));
                }
            }
            let lower = literal.to_lowercase();
            let asks = ["raise the ", "lower the ", "increase the ", "decrease the "]
                .iter()
                .any(|verb| lower.contains(verb));
            if asks && flags.is_empty() {
                no_flag.push(format!("{}: {literal:?}", file.display()));
            }
        }
    }
    assert!(
        unknown.is_empty(),
        "flags no command has:\n{}",
        unknown.join("\n")
    );
    assert!(
        no_flag.is_empty(),
        "messages that ask for a change without naming its flag:\n{}",
        no_flag.join("\n")
    );
}

#[test]
fn flags_are_found_in_literals_and_not_in_comments() {
    let source = "// --not-this\nlet a = \"pass --camera-info FILE, or --x\"; let b = 'a'; \
                  let c = \"--frames\\\n  --rate-hz\";";
    let literals = string_literals(source);
    let flags: Vec<String> = literals.iter().flat_map(|l| mentioned_flags(l)).collect();
    assert_eq!(flags, ["--camera-info", "--x", "--frames", "--rate-hz"]);
    assert!(mentioned_flags("a-b--c x---y 1--z").is_empty());
}
