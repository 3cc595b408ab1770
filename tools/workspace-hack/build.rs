//! Empty: cargo resolves `[build-dependencies]` only for a package with a build script,
//! and this crate's host-side pins are build dependencies.

fn main() {}
