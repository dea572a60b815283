//! Normalisation of a raw map to a distribution (Eq. 5).

/// A map divided by its total, with the dark flag of docs/method.md §3.
#[derive(Clone, Debug, PartialEq)]
pub struct Normalised {
    /// `ã(j) = a(j) / sum_i a(i)`, or all zeros for a dark map.
    pub map: Vec<f64>,
    /// The raw map summed to 0: no light reached the detector.
    pub dark: bool,
}

/// Eq. 5: divide every cell by the map's total.
///
/// A dark map (total 0) becomes the all-zero map and is flagged, so that
/// every distance formula applies to it unchanged instead of producing NaN.
/// Raw values are expected finite and non-negative.
pub fn normalise(raw: &[f64]) -> Normalised {
    let total: f64 = raw.iter().sum();
    if total == 0.0 {
        Normalised {
            map: vec![0.0; raw.len()],
            dark: true,
        }
    } else {
        Normalised {
            map: raw.iter().map(|&a| a / total).collect(),
            dark: false,
        }
    }
}
