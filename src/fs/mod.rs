//! The file system, used safely: [`input`] is the one way raypack reads a file a user names
//! (regular files only, never blocking, size-capped) and [`output`] the one way it writes one
//! (whole or not at all, never through a link, never over an input). Every layer above may
//! use them; `tests/one_reader_one_writer.rs` checks that nothing else opens a file.

pub mod input;
pub mod output;
