//! Detector geometry `J1 x J2`.

use std::fmt;

/// Size of the detector array: `J1` cells on the first axis, `J2` on the
/// second, each in `1..=16` (the firmware's limit, docs/method.md §2).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Geometry {
    j1: usize,
    j2: usize,
}

/// A geometry outside `1..=16` on some axis.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct GeometryError {
    /// The rejected `J1`.
    pub j1: usize,
    /// The rejected `J2`.
    pub j2: usize,
}

impl fmt::Display for GeometryError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "detector geometry {}x{} is not supported (each axis must be 1..={})",
            self.j1,
            self.j2,
            Geometry::MAX_AXIS
        )
    }
}

impl std::error::Error for GeometryError {}

impl Geometry {
    /// Largest number of cells on one axis.
    pub const MAX_AXIS: usize = 16;

    /// A `j1 x j2` geometry; both axes must be in `1..=16`.
    pub fn new(j1: usize, j2: usize) -> Result<Self, GeometryError> {
        let ok = |j: usize| (1..=Self::MAX_AXIS).contains(&j);
        if ok(j1) && ok(j2) {
            Ok(Self { j1, j2 })
        } else {
            Err(GeometryError { j1, j2 })
        }
    }

    /// Cells on the first axis (`J1`).
    pub fn j1(&self) -> usize {
        self.j1
    }

    /// Cells on the second axis (`J2`).
    pub fn j2(&self) -> usize {
        self.j2
    }

    /// Cells on axis `0` (`J1`) or `1` (`J2`).
    ///
    /// # Panics
    /// If `axis > 1`.
    pub fn axis(&self, axis: usize) -> usize {
        match axis {
            0 => self.j1,
            1 => self.j2,
            _ => panic!("a deflection map has two axes, got axis {axis}"),
        }
    }

    /// Number of cells, `J1 * J2` (the length of a map).
    pub fn cells(&self) -> usize {
        self.j1 * self.j2
    }

    /// Row-major index of the 0-based cell `(i1, i2)`.
    pub fn index(&self, i1: usize, i2: usize) -> usize {
        i1 * self.j2 + i2
    }

    /// 0-based cell `(i1, i2)` of a row-major index.
    pub fn cell(&self, index: usize) -> (usize, usize) {
        (index / self.j2, index % self.j2)
    }

    pub(crate) fn check_map(&self, map: &[f64]) {
        assert_eq!(
            map.len(),
            self.cells(),
            "a {}x{} map has {} cells",
            self.j1,
            self.j2,
            self.cells()
        );
    }
}
