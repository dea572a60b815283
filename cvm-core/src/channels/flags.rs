//! Per-position flag bits, shared by the engine, the line protocol and the
//! host decoder.

/// No frame arrived for this position (gap, overrun, short row).
pub const NO_DATA: u8 = 1 << 0;
/// The map summed to zero; it was scored as the all-zero map.
pub const DARK: u8 = 1 << 1;
/// A sample reached the configured full scale.
pub const SATURATED: u8 = 1 << 2;
/// A score hit the top of its integer range (cannot happen for the bounds
/// the scorer proves; reported rather than hidden if it ever does).
pub const CLIPPED: u8 = 1 << 3;
/// The position is a defect by its distance gradient: `mag >= thr`.
pub const CVM_DEFECT: u8 = 1 << 4;
/// The position is a defect by its power gradient: `pmag >= pthr`.
pub const POWER_DEFECT: u8 = 1 << 5;
/// The position is a defect by its spread gradient: `smag >= sthr`.
pub const SPREAD_DEFECT: u8 = 1 << 6;
/// Any channel: the position is a defect.
pub const DEFECT: u8 = CVM_DEFECT | POWER_DEFECT | SPREAD_DEFECT;
