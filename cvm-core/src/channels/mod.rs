//! The channels a position is decided on, below the scorer: the gradient
//! magnitude, the power and spread channels and the flag bits. Each is a
//! leaf that needs nothing but the configuration's limits, so the scorer,
//! the engine, the protocol and the host decoder can all build on them.

pub mod flags;
pub mod magnitude;
pub mod pooled;
pub mod power;
pub mod spread;
