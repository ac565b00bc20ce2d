//! The program of `tools/dependent-check` built inside the project (its release profile), for
//! `tools/dependent-check/run.sh` to time against the same source built as a dependent crate.
include!("../dependent-check/src/main.rs");
