//! What a scoring configuration is made of: detector geometry, kernel set,
//! weights and normalisation (docs/method.md §3).

/// Largest detector axis the core supports.
pub const MAX_J: usize = 16;
/// Largest number of detector cells (`MAX_J * MAX_J`).
pub const MAX_CELLS: usize = MAX_J * MAX_J;

/// Detector geometry `J1 x J2`; a map is stored row-major, cell `(j1, j2)`
/// (0-based) at index `j1 * J2 + j2`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Geometry {
    pub j1: u8,
    pub j2: u8,
}

impl Geometry {
    pub const fn new(j1: u8, j2: u8) -> Result<Self, ConfigError> {
        if j1 == 0 || j2 == 0 || j1 as usize > MAX_J || j2 as usize > MAX_J {
            return Err(ConfigError::Geometry);
        }
        Ok(Geometry { j1, j2 })
    }

    /// Number of detector cells `J1 * J2`.
    pub const fn cells(&self) -> usize {
        self.j1 as usize * self.j2 as usize
    }
}

/// The set of LCD kernel sizes `b` the distance sums over.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Kernels {
    /// The paper's kernels: `b = (b1, b2)` with `b_i` in `1..=min(J_i, bmax)`;
    /// `bmax = 0` means no cap (`b` ranges over `{1..J1} x {1..J2}`).
    Paper { bmax: u8 },
    /// Square kernels `b = (k, k)`, `k = 0..=kmax`, all weights 1.
    Square { kmax: u8 },
}

impl Kernels {
    /// Square kernels with the default `K = max(J1, J2) - 1`.
    pub const fn square_default(g: Geometry) -> Self {
        let m = if g.j1 > g.j2 { g.j1 } else { g.j2 };
        Kernels::Square { kmax: m - 1 }
    }
}

/// Weights `w(b)` of the paper kernels (square kernels always use 1).
// A configuration is built once, and `no_std` without allocation cannot box
// the separable variant: its size is the price of being `Copy` and `const`.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Weights {
    /// `w(b) = 1 / (n1 * n2)` with `n_i` the number of sizes on axis `i`,
    /// so that the weights sum to 1 (Eq. 9/10).
    Uniform,
    /// All weights 1 (Eq. 8).
    Unit,
    /// `w(b) = w1[b1 - 1] * w2[b2 - 1]`, non-negative and finite.
    Separable { w1: [f64; MAX_J], w2: [f64; MAX_J] },
}

/// A complete scoring configuration.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Config {
    pub geometry: Geometry,
    pub kernels: Kernels,
    pub weights: Weights,
    /// Normalise each map to unit sum (Eq. 5). Off keeps raw counts, which
    /// keeps the distance sensitive to intensity changes (absorbing defects).
    pub normalise: bool,
    /// A sample at or above this value flags the map as saturated.
    pub full_scale: u16,
}

impl Config {
    /// `i32` words of one prepared map: `J1 J2` for the paper kernels'
    /// embedding, and as many for the square kernels' (docs/method.md §4).
    pub const fn state_words(&self) -> usize {
        self.geometry.cells()
    }

    /// The paper's default: paper kernels, uniform weights, normalised maps.
    pub const fn paper(geometry: Geometry) -> Self {
        Config {
            geometry,
            kernels: Kernels::Paper { bmax: 0 },
            weights: Weights::Uniform,
            normalise: true,
            full_scale: u16::MAX,
        }
    }
}

/// Why a configuration was refused. Refusal happens once, when the tables
/// are built, never per beam.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ConfigError {
    /// An axis outside `1..=16`.
    Geometry,
    /// `kmax` above 15.
    KernelSize,
    /// A weight that is negative or not finite, or all weights zero.
    Weights,
    /// No fixed-point scaling keeps every accumulator in range.
    Range,
    /// The square kernels' factor table is too short, or a block of their
    /// quadratic form could not be factored.
    Table,
    /// A full scale of 0: every sample would flag its map saturated (the
    /// header's `fs` is 1 to 65535).
    FullScale,
}

impl core::fmt::Display for ConfigError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            ConfigError::Geometry => "detector axis outside 1..=16",
            ConfigError::KernelSize => "square kernel size K above 15",
            ConfigError::Weights => "a weight is negative or not finite, or all weights are zero",
            ConfigError::Range => "no fixed-point scaling keeps every accumulator in range",
            ConfigError::Table => "square kernels' factor table too short or not factorable",
            ConfigError::FullScale => "a full scale of 0 flags every map saturated",
        })
    }
}
