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

/// `text` with every number of more than 15 characters (a value such as
/// 1e300 that another crate's message wrote out in full) written as
/// [`fmt_num`] writes it.
pub fn short_numbers(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut run = String::new();
    let flush = |run: &mut String, out: &mut String| {
        match run.parse::<f64>() {
            Ok(v) if run.len() > 15 => out.push_str(&fmt_num(v)),
            _ => out.push_str(run),
        }
        run.clear();
    };
    for c in text.chars() {
        if c.is_ascii_digit() || (c == '.' && !run.is_empty()) {
            run.push(c);
        } else {
            flush(&mut run, &mut out);
            out.push(c);
        }
    }
    flush(&mut run, &mut out);
    out
}

#[cfg(test)]
mod tests {
    use super::{fmt_num, short_numbers};

    #[test]
    fn long_numbers_in_a_message_are_shortened() {
        let long = format!("radius {} mm, at 1.5 mm", 1e300);
        assert_eq!(short_numbers(&long), "radius 1e300 mm, at 1.5 mm");
        assert_eq!(short_numbers("v0.1.0, 12345"), "v0.1.0, 12345");
    }

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
