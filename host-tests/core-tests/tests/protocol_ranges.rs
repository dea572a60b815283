//! Each field's range, as docs/protocol.md gives it: a line whose fields
//! parse but one of which is outside its range is refused as a whole with
//! `ParseError::Range`, naming the field, however right its CRC; the
//! values at each end of a range are accepted. The lines are written by
//! hand from the document's examples, independent of the encoder.

use cvm_core::protocol::{self, Line, ParseError, Q_MAX, Q_MIN, crc16};

/// `body*XXXX\n` with the body's checksum.
fn sealed(body: &str) -> Vec<u8> {
    format!("{body}*{:04X}\n", crc16(body.as_bytes())).into_bytes()
}

/// The header of the document's first example with `key` set to `value`.
fn header_with(key: &str, value: &str) -> Vec<u8> {
    let fields = [
        ("v", protocol::VERSION.to_string()),
        ("fw", "0.1.0".into()),
        ("j", "15x15".into()),
        ("cols", "300".into()),
        ("k", "P".into()),
        ("b", "0".into()),
        ("w", "uniform".into()),
        ("norm", "1".into()),
        ("fs", "65535".into()),
        ("thr", "4194304".into()),
        ("pthr", "3277".into()),
        ("sthr", "4294967295".into()),
        ("q", "23".into()),
        ("scores", "0".into()),
        ("dcap", "0".into()),
        ("rst", "por".into()),
        ("boots", "1".into()),
        ("rows", "300".into()),
        ("src", "d".repeat(16)),
        ("store", "none".into()),
    ];
    let body: Vec<String> = fields
        .iter()
        .map(|(k, v)| {
            let v = if *k == key { value } else { v.as_str() };
            format!("{k}={v}")
        })
        .collect();
    sealed(&format!("H,{}", body.join(",")))
}

fn range_error(line: &[u8]) -> Option<&'static str> {
    match protocol::parse(line) {
        Err(ParseError::Range(what)) => Some(what),
        _ => None,
    }
}

#[test]
fn header_fields_out_of_range_are_refused() {
    let refused = [
        ("j", "0x0", "j: each axis 1 to 16"),
        ("j", "0x15", "j: each axis 1 to 16"),
        ("j", "17x17", "j: each axis 1 to 16"),
        ("j", "99x99", "j: each axis 1 to 16"),
        ("q", "63", "q: -120 to 62"),
        ("q", "99", "q: -120 to 62"),
        ("q", "-121", "q: -120 to 62"),
        ("fs", "0", "fs: 1 to 65535"),
        ("cols", "0", "cols: at least 1"),
        ("boots", "0", "boots: at least 1"),
        ("w", "triangular", "w: uniform, unit or separable"),
        ("fw", "0123456789012345678901234", "fw: at most 24"),
        ("fw", "a b", "fw: at most 24"),
        ("norm", "2", "norm: 0 or 1"),
        ("scores", "01", "scores: 0 or 1"),
    ];
    for (key, value, what) in refused {
        let line = header_with(key, value);
        let got = range_error(&line);
        assert!(
            got.is_some_and(|w| w.starts_with(what)),
            "{key}={value}: {got:?}"
        );
    }
    // Square kernels: K at most 15, unit weights only.
    let square = |b: &str, w: &str| {
        let l = String::from_utf8(header_with("k", "S")).unwrap();
        let body = l.split('*').next().unwrap();
        let body = body
            .replace(",b=0,", &format!(",b={b},"))
            .replace(",w=uniform,", &format!(",w={w},"));
        sealed(&body)
    };
    assert!(matches!(
        protocol::parse(&square("15", "unit")),
        Ok(Line::Header(_))
    ));
    assert_eq!(
        range_error(&square("16", "unit")),
        Some("b: 0 to 15 with square kernels")
    );
    assert!(range_error(&square("3", "uniform")).is_some_and(|w| w.starts_with("w: ")));
    // The ends of each range are accepted.
    let q_min = Q_MIN.to_string();
    let q_max = Q_MAX.to_string();
    let fw24 = "x".repeat(24);
    for (key, value) in [
        ("j", "1x16"),
        ("j", "16x1"),
        ("q", q_min.as_str()),
        ("q", q_max.as_str()),
        ("q", "0"),
        ("fs", "1"),
        ("cols", "1"),
        ("boots", "4294967295"),
        ("fw", fw24.as_str()),
        ("w", "separable"),
        ("norm", "0"),
        ("sthr", "0"),
        ("sthr", "92680"),
        // Above a channel's largest magnitude: off, as 4294967295 is
        // (docs/protocol.md, "Field ranges"), and no damage.
        ("sthr", "92681"),
        ("sthr", "4294967294"),
        ("pthr", "46341"),
        ("pthr", "4294967294"),
    ] {
        assert!(
            matches!(
                protocol::parse(&header_with(key, value)),
                Ok(Line::Header(_))
            ),
            "{key}={value}"
        );
    }
    assert_eq!((Q_MIN, Q_MAX), (-120, 62));
}

#[test]
fn row_defect_and_object_fields_out_of_range_are_refused() {
    // D,row,col,mag,pmag,smag,strength,flags and
    // O,id,row0,row1,col0,col1,area,peak,peak_row,peak_col,peak_mag,
    // peak_power,peak_spread,centroid_row_q8,centroid_col_q8,channels
    let refused = [
        ("R,7,5035553,141,46341,142,3,3,1,1,1", "pmax: 0 to 46340"),
        ("D,7,142,1200000,46341,0,99993,32", "pmag: 0 to 46340"),
        ("D,7,142,1200000,5000,92681,99993,32", "smag: 0 to 92680"),
        (
            "D,7,142,1200000,5000,0,65535,32",
            "strength: at least 65536",
        ),
        ("D,7,142,1200000,5000,0,99993,0", "flags: "),
        ("D,7,142,1200000,5000,0,99993,4", "flags: "),
        ("D,7,142,1200000,5000,0,99993,17", "flags: "),
        ("D,7,142,1200000,5000,0,99993,22", "flags: "),
        ("D,7,142,1200000,5000,0,99993,128", "flags: "),
        ("D,7,142,1200000,5000,0,99993,144", "flags: "),
        (
            "O,0,6,8,139,143,0,99993,7,142,1200000,5000,0,1801,36157,48",
            "area: at least 1",
        ),
        (
            "O,0,6,8,139,143,11,65535,7,142,1200000,5000,0,1801,36157,48",
            "peak: at least 65536",
        ),
        (
            "O,0,6,8,139,143,11,99993,7,142,1200000,46341,0,1801,36157,48",
            "peak_power: 0 to 46340",
        ),
        (
            "O,0,6,8,139,143,11,99993,7,142,1200000,5000,92681,1801,36157,64",
            "peak_spread: 0 to 92680",
        ),
        (
            "O,0,6,8,139,143,11,99993,7,142,1200000,5000,0,1801,36157,0",
            "channels: a sum of 16, 32 and 64",
        ),
    ];
    for (body, what) in refused {
        let got = range_error(&sealed(body));
        assert!(got.is_some_and(|w| w.starts_with(what)), "{body}: {got:?}");
    }
    for body in [
        "R,7,5035553,141,46340,142,3,3,1,1,1",
        "R,7,0,-,0,-,0,0,300,0,0",
        "D,7,142,1200000,46340,0,65536,32",
        "D,7,141,5035553,1800,0,78680,20",
        "D,7,141,4294967295,1800,0,78680,58",
        "D,7,140,1200000,5000,92680,99993,64",
        "D,7,140,4294967295,46340,92680,99993,122",
        "O,0,6,8,139,143,1,65536,7,142,1200000,46340,0,1801,36157,16",
        "O,0,6,8,139,143,1,65536,7,142,1200000,46340,92680,1801,36157,112",
    ] {
        assert!(protocol::parse(&sealed(body)).is_ok(), "{body}");
    }
}

/// One position of an `S` line: 12 base-64 digits of
/// `flags · 2^65 + smag · 2^48 + pmag · 2^32 + mag`, written here from the
/// document (in a `u128`).
fn position(flags: u64, smag: u64, pmag: u64, mag: u64) -> String {
    const B64: &[u8] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789-_";
    let v = (u128::from(flags) << 65)
        | (u128::from(smag) << 48)
        | (u128::from(pmag) << 32)
        | u128::from(mag);
    (0..12)
        .map(|i| B64[((v >> (6 * (11 - i))) & 63) as usize] as char)
        .collect()
}

#[test]
fn score_positions_out_of_range_are_refused() {
    let max = u64::from(u32::MAX);
    let refused = [
        (1, 0, 0, 1),      // no data, yet a magnitude
        (1, 0, 1, 0),      // no data, yet a power magnitude
        (1, 1, 0, 0),      // no data, yet a spread magnitude
        (3, 0, 0, 0),      // no data and dark
        (17, 0, 0, 0),     // no data and a defect
        (0, 0, 46341, 0),  // power above its largest value
        (0, 92681, 0, 0),  // spread above its largest value
        (0, 131071, 0, 0), // the largest 17-bit spread
        (6, 0, 0, 0),      // dark and saturated
        (8 | 16, 0, 0, 5), // clipped below the top
        (16, 0, 0, max),   // the top, not clipped
        (8, 0, 0, max),    // clipped, not a distance defect
    ];
    for (flags, smag, pmag, mag) in refused {
        let body = format!(
            "S,0,0,{}{}",
            position(0, 0, 0, 7),
            position(flags, smag, pmag, mag)
        );
        let got = range_error(&sealed(&body));
        assert!(
            got.is_some_and(|w| w.starts_with("a position of an S line")),
            "{flags} {smag} {pmag} {mag}: {got:?}"
        );
    }
    for (flags, smag, pmag, mag) in [
        (1, 0, 0, 0),
        (2, 0, 46340, 0),
        (4 | 32, 0, 3000, 9),
        (64, 92680, 0, 0),
        (8 | 16, 0, 0, max),
        (8 | 16 | 32 | 64 | 2, 92680, 46340, max),
    ] {
        let body = format!("S,0,0,{}", position(flags, smag, pmag, mag));
        let line = sealed(&body);
        let Ok(Line::Scores { chars, .. }) = protocol::parse(&line) else {
            panic!("{flags} {smag} {pmag} {mag}");
        };
        let v = protocol::decode_score(chars).unwrap();
        assert_eq!(
            (
                u64::from(v.flags),
                u64::from(v.smag),
                u64::from(v.pmag),
                u64::from(v.mag)
            ),
            (flags, smag, pmag, mag)
        );
    }
    // The document's examples.
    assert_eq!(position(0, 0, 0, 1), "AAAAAAAAAAAB");
    assert_eq!(position(0, 0, 100, 120000), "AAAAAGQAAdTA");
    assert_eq!(position(20, 0, 1800, 5035553), "KAAABwgATNYh");
    // The spread defect of the vector good-spread: flags 64 and smag
    // 14554 make the top 24 bits 8 403 162 = 32, 3, 35, 26 in base 64.
    assert_eq!(position(64, 14554, 22, 5984663), "gDjaABYAW1GX");
}
