//! Where the repository is, found when `dmap` runs rather than where it
//! was built: `dmap twin` and `dmap emulate` build the firmware from its
//! sources and run the chip model from `host-tests/twin`, and a copied or
//! installed `dmap` must use the checkout it is run in, not the one it was
//! compiled in.

use anyhow::{Context, Result, anyhow, bail};
use clap::Args;
use std::path::{Path, PathBuf};

#[derive(Args, Clone, Debug, Default)]
pub struct RepoArgs {
    /// The repository (the firmware's sources and host-tests/twin); default:
    /// $CVM_REPO, else the first folder from the current one upwards that
    /// holds build.rs, Cargo.toml and host-tests/twin/h743twin
    #[arg(long, value_name = "DIR")]
    pub repo: Option<PathBuf>,
}

impl RepoArgs {
    /// The repository's root.
    pub fn root(&self) -> Result<PathBuf> {
        find(self.repo.as_deref())
    }
}

/// The repository: `given` (`--repo`), else `CVM_REPO`, else the current
/// directory or the nearest folder above it that is one.
pub fn find(given: Option<&Path>) -> Result<PathBuf> {
    if let Some(dir) = given {
        return checked(dir, "--repo");
    }
    if let Some(dir) = std::env::var_os("CVM_REPO").filter(|v| !v.is_empty()) {
        return checked(Path::new(&dir), "CVM_REPO");
    }
    let here = std::env::current_dir().context("reading the current directory")?;
    here.ancestors()
        .find(|d| is_repo(d))
        .map(Path::to_path_buf)
        .ok_or_else(|| {
            anyhow!(
                "cannot find the repository from {} upwards (a folder with build.rs, Cargo.toml and host-tests/twin/h743twin): run dmap inside the checkout, or give --repo DIR or CVM_REPO=DIR",
                here.display()
            )
        })
}

fn is_repo(dir: &Path) -> bool {
    dir.join("build.rs").is_file()
        && dir.join("Cargo.toml").is_file()
        && dir.join("host-tests/twin/h743twin/__main__.py").is_file()
}

fn checked(dir: &Path, from: &str) -> Result<PathBuf> {
    if !is_repo(dir) {
        bail!(
            "{from} {}: not the repository (no build.rs, Cargo.toml and host-tests/twin/h743twin there)",
            dir.display()
        );
    }
    Ok(dir.to_path_buf())
}
