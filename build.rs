//! Picks the memory map and linker arguments for the selected board.
//!
//! cortex-m-rt's `link.x` does `INCLUDE memory.x`; each board's map is
//! `boards/<board>/memory.x` and only that folder goes on the linker's
//! search path. (There is deliberately no `memory.x` at the package root:
//! the linker looks in its working directory, the root, before the search
//! path, so a root file would shadow the other board's map.)
//! `defmt.x` is only passed when defmt is linked (the H743 board).

use std::env;
use std::path::PathBuf;

fn main() {
    let h743 = env::var_os("CARGO_FEATURE_H743").is_some();
    let emulated = env::var_os("CARGO_FEATURE_EMULATED").is_some();
    let board = match (h743, emulated) {
        (true, false) => "h743",
        (false, true) => "mps2-an386",
        // main.rs turns these into a clear compile_error!; keep the build
        // script quiet so that message is the one the user sees.
        _ => return,
    };

    let root =
        PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"));
    let dir = root.join("boards").join(board);
    println!("cargo:rustc-link-search={}", dir.display());
    println!("cargo:rerun-if-changed=boards");
    println!("cargo:rerun-if-changed=build.rs");

    println!("cargo:rustc-link-arg-bins=--nmagic");
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
    if h743 {
        println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
    }
}
