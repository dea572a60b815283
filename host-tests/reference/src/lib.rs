//! Exact f64 reference implementations.
