//! The command line's messages on standard error, all with the one prefix `[raypack]`: status
//! lines, warnings (`[raypack] warning: `) and errors (`[raypack] error: `). A status line that
//! waits for its end ("Collecting primitives... " then "Done!") is open until [`done`]; a
//! warning or error printed meanwhile first ends it, so that a message never shares a line
//! with progress.

use std::fmt::Display;
use std::sync::atomic::{AtomicBool, Ordering};

/// A status line was started and not yet ended.
static OPEN: AtomicBool = AtomicBool::new(false);

/// The prefix of every line the command prints on standard error.
pub(crate) const PREFIX: &str = "[raypack]";

/// Ends an open status line, if there is one.
fn close() {
    if OPEN.swap(false, Ordering::Relaxed) {
        eprintln!();
    }
}

/// Starts a status line that [`done`] ends: `[raypack] {what}` with no newline.
pub(crate) fn start(what: impl Display) {
    close();
    eprint!("{PREFIX} {what}");
    OPEN.store(true, Ordering::Relaxed);
}

/// Adds to the open status line (or starts one).
pub(crate) fn more(what: impl Display) {
    if OPEN.load(Ordering::Relaxed) {
        eprint!("{what}");
    } else {
        start(what);
    }
}

/// Ends the open status line with `what` (or prints it as a line of its own when a message
/// came between).
pub(crate) fn done(what: impl Display) {
    if OPEN.swap(false, Ordering::Relaxed) {
        eprintln!("{what}");
    } else {
        eprintln!("{PREFIX} ... {what}");
    }
}

/// A status line of its own.
pub(crate) fn line(what: impl Display) {
    close();
    eprintln!("{PREFIX} {what}");
}

/// A warning: `[raypack] warning: {what}` on a line of its own.
pub(crate) fn warning(what: impl Display) {
    close();
    eprintln!("{PREFIX} warning: {what}");
}

/// An error: `[raypack] error: {what}` on a line of its own.
pub(crate) fn error(what: impl Display) {
    close();
    eprintln!("{PREFIX} error: {what}");
}
