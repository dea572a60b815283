#![no_std]
//! Fixed-point CVM defect scoring of deflection maps (work in progress).
