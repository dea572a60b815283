//! What makes a reference unfit to calibrate with, and what a user must
//! hear about a calibration that came out, but may not do what they want:
//! a threshold is only as good as the references' background.

use std::path::Path;

use anyhow::{Result, bail};

/// The fewest positions a reference has along each axis: the gradient of
/// a position needs neighbours in both directions.
pub const MIN_SIDE: usize = 2;

/// The samples of a reference: the lowest and highest.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SampleRange {
    pub lowest: u16,
    pub highest: u16,
}

/// Refuses a reference that cannot calibrate: too small to have
/// gradients, dark, saturated or constant (each gives a threshold of 1,
/// which flags every position of a real part), or whose positions all
/// score 0.
pub fn refuse_unfit(
    path: &Path,
    (rows, cols): (usize, usize),
    range: SampleRange,
    full_scale: u16,
    cvm: &[u32],
) -> Result<()> {
    let p = path.display();
    if rows < MIN_SIDE || cols < MIN_SIDE {
        bail!(
            "{p} has {rows} x {cols} positions: a reference needs at least {MIN_SIDE} x {MIN_SIDE} (neighbours in both directions)"
        );
    }
    if range.highest == 0 {
        bail!("{p} is dark (every sample is 0): it cannot calibrate; scan a lit reference part");
    }
    if range.lowest >= full_scale {
        bail!(
            "{p} is saturated (every sample at or above the full scale {full_scale}): it cannot calibrate"
        );
    }
    if range.lowest == range.highest {
        bail!(
            "{p} is constant (every sample is {}): it shows no spot and cannot calibrate",
            range.lowest
        );
    }
    if cvm.iter().all(|&m| m == 0) {
        bail!("{p}: every position scores 0 (no spot moves): it cannot calibrate");
    }
    Ok(())
}

/// Refuses a reference given twice (the same file, whatever the path): it
/// would count twice and narrow the background it stands for.
pub fn refuse_duplicate(path: &Path, earlier: &[&Path]) -> Result<()> {
    for e in earlier {
        if crate::out::input_is_output(e, path) {
            bail!(
                "{} and {} are the same file: give each reference once",
                e.display(),
                path.display()
            );
        }
    }
    Ok(())
}

/// The warning for a reference with `n` positions at or above the
/// threshold the other references give (`channel`: "CVM" or "power").
pub fn outlier_warning(path: &Path, channel: &str, n: usize, others: &str) -> Option<String> {
    (n > 0).then(|| {
        format!(
            "{}: {n} position(s) at or above the {channel} threshold the other references give ({others}): a defect in a reference raises the threshold until that defect is invisible; check that part",
            path.display()
        )
    })
}
