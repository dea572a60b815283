//! The engine's three thresholds, and the channel subsets the experiments
//! compare.

use cvm_core::power;
use cvm_core::spread::{SPREAD_MAX, SPREAD_OFF};

/// The engine's three thresholds: CVM in the scorer's `Q(q)`, power in
/// `Q15`, spread in `Q16`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Thresholds {
    pub cvm: u32,
    pub power: u32,
    pub spread: u32,
}

impl Thresholds {
    /// Every channel measured, none firing (the spread channel measures
    /// only with a threshold other than `SPREAD_OFF`).
    pub const MEASURE: Thresholds = Thresholds {
        cvm: u32::MAX,
        power: power::POWER_OFF,
        spread: SPREAD_MAX + 1,
    };

    /// Only the CVM channel of `self`.
    pub fn cvm_only(self) -> Self {
        Thresholds {
            cvm: self.cvm,
            ..Self::MEASURE
        }
    }

    /// Only the power channel of `self`.
    pub fn power_only(self) -> Self {
        Thresholds {
            power: self.power,
            ..Self::MEASURE
        }
    }

    /// Only the spread channel of `self`.
    pub fn spread_only(self) -> Self {
        Thresholds {
            spread: self.spread,
            ..Self::MEASURE
        }
    }

    /// The CVM and power channels of `self`, the spread channel off.
    pub fn without_spread(self) -> Self {
        Thresholds {
            spread: SPREAD_OFF,
            ..self
        }
    }
}
