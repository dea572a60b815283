//! Numbers as the commands' messages print them. Every command reports
//! values in its errors and summaries; one formatter keeps them alike.

/// A number for a message: plain when short, in exponent form when huge
/// or tiny (never 300 digits).
pub fn fmt_num(v: f64) -> String {
    let a = v.abs();
    if v == 0.0 || !v.is_finite() || (1e-4..1e12).contains(&a) {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

#[cfg(test)]
mod tests {
    use super::fmt_num;

    #[test]
    fn plain_in_the_middle_exponent_at_the_ends() {
        assert_eq!(fmt_num(0.0), "0");
        assert_eq!(fmt_num(0.5), "0.5");
        assert_eq!(fmt_num(-1e-4), "-0.0001");
        assert_eq!(fmt_num(5e-5), "5e-5");
        assert_eq!(fmt_num(1e12), "1e12");
        assert_eq!(fmt_num(999_999_999_999.0), "999999999999");
        assert_eq!(fmt_num(f64::INFINITY), "inf");
        assert_eq!(fmt_num(f64::NAN), "NaN");
    }
}
