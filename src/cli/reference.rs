//! The command reference, `docs/cli.md`, written from clap's own definitions
//! of the commands, so that it cannot drift from them: a test of the binary
//! (`cli_reference_is_the_code's` in `src/main.rs`) compares the file with
//! what this makes, and `GROUNDCAL_BLESS=1` writes it.

use std::fmt::Write;

/// The reference of `top` (built, so that every usage line is whole) in
/// Markdown: the top level's words, then each command's usage, arguments
/// and examples.
pub fn markdown(top: &clap::Command) -> String {
    let mut top = top.clone();
    top.build();
    let name = top.get_name().to_string();
    let mut out = String::new();
    let _ = writeln!(
        out,
        "# `{name}` command reference\n\n\
         Generated from the commands' own definitions (`src/cli/reference.rs`);\n\
         do not edit: `GROUNDCAL_BLESS=1 cargo test --bin groundcal cli_reference`\n\
         writes it again. What the commands are for, with examples, is in\n\
         [commands.md](commands.md).\n"
    );
    if let Some(about) = top.get_long_about().or(top.get_about()) {
        let _ = writeln!(out, "{about}\n");
    }
    let _ = writeln!(out, "```text\n{}\n```\n", top.render_usage());
    if let Some(after) = top.get_after_help() {
        let _ = writeln!(out, "```text\n{after}\n```\n");
    }
    let _ = writeln!(out, "## Commands\n");
    for sub in top.get_subcommands() {
        let _ = writeln!(
            out,
            "- [`{name} {}`](#{name}-{}): {}",
            sub.get_name(),
            sub.get_name(),
            first_line(sub.get_about().map(|a| a.to_string()).unwrap_or_default())
        );
    }
    for sub in top.get_subcommands_mut() {
        let _ = writeln!(out, "\n## {name} {}\n", sub.get_name());
        if let Some(about) = sub.get_long_about().or(sub.get_about()) {
            let _ = writeln!(out, "{about}\n");
        }
        let usage = sub.render_usage().to_string();
        let _ = writeln!(out, "```text\n{usage}\n```\n");
        let arguments: Vec<&clap::Arg> = sub
            .get_arguments()
            .filter(|a| a.get_id() != "help" && !a.is_hide_set())
            .collect();
        if !arguments.is_empty() {
            let _ = writeln!(out, "| argument | meaning |\n|---|---|");
            for arg in arguments {
                let _ = writeln!(out, "| {} | {} |", argument_name(arg), argument_help(arg));
            }
            out.push('\n');
        }
        if let Some(after) = sub.get_after_help() {
            let _ = writeln!(out, "```text\n{after}\n```");
        }
    }
    out
}

fn first_line(text: String) -> String {
    text.lines().next().unwrap_or_default().to_string()
}

/// `--flag VALUE`, `-s, --flag` or `<FILE>`, in backquotes.
fn argument_name(arg: &clap::Arg) -> String {
    let values = arg
        .get_value_names()
        .map(|names| {
            names
                .iter()
                .map(|n| n.to_string())
                .collect::<Vec<_>>()
                .join(" ")
        })
        .unwrap_or_else(|| arg.get_id().as_str().to_uppercase());
    if arg.is_positional() {
        return format!("`<{values}>`");
    }
    let takes_value = arg.get_num_args().is_some_and(|n| n.takes_values());
    let mut name = String::new();
    if let Some(short) = arg.get_short() {
        let _ = write!(name, "-{short}, ");
    }
    if let Some(long) = arg.get_long() {
        let _ = write!(name, "--{long}");
    }
    if takes_value {
        let _ = write!(name, " {values}");
    }
    format!("`{name}`")
}

/// The argument's help on one line of a table, with its choices and default.
fn argument_help(arg: &clap::Arg) -> String {
    let mut help = arg
        .get_long_help()
        .or(arg.get_help())
        .map(|h| h.to_string())
        .unwrap_or_default()
        .split_whitespace()
        .collect::<Vec<_>>()
        .join(" ")
        .replace('|', "\\|");
    let choices: Vec<String> = arg
        .get_possible_values()
        .iter()
        .filter(|v| !v.is_hide_set())
        .map(|v| format!("`{}`", v.get_name()))
        .collect();
    if !choices.is_empty() {
        let _ = write!(help, " One of {}.", choices.join(", "));
    }
    let defaults: Vec<String> = arg
        .get_default_values()
        .iter()
        .map(|v| v.to_string_lossy().into_owned())
        .collect();
    if !defaults.is_empty() && arg.get_num_args().is_some_and(|n| n.takes_values()) {
        let _ = write!(help, " Default `{}`.", defaults.join(","));
    }
    if arg.is_required_set() && !arg.is_positional() {
        help.push_str(" Required.");
    }
    help
}
