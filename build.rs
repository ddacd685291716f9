//! Puts `memory.x` on the linker search path for bare-metal builds (the
//! firmware example links with cortex-m-rt's `link.x`, which includes it).
//! Host builds are untouched.

use std::env;

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-changed=memory.x");
    if env::var("CARGO_CFG_TARGET_OS").as_deref() == Ok("none") {
        let dir = env::var("CARGO_MANIFEST_DIR").expect("set by cargo");
        println!("cargo:rustc-link-search={dir}");
    }
}
