//! The line protocol from both ends.
//!
//! 1. Arbitrary bytes, split into lines, go through `protocol::parse` and the
//!    host's stream `Decoder`: neither may panic. Random bytes almost never
//!    carry a valid CRC, so every line is also tried with its checksum
//!    repaired, which takes the fuzzer into the field parsers.
//! 2. Records built from the same bytes, every field within its range
//!    (docs/protocol.md, "Field ranges"), go through the encoder; every line
//!    it writes must parse back to exactly what was encoded, and the decoder
//!    must accept the whole stream without a single line error.
#![no_main]

use cvm_core::flags;
use cvm_core::power::POWER_MAX;
use cvm_core::protocol::{
    self, EndInfo, HeaderInfo, Line, LineSink, MAX_FW, MAX_LINE, Origin, Priority, SCORE_CHARS,
    SCORES_PER_LINE,
};
use cvm_core::settings::{KEYS, Source, Store};
use cvm_core::stream::{PositionScore, RowSummary, RowView, Totals};
use dmap::listen::Decoder;
use libfuzzer_sys::arbitrary::{Result, Unstructured};
use libfuzzer_sys::fuzz_target;

#[derive(Default)]
struct Lines(Vec<Vec<u8>>);

impl LineSink for Lines {
    fn line(&mut self, line: &[u8], _priority: Priority) {
        self.0.push(line.to_vec());
    }
}

/// `body*XXXX` with the right checksum.
fn with_crc(body: &[u8]) -> Vec<u8> {
    let mut l = body.to_vec();
    l.extend_from_slice(format!("*{:04X}", protocol::crc16(body)).as_bytes());
    l
}

fn decode_raw(data: &[u8]) {
    let mut dec = Decoder::new();
    for raw in data.split_inclusive(|&b| b == b'\n') {
        let _ = protocol::parse(raw);
        dec.feed(raw);
        let body = raw.strip_suffix(b"\n").unwrap_or(raw);
        let body = match body.iter().rposition(|&b| b == b'*') {
            Some(star) => &body[..star],
            None => body,
        };
        let fixed = with_crc(body);
        if let Err(e) = protocol::parse(&fixed) {
            assert_ne!(e, protocol::ParseError::Checksum, "repaired CRC refused");
        }
        dec.feed(&fixed);
    }
    dec.finish();
    for s in &dec.scans {
        let _ = s.coverage();
        let _ = s.n_rows();
    }
    let _ = dmap::listen::summary_text(&dec);
}

fn totals(u: &mut Unstructured) -> Result<Totals> {
    Ok(Totals {
        rows: u.arbitrary()?,
        frames: u.arbitrary()?,
        missing: u.arbitrary()?,
        dark: u.arbitrary()?,
        saturated: u.arbitrary()?,
        defects: u.arbitrary()?,
        objects: u.arbitrary()?,
        unobjected: u.arbitrary()?,
        rejected: u.arbitrary()?,
        extra: u.arbitrary()?,
        bad: u.arbitrary()?,
        clipped: u.arbitrary()?,
        misplaced: u.arbitrary()?,
    })
}

/// A position as the engine can score it: without data nothing else; with
/// data not both DARK and SATURATED, CLIPPED (with CVM_DEFECT) exactly at
/// the top magnitude, a power magnitude of at most 46340, a spread
/// magnitude of at most 92680, a defect's
/// strength at least 65536.
fn position(u: &mut Unstructured) -> Result<PositionScore> {
    let mut flags: u8 = u.int_in_range(0..=127)?;
    if flags & flags::NO_DATA != 0 {
        return Ok(PositionScore {
            flags: flags::NO_DATA,
            ..PositionScore::default()
        });
    }
    if flags & (flags::DARK | flags::SATURATED) == flags::DARK | flags::SATURATED {
        flags &= !flags::SATURATED;
    }
    let mag: u32 = u.arbitrary()?;
    flags &= !flags::CLIPPED;
    if mag == u32::MAX {
        flags |= flags::CLIPPED | flags::CVM_DEFECT;
    }
    let strength: u32 = u.arbitrary()?;
    Ok(PositionScore {
        mag,
        pmag: u.int_in_range(0..=POWER_MAX as u16)?,
        smag: u.int_in_range(0..=cvm_core::spread::SPREAD_MAX)?,
        strength: if flags & flags::DEFECT != 0 {
            strength.max(1 << 16)
        } else {
            0
        },
        flags,
        ..PositionScore::default()
    })
}

fn round_trip(u: &mut Unstructured) -> Result<()> {
    let cols = u.int_in_range(1..=3 * SCORES_PER_LINE as u32)?;
    let threshold: u32 = u.arbitrary()?;
    let fw_raw: Vec<u8> = u.arbitrary()?;
    let fw = String::from_utf8_lossy(&fw_raw).into_owned();
    let kernels = *u.choose(b"PS")?;
    let (weights, kernel_size) = if kernels == b'S' {
        ("unit", u.int_in_range(0..=15)?)
    } else {
        (
            *u.choose(&["uniform", "unit", "separable"])?,
            u.arbitrary()?,
        )
    };
    let mut sources = [Source::Default; KEYS];
    for s in &mut sources {
        *s = *u.choose(&Source::ALL)?;
    }
    let h = HeaderInfo {
        version: protocol::VERSION,
        firmware: &fw,
        j1: u.int_in_range(1..=16)?,
        j2: u.int_in_range(1..=16)?,
        cols,
        kernels,
        kernel_size,
        weights,
        normalise: u.arbitrary()?,
        full_scale: u.int_in_range(1..=u16::MAX)?,
        threshold,
        power_threshold: u.arbitrary()?,
        spread_threshold: u.arbitrary()?,
        q: u.int_in_range(protocol::Q_MIN..=protocol::Q_MAX)?,
        scores: true,
        max_defect_lines: u.arbitrary()?,
        reset_cause: *u.choose(&protocol::ResetCause::ALL)?,
        boots: u.int_in_range(1..=u32::MAX)?,
        origin: Some(Origin {
            rows: u.arbitrary()?,
            sources,
            store: *u.choose(&Store::ALL)?,
        }),
    };
    let mut out = Lines::default();
    protocol::encode_header(&h, &mut out);
    let max_defects: u16 = u.int_in_range(0..=8)?;

    let n_rows = u.int_in_range(0..=4u32)?;
    let mut rows = Vec::new();
    for row in 0..n_rows {
        let scores: Vec<PositionScore> = (0..cols).map(|_| position(u)).collect::<Result<_>>()?;
        let summary = RowSummary {
            row,
            max: u.arbitrary()?,
            argmax: u.arbitrary()?,
            pmax: u.int_in_range(0..=POWER_MAX)?,
            pargmax: u.arbitrary()?,
            defects: u.arbitrary()?,
            no_data: u.arbitrary()?,
            dark: u.arbitrary()?,
            saturated: u.arbitrary()?,
        };
        let view = RowView {
            summary,
            scores: &scores,
            threshold,
            power_threshold: h.power_threshold,
        };
        protocol::encode_row(&view, max_defects, true, &mut out);
        rows.push((summary, scores));
    }
    let end = EndInfo {
        totals: totals(u)?,
        dropped: u.arbitrary()?,
        verdict: *u.choose(&cvm_core::Verdict::ALL)?,
    };
    protocol::encode_end(&end.totals, end.dropped, end.verdict, &mut out);

    // Line by line, against what was encoded.
    let mut lines = out.0.iter();
    let first = lines.next().expect("header line");
    let Ok(Line::Header(got)) = protocol::parse(first) else {
        panic!(
            "header does not parse: {:?}",
            String::from_utf8_lossy(first)
        );
    };
    let fw_sent: String = fw
        .bytes()
        .take(MAX_FW)
        .map(|b| {
            if b.is_ascii_graphic() && b != b',' && b != b'*' {
                b as char
            } else {
                '?'
            }
        })
        .collect();
    assert_eq!(got.firmware, fw_sent);
    assert_eq!(
        HeaderInfo {
            firmware: &fw,
            ..got
        },
        h
    );
    for (summary, scores) in &rows {
        let listed = summary.defects.min(u32::from(max_defects));
        let l = lines.next().expect("row line");
        assert_eq!(
            protocol::parse(l),
            Ok(Line::Row {
                summary: *summary,
                listed
            })
        );
        // The strongest defects, strongest first, ties leftmost first.
        let mut defects: Vec<(u32, &PositionScore)> = scores
            .iter()
            .enumerate()
            .filter(|(_, p)| p.flags & flags::NO_DATA == 0 && p.flags & flags::DEFECT != 0)
            .map(|(c, p)| (c as u32, p))
            .collect();
        defects.sort_by_key(|&(c, p)| (std::cmp::Reverse(p.strength), c));
        defects.truncate(listed as usize);
        for (col, p) in defects {
            let l = lines.next().expect("defect line");
            assert_eq!(
                protocol::parse(l),
                Ok(Line::Defect {
                    row: summary.row,
                    col,
                    mag: p.mag,
                    pmag: p.pmag,
                    smag: p.smag,
                    strength: p.strength,
                    flags: p.flags
                })
            );
        }
        for (k, chunk) in scores.chunks(SCORES_PER_LINE).enumerate() {
            let l = lines.next().expect("score line");
            let Ok(Line::Scores { row, col0, chars }) = protocol::parse(l) else {
                panic!(
                    "score line does not parse: {:?}",
                    String::from_utf8_lossy(l)
                );
            };
            assert_eq!((row, col0), (summary.row, (k * SCORES_PER_LINE) as u32));
            assert_eq!(chars.len(), chunk.len() * SCORE_CHARS);
            for (c, p) in chars.chunks(SCORE_CHARS).zip(chunk) {
                // Score lines carry the seven defined flag bits.
                let want = protocol::ScoreValue {
                    mag: p.mag,
                    pmag: p.pmag,
                    smag: p.smag,
                    flags: p.flags & 0x7F,
                };
                assert_eq!(protocol::decode_score(c), Some(want));
            }
        }
    }
    let l = lines.next().expect("end line");
    assert_eq!(protocol::parse(l), Ok(Line::End(end)));
    assert!(lines.next().is_none());
    assert!(
        out.0
            .iter()
            .all(|l| l.len() <= MAX_LINE && l.ends_with(b"\n"))
    );

    // The whole stream through the host decoder: no damaged line, and every
    // position's score where it was sent.
    let mut dec = Decoder::new();
    for l in &out.0 {
        dec.feed(l);
    }
    dec.finish();
    assert!(dec.errors.is_empty(), "{:?}", dec.errors);
    assert_eq!(dec.scans.len(), 1);
    let scan = &dec.scans[0];
    assert_eq!(scan.end, Some(end));
    for (summary, scores) in &rows {
        let got = &scan.scores[&summary.row];
        assert_eq!(got.len(), scores.len());
        for (c, p) in scores.iter().enumerate() {
            let want = protocol::ScoreValue {
                mag: p.mag,
                pmag: p.pmag,
                smag: p.smag,
                flags: p.flags & 0x7F,
            };
            assert_eq!(got.get(&(c as u32)), Some(&want));
        }
    }
    Ok(())
}

fuzz_target!(|data: &[u8]| {
    decode_raw(data);
    let _ = round_trip(&mut Unstructured::new(data));
});
