//! Why a frame could not be scored.

/// Why a frame could not be scored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FrameError {
    /// The frame or the state buffer does not hold `J1 * J2` values.
    Length,
    /// Square kernels without their factor table
    /// ([`Scorer::with_factors`](crate::scorer::Scorer::with_factors)).
    Factors,
}

impl core::fmt::Display for FrameError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            FrameError::Length => "frame or state buffer of the wrong length",
            FrameError::Factors => "square kernels without their factor table",
        })
    }
}
