//! Links with cortex-m-rt's `link.x`, which includes `memory.x`: the one
//! beside this file, found in the linker's working directory (the
//! package's root).

fn main() {
    println!("cargo:rerun-if-changed=memory.x");
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rustc-link-arg-bins=--nmagic");
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
}
