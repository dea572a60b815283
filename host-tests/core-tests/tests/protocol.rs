//! The line protocol: CRC, encode/parse round trips, corruption detection,
//! line length bounds.

use cvm_core::protocol::{
    self, HeaderInfo, Line, LineSink, MAX_LINE, Origin, ParseError, Priority, ResetCause, crc16,
    decode_score, encode_end, encode_header, encode_row, encode_score,
};
use cvm_core::settings::{KEYS, Source, Store};
use cvm_core::{PositionScore, RowSummary, RowView, Totals};
use proptest::prelude::*;

#[derive(Default)]
struct Lines(Vec<(Vec<u8>, Priority)>);
impl LineSink for Lines {
    fn line(&mut self, line: &[u8], p: Priority) {
        self.0.push((line.to_vec(), p));
    }
}

#[test]
fn crc_is_ccitt_false() {
    // The catalogued check value of CRC-16/CCITT-FALSE.
    assert_eq!(crc16(b"123456789"), 0x29B1);
    assert_eq!(crc16(b""), 0xFFFF);
}

fn header(fw: &'static str, q: i32) -> HeaderInfo<'static> {
    HeaderInfo {
        version: protocol::VERSION,
        firmware: fw,
        j1: 15,
        j2: 9,
        cols: 300,
        kernels: b'P',
        kernel_size: 0,
        weights: "uniform",
        normalise: true,
        full_scale: 65535,
        threshold: 12345,
        power_threshold: 3277,
        spread_threshold: 1241,
        q,
        scores: true,
        max_defect_lines: 16,
        reset_cause: ResetCause::Watchdog,
        boots: 3,
        origin: Some(Origin {
            rows: 200,
            sources: SOURCES,
            store: Store::Loaded,
        }),
    }
}

/// Every source somewhere, in an order no default would give.
const SOURCES: [Source; KEYS] = {
    let mut s = [Source::Flash; KEYS];
    s[0] = Source::Changed;
    s[3] = Source::Default;
    s[KEYS - 1] = Source::Changed;
    s
};

#[test]
fn header_origin_is_written_as_specified_and_version_5_still_reads() {
    let mut s = Lines::default();
    encode_header(&header("fw", 23), &mut s);
    let line = String::from_utf8(s.0[0].0.clone()).unwrap();
    let src = format!("cffd{}c", "f".repeat(KEYS - 5));
    let want_tail = format!(",rst=wdg,boots=3,rows=200,src={src},store=ok*");
    assert!(line.contains(&want_tail), "{line}");
    assert!(line.starts_with("H,v=7,"), "{line}");
    assert!(line.contains(",pthr=3277,sthr=1241,q=23,"), "{line}");
    // A version 5 header: no origin fields, and none may follow boots.
    let v5 = "H,v=5,fw=0.1.0,j=15x15,cols=300,k=P,b=0,w=uniform,norm=1,fs=65535,thr=4194304,pthr=3277,q=23,scores=0,dcap=0,rst=por,boots=1";
    let framed = |body: &str| format!("{body}*{:04X}\n", crc16(body.as_bytes())).into_bytes();
    let v5_line = framed(v5);
    let Ok(Line::Header(h)) = protocol::parse(&v5_line) else {
        panic!("version 5 header refused")
    };
    assert_eq!((h.version, h.origin, h.boots), (5, None, 1));
    let v6_short = v5.replace("v=5", "v=6");
    assert!(
        protocol::parse(&framed(&v6_short)).is_err(),
        "version 6 needs its origin"
    );
    // Version 6 had 15 settings (no `sthr`): 15 `src` letters.
    let d = "d".repeat(KEYS);
    let v6_letters = "d".repeat(KEYS - 1);
    let short = "d".repeat(KEYS - 2);
    for bad in [
        format!(",rows=1,src={short},store=none"),
        format!(",rows=1,src={short}x,store=none"),
        format!(",rows=1,src={d},store=none"),
        format!(",rows=1,src={v6_letters},store=maybe"),
        format!(",rows=1,src={v6_letters}"),
        format!(",rows=x,src={v6_letters},store=none"),
    ] {
        let l = format!("{v6_short}{bad}");
        assert!(protocol::parse(&framed(&l)).is_err(), "{l}");
    }
    let good = format!("{v6_short},rows=1,src={v6_letters},store=none");
    let good_line = framed(&good);
    let Ok(Line::Header(h)) = protocol::parse(&good_line) else {
        panic!("version 6 header refused: {good}")
    };
    // Before version 7 there is no spread channel: it reads as off.
    assert_eq!(h.spread_threshold, cvm_core::spread::SPREAD_OFF);
    // From version 7 on `sthr` follows `pthr`, and must.
    let v7 = good
        .replace("v=6", "v=7")
        .replace(&format!("src={v6_letters},"), &format!("src={d},"));
    assert!(protocol::parse(&framed(&v7)).is_err(), "{v7}");
    let v7 = v7.replace(",pthr=3277,", ",pthr=3277,sthr=665,");
    let v7_line = framed(&v7);
    let Ok(Line::Header(h)) = protocol::parse(&v7_line) else {
        panic!("version 7 header refused: {v7}")
    };
    assert_eq!((h.version, h.spread_threshold), (7, 665));
}

#[test]
fn header_round_trip() {
    for (q, cause) in [-40, 0, 23, 62, 1].into_iter().zip(ResetCause::ALL) {
        let mut s = Lines::default();
        let h = HeaderInfo {
            reset_cause: cause,
            ..header("0.1.0", q)
        };
        encode_header(&h, &mut s);
        let (line, p) = &s.0[0];
        assert_eq!(*p, Priority::Keep);
        assert!(line.ends_with(b"\n"));
        assert_eq!(protocol::parse(line), Ok(Line::Header(h)));
    }
}

/// A position as the engine can score it (docs/protocol.md, "A position's
/// rules" of the `S` line): without data nothing else; with data a power magnitude
/// of at most 46340, a spread magnitude of at most 92680, not both DARK
/// and SATURATED, CLIPPED (and then a
/// distance defect) exactly at the top magnitude, a defect's strength at
/// least 65536. Values outside are refused (`protocol_ranges.rs`).
fn arb_score() -> impl Strategy<Value = PositionScore> {
    use cvm_core::flags::{CLIPPED, CVM_DEFECT, DARK, DEFECT, NO_DATA, SATURATED};
    (
        any::<u32>(),
        any::<u32>(),
        prop_oneof![any::<u32>(), Just(u32::MAX)],
        any::<u32>(),
        0u16..=46340,
        prop_oneof![0u32..=92680, Just(92680u32)],
        0u8..128,
    )
        .prop_map(|(g0, g1, mag, strength, pmag, smag, mut flags)| {
            if flags & NO_DATA != 0 {
                return PositionScore {
                    flags: NO_DATA,
                    ..Default::default()
                };
            }
            if flags & (DARK | SATURATED) == DARK | SATURATED {
                flags &= !SATURATED;
            }
            flags &= !CLIPPED;
            if mag == u32::MAX {
                flags |= CLIPPED | CVM_DEFECT;
            }
            let strength = if flags & DEFECT != 0 {
                strength.max(1 << 16)
            } else {
                0
            };
            PositionScore {
                g0,
                g1,
                mag,
                strength,
                pmag,
                smag,
                flags,
                ..Default::default()
            }
        })
}

proptest! {
    #[test]
    fn score_encoding_round_trips(s in arb_score()) {
        let want = protocol::ScoreValue { mag: s.mag, pmag: s.pmag, smag: s.smag, flags: s.flags };
        prop_assert_eq!(decode_score(&encode_score(&s)), Some(want));
    }

    /// Row, defect and score lines decode to what was encoded, and only
    /// score lines are droppable.
    #[test]
    fn row_lines_round_trip(row in any::<u32>(), scores in prop::collection::vec(arb_score(), 1..100), thr in any::<u32>(), max_def in 0u16..5) {
        // A defect: data, and a channel's decision bit (bits 4, 5 and 6).
        let mut defects: Vec<usize> = (0..scores.len()).filter(|&c| scores[c].flags & 1 == 0 && scores[c].flags & 0x70 != 0).collect();
        let summary = RowSummary { row, max: 77, argmax: Some(3), pmax: 4000, pargmax: Some(1), defects: defects.len() as u32, no_data: 1, dark: 2, saturated: 3 };
        let view = RowView { summary, scores: &scores, threshold: thr, power_threshold: 3000 };
        let mut s = Lines::default();
        encode_row(&view, max_def, true, &mut s);
        let mut got_scores = vec![None; scores.len()];
        let mut got_defects = Vec::new();
        for (line, p) in &s.0 {
            prop_assert!(line.len() <= MAX_LINE);
            match protocol::parse(line).unwrap() {
                Line::Row { summary: got, listed } => {
                    prop_assert_eq!(got, summary);
                    prop_assert_eq!(listed as usize, defects.len().min(max_def as usize));
                    prop_assert_eq!(*p, Priority::Keep);
                }
                Line::Defect { row: r, col, mag, pmag, smag, strength, flags } => {
                    prop_assert_eq!(r, row);
                    prop_assert_eq!(mag, scores[col as usize].mag);
                    prop_assert_eq!(pmag, scores[col as usize].pmag);
                    prop_assert_eq!(smag, scores[col as usize].smag);
                    prop_assert_eq!(strength, scores[col as usize].strength);
                    prop_assert_eq!(flags, scores[col as usize].flags);
                    got_defects.push(col as usize);
                    prop_assert_eq!(*p, Priority::Keep);
                }
                Line::Scores { row: r, col0, chars } => {
                    prop_assert_eq!(r, row);
                    for (k, c) in chars.chunks(12).enumerate() {
                        got_scores[col0 as usize + k] = decode_score(c);
                    }
                    prop_assert_eq!(*p, Priority::Droppable);
                }
                other => prop_assert!(false, "unexpected line {:?}", other),
            }
        }
        // The strongest defects, strongest first, equal strengths leftmost first.
        defects.sort_by_key(|&c| (std::cmp::Reverse(scores[c].strength), c));
        prop_assert_eq!(&got_defects[..], &defects[..defects.len().min(max_def as usize)]);
        let want: Vec<_> = scores.iter().map(|s| Some(protocol::ScoreValue { mag: s.mag, pmag: s.pmag, smag: s.smag, flags: s.flags })).collect();
        prop_assert_eq!(got_scores, want);
    }

    #[test]
    fn end_line_round_trips(v in prop::collection::vec(any::<u32>(), 14)) {
        let t = Totals { rows: v[0], frames: v[1], missing: v[2], dark: v[3], saturated: v[4], defects: v[5], objects: v[12], unobjected: v[13], rejected: v[6], extra: v[7], bad: v[8], clipped: v[9], misplaced: v[10] };
        let mut s = Lines::default();
        let verdict = cvm_core::Verdict::ALL[v[0] as usize % cvm_core::Verdict::ALL.len()];
        encode_end(&t, v[11], verdict, &mut s);
        prop_assert!(s.0[0].0.len() <= MAX_LINE);
        prop_assert_eq!(protocol::parse(&s.0[0].0), Ok(Line::End(protocol::EndInfo { totals: t, dropped: v[11], verdict })));
    }

    /// Any object the labeller can close (rows and columns in order, a
    /// channel among the decision bits) decodes to itself; the parser sits
    /// beside the encoder, so the two cannot drift apart unnoticed.
    #[test]
    fn object_line_round_trips(v in prop::collection::vec(any::<u32>(), 10), power in 0u16..=46340, spread in 0u32..=92680, cr in any::<u64>(), cc in any::<u64>(), channels in 1u8..8) {
        let o = cvm_core::Object {
            id: v[0],
            row0: v[1].min(v[2]),
            row1: v[1].max(v[2]),
            col0: v[3].min(v[4]),
            col1: v[3].max(v[4]),
            area: v[5].max(1),
            peak: v[6].max(1 << 16),
            peak_row: v[7],
            peak_col: v[8],
            peak_mag: v[9],
            peak_power: power,
            peak_spread: spread,
            channels: channels << 4,
            centroid_row_q8: cr,
            centroid_col_q8: cc,
        };
        let mut s = Lines::default();
        protocol::encode_object(&o, &mut s);
        let (line, p) = &s.0[0];
        prop_assert_eq!(*p, Priority::Keep);
        prop_assert!(line.len() <= MAX_LINE);
        prop_assert_eq!(protocol::parse(line), Ok(Line::Object(o)));
    }

    /// Changing any one byte of a line (its newline aside, which delimits
    /// lines in the stream) is detected: CRC-16 catches every error burst
    /// of up to 16 bits, and a damaged trailer fails its own syntax.
    #[test]
    fn any_single_byte_change_is_detected(row in any::<u32>(), scores in prop::collection::vec(arb_score(), 1..40), pos in any::<prop::sample::Index>(), byte in any::<u8>()) {
        let summary = RowSummary { row, max: 1, argmax: None, pmax: 7, pargmax: None, defects: 0, no_data: 0, dark: 0, saturated: 0 };
        let view = RowView { summary, scores: &scores, threshold: u32::MAX, power_threshold: u32::MAX };
        let mut s = Lines::default();
        encode_row(&view, 0, true, &mut s);
        for (line, _) in &s.0 {
            let i = pos.index(line.len() - 1);
            prop_assume!(line[i] != byte);
            let mut bad = line.clone();
            bad[i] = byte;
            prop_assert!(protocol::parse(&bad).is_err(), "undetected: {:?}", String::from_utf8_lossy(&bad));
        }
    }

    /// A line with one field more than its type has, under a valid
    /// checksum, is refused; sealed again as it was, it parses.
    #[test]
    fn an_extra_field_is_refused(row in any::<u32>(), scores in prop::collection::vec(arb_score(), 1..40), extra in "[0-9a-z=]{0,6}") {
        let summary = RowSummary { row, max: 1, argmax: Some(0), pmax: 7, pargmax: None, defects: 0, no_data: 0, dark: 0, saturated: 0 };
        let view = RowView { summary, scores: &scores, threshold: u32::MAX, power_threshold: u32::MAX };
        let mut s = Lines::default();
        encode_row(&view, 0, true, &mut s);
        let seal = |body: &[u8]| {
            let mut l = body.to_vec();
            l.extend_from_slice(format!("*{:04X}\n", protocol::crc16(body)).as_bytes());
            l
        };
        for (line, _) in &s.0 {
            let body = &line[..line.iter().position(|&b| b == b'*').unwrap()];
            let again = seal(body);
            prop_assert!(protocol::parse(line).is_ok());
            prop_assert_eq!(protocol::parse(&again), protocol::parse(line));
            let longer = seal(&[body, b",", extra.as_bytes()].concat());
            prop_assert_eq!(protocol::parse(&longer).err(), Some(ParseError::Format), "{}", String::from_utf8_lossy(&longer));
        }
    }

    /// Truncated lines never parse.
    #[test]
    fn truncation_is_detected(scores in prop::collection::vec(arb_score(), 1..40), cut in any::<prop::sample::Index>()) {
        let summary = RowSummary { row: 3, max: 1, argmax: Some(0), pmax: 1, pargmax: Some(0), defects: 0, no_data: 0, dark: 0, saturated: 0 };
        let view = RowView { summary, scores: &scores, threshold: u32::MAX, power_threshold: u32::MAX };
        let mut s = Lines::default();
        encode_row(&view, 0, true, &mut s);
        for (line, _) in &s.0 {
            let body = &line[..line.len() - 1];
            let k = cut.index(body.len());
            prop_assert!(protocol::parse(&body[..k]).is_err());
        }
    }
}

/// The longest lines the encoder can write stay within MAX_LINE.
#[test]
fn worst_case_lines_fit() {
    let mut s = Lines::default();
    let mut h = header("a-very-long-firmware-version-string-that-gets-cut", -120);
    h.cols = u32::MAX;
    h.threshold = u32::MAX;
    h.power_threshold = u32::MAX;
    h.weights = "separable";
    h.max_defect_lines = u16::MAX;
    h.reset_cause = ResetCause::Other;
    h.boots = u32::MAX;
    encode_header(&h, &mut s);
    let scores = vec![
        PositionScore {
            g0: u32::MAX,
            g1: u32::MAX,
            mag: u32::MAX,
            strength: u32::MAX,
            p0: u16::MAX,
            p1: u16::MAX,
            // The widest values in range: five digits, two-digit flags.
            pmag: 46340,
            flags: 60,
            // The lines do not carry the spread channel yet.
            ..PositionScore::default()
        };
        64
    ];
    let summary = RowSummary {
        row: u32::MAX,
        max: u32::MAX,
        argmax: Some(u32::MAX),
        pmax: 46340,
        pargmax: Some(u32::MAX),
        defects: u32::MAX,
        no_data: u32::MAX,
        dark: u32::MAX,
        saturated: u32::MAX,
    };
    encode_row(
        &RowView {
            summary,
            scores: &scores,
            threshold: 0,
            power_threshold: 0,
        },
        u16::MAX,
        true,
        &mut s,
    );
    let t = Totals {
        rows: u32::MAX,
        frames: u32::MAX,
        missing: u32::MAX,
        dark: u32::MAX,
        saturated: u32::MAX,
        defects: u32::MAX,
        objects: u32::MAX,
        unobjected: u32::MAX,
        rejected: u32::MAX,
        extra: u32::MAX,
        bad: u32::MAX,
        clipped: u32::MAX,
        misplaced: u32::MAX,
    };
    // The longest verdict.
    encode_end(
        &t,
        u32::MAX,
        cvm_core::Verdict::Fault(cvm_core::Fault::Misplaced),
        &mut s,
    );
    let o = cvm_core::Object {
        id: u32::MAX,
        row0: u32::MAX,
        row1: u32::MAX,
        col0: u32::MAX,
        col1: u32::MAX,
        area: u32::MAX,
        peak: u32::MAX,
        peak_row: u32::MAX,
        peak_col: u32::MAX,
        peak_mag: u32::MAX,
        peak_power: 46340,
        peak_spread: 92680,
        channels: 0x70,
        centroid_row_q8: u64::from(u32::MAX) << 8,
        centroid_col_q8: u64::from(u32::MAX) << 8,
    };
    protocol::encode_object(&o, &mut s);
    assert_eq!(protocol::parse(&s.0.last().unwrap().0), Ok(Line::Object(o)));
    for (line, _) in &s.0 {
        assert!(line.len() <= MAX_LINE, "{} bytes", line.len());
        // A queue reserves MAX_ROW_LINE for each line of a row.
        if !matches!(line[0], b'H' | b'E') {
            assert!(line.len() <= protocol::MAX_ROW_LINE, "{} bytes", line.len());
        }
        assert!(
            protocol::parse(line).is_ok(),
            "{}",
            String::from_utf8_lossy(line)
        );
    }
    let longest = s.0.iter().map(|l| l.0.len()).max().unwrap();
    println!("longest line: {longest} bytes");
}

#[test]
fn garbage_is_rejected_with_a_reason() {
    assert_eq!(protocol::parse(b"hello"), Err(ParseError::NoChecksum));
    let mut s = Lines::default();
    encode_end(&Totals::default(), 0, cvm_core::Verdict::Good, &mut s);
    let mut l = s.0[0].0.clone();
    l[0] = b'X';
    assert_eq!(protocol::parse(&l), Err(ParseError::Checksum));
}

/// At the cap, the strongest defects are listed, strongest first; equal
/// strengths by column, leftmost first; positions without data, and
/// positions no channel fired at, never.
#[test]
fn cap_lists_the_strongest_defects_with_ties_by_column() {
    let strengths = [5u32, 9, 7, 9, 3, 9, 8, 100, 1];
    let mut scores: Vec<PositionScore> = strengths
        .iter()
        .enumerate()
        .map(|(c, &strength)| PositionScore {
            // At least 65536, a defect's least strength.
            strength: strength << 16,
            // Alternate channels: the order does not depend on which fired.
            flags: if c % 2 == 0 {
                cvm_core::flags::CVM_DEFECT
            } else {
                cvm_core::flags::POWER_DEFECT
            },
            ..PositionScore::default()
        })
        .collect();
    scores[7].flags = cvm_core::flags::NO_DATA | cvm_core::flags::CVM_DEFECT;
    scores[8].flags = 0;
    let summary = RowSummary {
        row: 4,
        defects: 7,
        ..RowSummary::default()
    };
    let view = RowView {
        summary,
        scores: &scores,
        threshold: 3,
        power_threshold: 3,
    };
    for (cap, want) in [
        (0u16, vec![]),
        (1, vec![1]),
        (4, vec![1, 3, 5, 6]),
        (7, vec![1, 3, 5, 6, 2, 0, 4]),
        (20, vec![1, 3, 5, 6, 2, 0, 4]),
    ] {
        let mut s = Lines::default();
        encode_row(&view, cap, false, &mut s);
        let cols: Vec<u32> =
            s.0.iter()
                .filter_map(|(l, _)| match protocol::parse(l) {
                    Ok(Line::Defect { col, .. }) => Some(col),
                    _ => None,
                })
                .collect();
        assert_eq!(cols, want, "cap {cap}");
    }
}

/// A line given more than fits is cut so that its trailer still does: the
/// finished line is exactly `MAX_LINE` bytes, ends in `*XXXX\n` with the
/// CRC of what was kept, and nothing of the overflow leaks past it.
#[test]
fn an_overlong_line_keeps_room_for_its_trailer() {
    use cvm_core::protocol::LineBuf;
    let mut l = LineBuf::new(b'R');
    for i in 0..2 * MAX_LINE {
        l.byte(b'0' + (i % 10) as u8);
    }
    let line = l.finish();
    assert_eq!(line.len(), MAX_LINE);
    let (body, tail) = line.split_at(MAX_LINE - 6);
    assert_eq!(body[0], b'R');
    assert!(
        body[1..]
            .iter()
            .enumerate()
            .all(|(i, &b)| b == b'0' + (i % 10) as u8)
    );
    assert_eq!(tail, format!("*{:04X}\n", crc16(body)).as_bytes());
}

/// Numbers are written in decimal exactly as Rust formats them, on both
/// sides of 2^32 (the encoder divides in 32 bits when the value fits) and
/// at the ends of `u64` and `i64`.
#[test]
fn numbers_are_written_in_decimal() {
    use cvm_core::protocol::LineBuf;
    let mut r = cvm_core_tests::rng(64);
    let mut values: Vec<u64> = vec![0, 1, 9, 10, 99, 100, u64::from(u32::MAX)];
    values.extend([
        1 << 32,
        (1 << 32) + 1,
        10_000_000_000,
        10u64.pow(19),
        u64::MAX,
    ]);
    values.extend((0..200).map(|_| rand::RngExt::random::<u64>(&mut r) >> (r.random_range(0..64))));
    for v in values {
        let mut l = LineBuf::new(b'X');
        l.u64(v);
        let line = l.finish();
        assert_eq!(&line[1..line.len() - 6], v.to_string().as_bytes(), "{v}");
        let s = v as i64;
        let mut l = LineBuf::new(b'X');
        l.i64(s);
        let line = l.finish();
        assert_eq!(&line[1..line.len() - 6], s.to_string().as_bytes(), "{s}");
    }
}

/// A firmware name with characters that would break the header's syntax
/// (field and checksum separators, spaces, non-ASCII) is sent with each of
/// them replaced by `?`.
#[test]
fn firmware_name_cannot_break_the_header() {
    let mut sink = Lines::default();
    encode_header(&header("a,b*c d\u{e9}f", 20), &mut sink);
    let line = &sink.0[0].0;
    let Ok(Line::Header(h)) = protocol::parse(line) else {
        panic!("{}", String::from_utf8_lossy(line));
    };
    assert_eq!(h.firmware, "a?b?c?d??f");
}

/// The flag bits are the ones docs/protocol.md lists (its "Flags" table:
/// bit, value, name), which is what a decoder written from the document
/// reads.
#[test]
fn flags_are_the_documented_bits() {
    use cvm_core::flags;
    let doc = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../docs/protocol.md"
    ))
    .unwrap();
    let table = doc.split("## Flags").nth(1).expect("a Flags section");
    let rows: Vec<(u32, u32, String)> = table
        .lines()
        .skip_while(|l| !l.starts_with("| bit"))
        .skip(2)
        .take_while(|l| l.starts_with('|'))
        .map(|l| {
            let f: Vec<&str> = l.split('|').map(str::trim).collect();
            (
                f[1].parse().unwrap(),
                f[2].parse().unwrap(),
                f[3].trim_matches('`').to_string(),
            )
        })
        .collect();
    let ours = [
        ("NO_DATA", flags::NO_DATA),
        ("DARK", flags::DARK),
        ("SATURATED", flags::SATURATED),
        ("CLIPPED", flags::CLIPPED),
        ("CVM_DEFECT", flags::CVM_DEFECT),
        ("POWER_DEFECT", flags::POWER_DEFECT),
        ("SPREAD_DEFECT", flags::SPREAD_DEFECT),
    ];
    assert_eq!(rows.len(), ours.len(), "{rows:?}");
    for ((bit, value, name), (our_name, our_value)) in rows.iter().zip(ours) {
        assert_eq!((name.as_str(), *value), (our_name, 1 << bit), "{rows:?}");
        assert_eq!(u32::from(our_value), *value, "{name}");
    }
    assert_eq!(flags::SPREAD_DEFECT, 1 << 6);
    assert_eq!(
        flags::DEFECT,
        flags::CVM_DEFECT | flags::POWER_DEFECT | flags::SPREAD_DEFECT
    );
}

/// `body*XXXX\n` with the body's checksum.
fn sealed(body: &str) -> Vec<u8> {
    format!("{body}*{:04X}\n", crc16(body.as_bytes())).into_bytes()
}

/// An object line whose fields are replaced one at a time: its numbers
/// must be whole decimal numbers of their width (no empty field, no more
/// than 20 digits, nothing above the type's maximum), and its extents and
/// channels consistent; each bad field alone is refused.
#[test]
fn object_fields_are_checked_one_by_one() {
    // id, row0, row1, col0, col1, area, peak, peak row, peak col, peak
    // magnitude, peak power, peak spread, centroid row and column (Q8),
    // channels.
    let good = [
        "0", "0", "2", "0", "3", "12", "385844", "2", "2", "4938812", "859", "1700", "296", "385",
        "80",
    ];
    let line = |f: &[&str]| sealed(&format!("O,{}", f.join(",")));
    let with = |i: usize, v: &str| {
        let mut f = good.to_vec();
        f[i] = v;
        line(&f)
    };
    let Ok(Line::Object(o)) = protocol::parse(&line(&good)) else {
        panic!("the good line must parse");
    };
    assert_eq!(
        (o.row0, o.row1, o.col0, o.col1, o.peak_spread, o.channels),
        (0, 2, 0, 3, 1700, 80)
    );
    // The widest centroid a u64 holds, 20 digits.
    let max = u64::MAX.to_string();
    let Ok(Line::Object(o)) = protocol::parse(&with(12, &max)) else {
        panic!("a 20-digit centroid must parse");
    };
    assert_eq!(o.centroid_row_q8, u64::MAX);
    // Leading zeros, however many: 21 digits whose value is 1.
    let Ok(Line::Object(o)) = protocol::parse(&with(13, "000000000000000000001")) else {
        panic!("a zero-padded number must parse");
    };
    assert_eq!(o.centroid_col_q8, 1);
    let bad: [(usize, &str); 10] = [
        (1, "3"),                     // row0 > row1
        (3, "4"),                     // col0 > col1
        (14, "17"),                   // a channel bit that is not a decision
        (14, "144"),                  // bit 7, no channel
        (12, ""),                     // an empty number
        (12, "18446744073709551616"), // u64::MAX + 1
        (1, "4294967296"),            // u32::MAX + 1
        (10, "65536"),                // peak power above u16
        (11, "4294967296"),           // peak spread above u32
        (12, "+1"),                   // not a digit
    ];
    for (i, v) in bad {
        assert_eq!(
            protocol::parse(&with(i, v)).err(),
            Some(ParseError::Format),
            "field {i} = {v:?} must be refused"
        );
    }
}

/// A score line carries whole scores of 12 characters: none at all, or a
/// partial one, is refused.
#[test]
fn score_lines_hold_whole_scores() {
    let one = "CAAUQBwQAIBJ";
    assert!(matches!(
        protocol::parse(&sealed(&format!("S,4,7,{one}{one}"))),
        Ok(Line::Scores { row: 4, col0: 7, chars }) if chars.len() == 24
    ));
    for bad in [
        "",
        &one[..11],
        &format!("{one}Q"),
        &format!("{one}{}", &one[..9]),
    ] {
        assert_eq!(
            protocol::parse(&sealed(&format!("S,4,7,{bad}"))).err(),
            Some(ParseError::Format),
            "{bad:?}"
        );
    }
}
