//! No code: this crate only pins dependency features so that the workspace's builds with
//! and without the optional features share their compiled dependencies. See its
//! `Cargo.toml` for why and how to keep it up to date.
