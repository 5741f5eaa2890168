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
