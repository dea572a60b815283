//! Value parsers shared by the subcommands' options: clap calls them, so a
//! bad value is a usage error (status 2) that names the option.
//!
//! Comma-separated lists (`--crop R0,C0,H,W`, `--center-mm X,Y`, ...) are
//! split by clap (`value_delimiter = ','`); the parsers here read one
//! element each. A repeatable list option (`--bubble X,Y,Z,R` once per
//! bubble) reads each occurrence with [`finite_f64s`] instead: clap 4's
//! derive keeps delimited values per occurrence (`Vec<Vec<T>>`) only behind
//! its `unstable-v5` feature, and flattened they would lose which bubble a
//! number belongs to. The caller checks how many values a list has.

/// A component of a gradient image (rows x cols x 3, as `dmap score`
/// writes it): `--component` of `render` and `eval`. Its index (0, 1, 2)
/// is taken too, as `--channel` took it before.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Component {
    /// The horizontal gradient, [..., 0]
    #[value(alias = "0")]
    Horizontal,
    /// The vertical gradient, [..., 1]
    #[value(alias = "1")]
    Vertical,
    /// Their magnitude, [..., 2]
    #[value(alias = "2")]
    Magnitude,
}

impl Component {
    /// Its index in the image's last axis.
    pub fn index(self) -> usize {
        self as usize
    }
}

/// Largest detector axis: what the scorers take.
pub const MAX_AXIS: usize = 16;

/// A detector geometry `J1xJ2` (`x` or `X`), each axis `1..=16`: `15x15`.
pub fn j1xj2(s: &str) -> Result<(usize, usize), String> {
    let bad = || format!("expected J1xJ2 with each axis in 1..={MAX_AXIS}, e.g. 15x15");
    let (a, b) = s.split_once(['x', 'X']).ok_or_else(bad)?;
    let axis = |t: &str| {
        t.trim()
            .parse::<usize>()
            .ok()
            .filter(|n| (1..=MAX_AXIS).contains(n))
            .ok_or_else(bad)
    };
    Ok((axis(a)?, axis(b)?))
}

/// One element of a list of numbers: a finite number (spaces around it allowed).
pub fn finite_f64(s: &str) -> Result<f64, String> {
    s.trim()
        .parse::<f64>()
        .ok()
        .filter(|x| x.is_finite())
        .ok_or_else(|| "expected a finite number".to_string())
}

/// One occurrence of a repeatable list option: comma-separated finite
/// numbers, each read by [`finite_f64`].
pub fn finite_f64s(s: &str) -> Result<Vec<f64>, String> {
    s.split(',')
        .map(|t| finite_f64(t).map_err(|e| format!("'{}': {e}", t.trim())))
        .collect()
}

/// One element of a list of counts or indices: a whole number `>= 0`
/// (spaces around it allowed).
pub fn index(s: &str) -> Result<usize, String> {
    s.trim()
        .parse::<usize>()
        .map_err(|_| "expected a whole number >= 0".to_string())
}

/// One element of a list of names: the text without the spaces around it.
pub fn trimmed(s: &str) -> Result<String, String> {
    Ok(s.trim().to_string())
}

/// A finite number above 0 (a pitch in µm).
pub fn positive_f64(s: &str) -> Result<f64, String> {
    s.trim()
        .parse::<f64>()
        .ok()
        .filter(|v| v.is_finite() && *v > 0.0)
        .ok_or_else(|| "expected a finite number above 0".to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn j1xj2_takes_each_axis_1_to_16() {
        assert_eq!(j1xj2("15x15"), Ok((15, 15)));
        assert_eq!(j1xj2("1X16"), Ok((1, 16)));
        assert_eq!(j1xj2(" 9 x 7 "), Ok((9, 7)));
        for bad in ["0x3", "17x3", "3x17", "15", "ax9", "9by9", "x", "-1x3", ""] {
            let e = j1xj2(bad).unwrap_err();
            assert!(e.contains("J1xJ2") && e.contains("1..=16"), "{bad}: {e}");
        }
    }

    #[test]
    fn list_elements() {
        assert_eq!(finite_f64(" -2.5"), Ok(-2.5));
        assert!(finite_f64("nan").is_err());
        assert!(finite_f64("inf").is_err());
        assert!(finite_f64("").is_err());
        assert_eq!(finite_f64s("1, -2,3e-1"), Ok(vec![1.0, -2.0, 0.3]));
        assert_eq!(
            finite_f64s("1,,3").unwrap_err(),
            "'': expected a finite number"
        );
        assert_eq!(
            finite_f64s("1,x").unwrap_err(),
            "'x': expected a finite number"
        );
        assert_eq!(index(" 3 "), Ok(3));
        assert!(index("-1").is_err());
        assert!(index("1.5").is_err());
        assert_eq!(trimmed(" CVM "), Ok("CVM".to_string()));
    }
}
