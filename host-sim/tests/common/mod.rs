//! What the `gma` binary tests share: running it, reading its stderr, and the one shape every
//! refusal must have.

#![allow(dead_code)] // each test file uses what it needs

use std::process::{Command, Output};

/// Runs `gma` with `args`.
pub fn gma(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_gma")).args(args).output().expect("run gma")
}

/// Its stderr as text.
pub fn err(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).to_string()
}

/// The command failed cleanly: exit code 1, a `gma: error:` line, every fragment in the
/// message, and no panic.
pub fn refused(o: &Output, fragments: &[&str], what: &str) {
    let e = err(o);
    assert_eq!(o.status.code(), Some(1), "{what}: exit code {:?}\n{e}", o.status.code());
    assert!(e.contains("gma: error: "), "{what}: no error line\n{e}");
    assert!(!e.contains("panicked") && !e.contains("RUST_BACKTRACE"), "{what}: panic\n{e}");
    for f in fragments {
        assert!(e.contains(f), "{what}: message lacks `{f}`\n{e}");
    }
}

/// Checks that `text` is one SVG document: it opens with the one `<svg` element, every element
/// closes in order, and nothing but whitespace follows the root's `</svg>` (a figure whose
/// first panel ended the document and whose further panels were written after it is not).
pub fn one_svg_document(text: &str) -> Result<(), String> {
    if !text.starts_with("<svg") {
        return Err(format!("does not open with `<svg`: {:?}", &text[..text.len().min(60)]));
    }
    let opened = text.matches("<svg").count();
    if opened != 1 {
        return Err(format!("{opened} `<svg` elements"));
    }
    if !text.trim_end().ends_with("</svg>") {
        return Err(format!("does not end with `</svg>`: …{:?}", &text[text.len().saturating_sub(60)..]));
    }
    let mut open: Vec<&str> = Vec::new();
    let mut rest = text;
    let mut closed_root = false;
    while let Some(at) = rest.find('<') {
        if open.is_empty() && !rest[..at].trim().is_empty() {
            let junk: String = rest[..at].trim().chars().take(60).collect();
            return Err(format!("text outside the root element: {junk:?}"));
        }
        let tag_and_rest = &rest[at + 1..];
        let end = tag_and_rest.find('>').ok_or("an unterminated tag")?;
        let tag = &tag_and_rest[..end];
        rest = &tag_and_rest[end + 1..];
        if tag.starts_with('?') || tag.starts_with('!') {
            continue;
        }
        if closed_root {
            let junk: String = tag.chars().take(60).collect();
            return Err(format!("junk after the document element: <{junk}>"));
        }
        if let Some(name) = tag.strip_prefix('/') {
            match open.pop() {
                Some(top) if top == name.trim() => closed_root = open.is_empty(),
                top => return Err(format!("`</{name}>` closes {top:?}")),
            }
        } else {
            let name = tag.split(|c: char| c.is_whitespace() || c == '/').next().unwrap_or_default();
            if !tag.ends_with('/') {
                open.push(name);
            } else if open.is_empty() {
                return Err(format!("element <{name}/> outside the root"));
            }
        }
    }
    if !open.is_empty() {
        return Err(format!("unclosed elements {open:?}"));
    }
    if !rest.trim().is_empty() {
        return Err("text after the document element".into());
    }
    Ok(())
}
