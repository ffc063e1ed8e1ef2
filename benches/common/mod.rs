//! Helpers shared by the benches (each bench includes what it uses with `mod common;`).

pub mod scenes;
