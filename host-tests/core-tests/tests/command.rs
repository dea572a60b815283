//! The command channel's codec (cvm_core::command, docs/commands.md):
//! hand-written lines checked byte for byte (their CRC
//! from a bit-by-bit CRC-16 written here, not the crate's table), round
//! trips of every request and reply, every refusal, the line length bound,
//! the line reader, and arbitrary bytes.

use cvm_core::command::{
    Calibration, Capacity, Event, Key, Kind, LastScan, LineReader, LinkError,
    MAX_CALIBRATION_RATE_PPM, MAX_CALIBRATION_SCANS, MAX_LINE, Refusal, Reply, Request, Source,
    Status, Store, conflict, encode_reply, encode_request, parse_reply, parse_request,
};
use cvm_core::protocol::{LineSink, MAX_FW, ParseError, Priority, ResetCause};
use cvm_core::settings::{KEYS, RejectMode};
use cvm_core::{Fault, Settings, Verdict};
use proptest::prelude::*;

#[derive(Default)]
struct Lines(Vec<(Vec<u8>, Priority)>);
impl LineSink for Lines {
    fn line(&mut self, line: &[u8], p: Priority) {
        self.0.push((line.to_vec(), p));
    }
}

/// CRC-16/CCITT-FALSE bit by bit (polynomial 0x1021, initial 0xFFFF).
fn crc_bitwise(data: &[u8]) -> u16 {
    let mut crc: u16 = 0xFFFF;
    for &b in data {
        crc ^= (b as u16) << 8;
        for _ in 0..8 {
            crc = if crc & 0x8000 != 0 {
                (crc << 1) ^ 0x1021
            } else {
                crc << 1
            };
        }
    }
    crc
}

/// `body*XXXX\n`, framed independently of the crate.
fn framed(body: &str) -> Vec<u8> {
    format!("{body}*{:04X}\n", crc_bitwise(body.as_bytes())).into_bytes()
}

const CAP: Capacity = Capacity {
    max_cols: 300,
    max_rows: 1000,
    max_dcap: 16,
    max_pulse_us: 65536,
};

fn request_line(id: u32, r: &Request) -> Vec<u8> {
    let mut s = Lines::default();
    encode_request(id, r, &mut s);
    assert_eq!(s.0.len(), 1);
    assert_eq!(s.0[0].1, Priority::Keep);
    s.0.remove(0).0
}

fn reply_line(id: Option<u32>, r: &Reply) -> Vec<u8> {
    let mut s = Lines::default();
    encode_reply(id, r, &mut s);
    assert_eq!(s.0.len(), 1);
    assert_eq!(s.0[0].1, Priority::Keep);
    s.0.remove(0).0
}

#[test]
fn crc_reference_is_the_catalogued_one() {
    assert_eq!(crc_bitwise(b"123456789"), 0x29B1);
    assert_eq!(cvm_core::protocol::crc16(b"123456789"), 0x29B1);
}

#[test]
fn requests_are_written_as_specified() {
    let cases: [(u32, Request, &str); 15] = [
        (1, Request::Status, "C,1,status"),
        (2, Request::Set(Key::RejectMode, 1), "C,2,set,mode=row"),
        (3, Request::Set(Key::ReadyLevel, 1), "C,3,set,ready=high"),
        (4, Request::Set(Key::RejectLevel, 0), "C,4,set,reject=low"),
        (5, Request::Set(Key::MinArea, 12), "C,5,set,area=12"),
        (42, Request::Get(Key::Threshold), "C,42,get,thr"),
        (7, Request::Get(Key::Rows), "C,7,get,rows"),
        (
            4294967295,
            Request::Set(Key::PowerThreshold, 3277),
            "C,4294967295,set,pthr=3277",
        ),
        (0, Request::Set(Key::Scores, 1), "C,0,set,scores=1"),
        (
            9,
            Request::Calibrate {
                scans: 5,
                rate_ppm: 1000,
            },
            "C,9,calibrate,5",
        ),
        // One false position in 10 000 parts; the largest target.
        (
            13,
            Request::Calibrate {
                scans: 100,
                rate_ppm: 100,
            },
            "C,13,calibrate,100,100",
        ),
        (
            14,
            Request::Calibrate {
                scans: 1,
                rate_ppm: 1_000_000,
            },
            "C,14,calibrate,1,1000000",
        ),
        (10, Request::Save, "C,10,save"),
        (11, Request::Defaults, "C,11,defaults"),
        (12, Request::Reset, "C,12,reset"),
    ];
    for (id, r, body) in cases {
        let line = request_line(id, &r);
        assert_eq!(line, framed(body), "{body}");
        assert_eq!(parse_request(&line, &CAP), Ok((id, r)), "{body}");
    }
}

fn status_example() -> Status {
    Status {
        firmware: "0.1.0",
        j1: 15,
        j2: 15,
        max_cols: 300,
        max_rows: 1000,
        store: Store::Loaded,
        reset_cause: ResetCause::PowerOn,
        boots: 3,
        last: LastScan {
            scans: 2,
            defects: 14,
            objects: 1,
            verdict: Some(Verdict::Objects),
        },
    }
}

#[test]
fn replies_are_written_as_specified() {
    let cal = Calibration {
        scans: 5,
        positions: 1500,
        threshold: 838861,
        power_threshold: 3277,
        median: 1000,
        mad: 120,
        power_median: 500,
        power_mad: 60,
        spread_threshold: 6554,
        spread_median: 700,
        spread_mad: 90,
        rate_ppm: 1000,
    };
    let cases: Vec<(Option<u32>, Reply, &str)> = vec![
        (
            Some(1),
            Reply::Status(status_example()),
            "A,1,ok,status,pv=7,fw=0.1.0,j=15x15,cap=300x1000,store=ok,rst=por,boots=3,\
             last=2/14/1/obj,keys=16",
        ),
        (
            Some(42),
            Reply::Value {
                key: Key::Threshold,
                value: 4194304,
                source: Source::Flash,
            },
            "A,42,ok,thr=4194304:f",
        ),
        (
            Some(43),
            Reply::Value {
                key: Key::RejectMode,
                value: 1,
                source: Source::Changed,
            },
            "A,43,ok,mode=row:c",
        ),
        (
            Some(44),
            Reply::Value {
                key: Key::ReadyLevel,
                value: 1,
                source: Source::Default,
            },
            "A,44,ok,ready=high:d",
        ),
        (Some(9), Reply::Calibrating(5), "A,9,ok,calibrate,5"),
        (
            Some(9),
            Reply::Calibrated(cal),
            "A,9,ok,calibrated,scans=5,positions=1500,thr=838861,pthr=3277,sthr=6554,med=1000,mad=120,pmed=500,pmad=60,\
             smed=700,smad=90,rate=1000",
        ),
        (
            Some(9),
            Reply::Calibrated(Calibration {
                rate_ppm: 100,
                ..cal
            }),
            "A,9,ok,calibrated,scans=5,positions=1500,thr=838861,pthr=3277,sthr=6554,med=1000,mad=120,pmed=500,pmad=60,\
             smed=700,smad=90,rate=100",
        ),
        (Some(10), Reply::Saved, "A,10,ok,save"),
        (Some(11), Reply::Defaults, "A,11,ok,defaults"),
        (Some(12), Reply::Resetting, "A,12,ok,reset"),
        (
            Some(3),
            Reply::Refused(Refusal::OutOfRange { min: 1, max: 300 }),
            "A,3,err,range,1,300",
        ),
        (None, Reply::Refused(Refusal::Checksum), "A,-,err,checksum"),
        (
            Some(5),
            Reply::Refused(Refusal::UnknownKey),
            "A,5,err,unknown-key",
        ),
    ];
    for (id, r, body) in cases {
        let line = reply_line(id, &r);
        assert_eq!(
            String::from_utf8_lossy(&line),
            String::from_utf8_lossy(&framed(body))
        );
        assert_eq!(parse_reply(&line), Ok((id, r)), "{body}");
    }
    // A board that predates the `rate` field calibrated for the default
    // target; any other field in its place, or after it, is refused.
    let before = "A,9,ok,calibrated,scans=5,positions=1500,thr=838861,pthr=3277,sthr=6554,med=1000,\
                  mad=120,pmed=500,pmad=60,smed=700,smad=90";
    assert_eq!(
        parse_reply(&framed(before)),
        Ok((Some(9), Reply::Calibrated(cal)))
    );
    for tail in [
        ",rte=100",
        ",rate=100,x=1",
        ",rate=-1",
        ",rate=",
        ",rate=4294967296",
    ] {
        assert_eq!(
            parse_reply(&framed(&format!("{before}{tail}"))),
            Err(ParseError::Format),
            "{tail}"
        );
    }
}

#[test]
fn every_refusal_has_its_word_and_round_trips() {
    let words = [
        "checksum",
        "malformed",
        "too-long",
        "unknown-command",
        "unknown-key",
        "type",
        "busy",
        "overrun",
        "framing",
        "noise",
        "storage",
        "conflict",
        "no-result",
    ];
    for (r, w) in Refusal::SIMPLE.into_iter().zip(words) {
        let line = reply_line(Some(77), &Reply::Refused(r));
        assert_eq!(line, framed(&format!("A,77,err,{w}")));
        assert_eq!(parse_reply(&line), Ok((Some(77), Reply::Refused(r))));
        assert!(!r.to_string().is_empty());
    }
}

/// The refusal each request line gets, with the id it echoes.
#[test]
fn every_refusal_of_a_request() {
    let range = |min, max| Refusal::OutOfRange { min, max };
    let cases: Vec<(&str, Option<u32>, Refusal)> = vec![
        ("C,5,launch", Some(5), Refusal::UnknownCommand),
        ("C,5,STATUS", Some(5), Refusal::UnknownCommand),
        ("C,5,get,speed", Some(5), Refusal::UnknownKey),
        ("C,5,set,speed=3", Some(5), Refusal::UnknownKey),
        ("C,5,set,thr=abc", Some(5), Refusal::WrongType),
        ("C,5,set,thr=-1", Some(5), Refusal::WrongType),
        ("C,5,set,thr=", Some(5), Refusal::WrongType),
        ("C,5,set,thr=0.5", Some(5), Refusal::WrongType),
        ("C,5,set,scores=2", Some(5), Refusal::WrongType),
        ("C,5,set,scores=01", Some(5), Refusal::WrongType),
        ("C,5,set,scores=yes", Some(5), Refusal::WrongType),
        ("C,5,calibrate,five", Some(5), Refusal::WrongType),
        ("C,5,set,mode=rows", Some(5), Refusal::WrongType),
        ("C,5,set,mode=1", Some(5), Refusal::WrongType),
        ("C,5,set,ready=HIGH", Some(5), Refusal::WrongType),
        ("C,5,set,reject=", Some(5), Refusal::WrongType),
        // Only the fail-safe levels (docs/firmware.md, "Fail-safe").
        ("C,5,set,ready=low", Some(5), range(1, 1)),
        ("C,5,set,reject=high", Some(5), range(0, 0)),
        ("C,5,set,pulse=65537", Some(5), range(0, 65536)),
        ("C,5,set,area=4294967296", Some(5), range(0, u32::MAX)),
        ("C,5,set,cols=0", Some(5), range(1, 300)),
        ("C,5,set,cols=301", Some(5), range(1, 300)),
        ("C,5,set,rows=1001", Some(5), range(1, 1000)),
        ("C,5,set,dcap=17", Some(5), range(0, 16)),
        ("C,5,set,thr=4294967296", Some(5), range(0, u32::MAX)),
        ("C,5,set,pthr=99999999999", Some(5), range(0, u32::MAX)),
        ("C,5,set,sthr=4294967296", Some(5), range(0, u32::MAX)),
        ("C,5,set,sthr=off", Some(5), Refusal::WrongType),
        ("C,5,set,sthr=-1", Some(5), Refusal::WrongType),
        ("C,5,calibrate,0", Some(5), range(1, 100)),
        ("C,5,calibrate,101", Some(5), range(1, 100)),
        ("C,5,calibrate,70000", Some(5), range(1, 100)),
        ("C,5,calibrate,5,0", Some(5), range(1, 1_000_000)),
        ("C,5,calibrate,5,1000001", Some(5), range(1, 1_000_000)),
        ("C,5,calibrate,5,4294967296", Some(5), range(1, 1_000_000)),
        ("C,5,calibrate,5,0.001", Some(5), Refusal::WrongType),
        ("C,5,calibrate,5,", Some(5), Refusal::WrongType),
        ("C,5,calibrate,5,100,1", Some(5), Refusal::Malformed),
        ("C,5,calibrate,0,100", Some(5), range(1, 100)),
        ("C,5,set,thr=5,6", Some(5), Refusal::Malformed),
        ("C,5", Some(5), Refusal::Malformed),
        ("C,5,status,now", Some(5), Refusal::Malformed),
        ("C,5,save,1", Some(5), Refusal::Malformed),
        ("C,5,get", Some(5), Refusal::Malformed),
        ("C,5,get,thr,pthr", Some(5), Refusal::Malformed),
        ("C,5,set,thr", Some(5), Refusal::Malformed),
        ("C,5,calibrate", Some(5), Refusal::Malformed),
        ("C,x,status", None, Refusal::Malformed),
        ("C,-1,status", None, Refusal::Malformed),
        ("C,4294967296,status", None, Refusal::Malformed),
        ("C,,status", None, Refusal::Malformed),
        ("A,5,status", None, Refusal::Malformed),
        ("H,v=4", None, Refusal::Malformed),
        ("", None, Refusal::Malformed),
    ];
    for (body, id, why) in cases {
        let line = framed(body);
        assert_eq!(parse_request(&line, &CAP), Err((id, why)), "{body}");
    }
    // Framing failures, where the id cannot be trusted.
    let good = framed("C,5,status");
    let mut flipped = good.clone();
    flipped[2] = b'6';
    assert_eq!(
        parse_request(&flipped, &CAP),
        Err((None, Refusal::Checksum))
    );
    let lower = String::from_utf8(good.clone()).unwrap().to_lowercase();
    let lower = lower.replace("c,5", "C,5");
    if lower.as_bytes() != good.as_slice() {
        assert_eq!(
            parse_request(lower.as_bytes(), &CAP),
            Err((None, Refusal::Malformed)),
            "lower-case hex"
        );
    }
    assert_eq!(
        parse_request(b"C,5,status\n", &CAP),
        Err((None, Refusal::Malformed))
    );
    assert_eq!(
        parse_request(&good[..good.len() - 3], &CAP),
        Err((None, Refusal::Malformed)),
        "truncated trailer"
    );
    // The longest accepted line has 255 bytes before its `\n`.
    let pad = |n: usize| {
        let base = "C,5,get,";
        let key = "x".repeat(n - base.len() - 5);
        framed(&format!("{base}{key}"))
    };
    assert_eq!(pad(255).len(), 256);
    assert_eq!(
        parse_request(&pad(255), &CAP),
        Err((Some(5), Refusal::UnknownKey))
    );
    assert_eq!(
        parse_request(&pad(256), &CAP),
        Err((None, Refusal::TooLong))
    );
    // A `\r` before the `\n` counts in the 255 bytes (docs/commands.md).
    let with_cr = |mut l: Vec<u8>| {
        l.pop();
        l.extend_from_slice(b"\r\n");
        l
    };
    assert_eq!(
        parse_request(&with_cr(pad(254)), &CAP),
        Err((Some(5), Refusal::UnknownKey))
    );
    assert_eq!(
        parse_request(&with_cr(pad(255)), &CAP),
        Err((None, Refusal::TooLong))
    );
    // `\r\n` is accepted like `\n`.
    let mut crlf = good[..good.len() - 1].to_vec();
    crlf.extend_from_slice(b"\r\n");
    assert_eq!(parse_request(&crlf, &CAP), Ok((5, Request::Status)));
}

#[test]
fn protocol_document_example() {
    assert_eq!(
        parse_request(b"C,1,set,thr=4194304*EE0C\n", &CAP),
        Ok((1, Request::Set(Key::Threshold, 4194304)))
    );
    let reply = Reply::Value {
        key: Key::Threshold,
        value: 4194304,
        source: Source::Changed,
    };
    assert_eq!(reply_line(Some(1), &reply), b"A,1,ok,thr=4194304:c*23E1\n");
}

#[test]
fn keys_read_and_write_the_settings_value() {
    let mut s = Settings::new(300, 200, 4194304, 3277);
    // Each key reads its own field: a distinct value in each, checked
    // against the field, not against the key's own code.
    let values: [u32; KEYS] = [9, 8, 7, 6, 12, 1, 16, 5, 4, 3, 2, 1, 1000, 11, 1, 0];
    for (k, v) in Key::ALL.into_iter().zip(values) {
        assert!(k.set(&mut s, v), "{}", k.name());
    }
    let o = s.outputs;
    assert_eq!(
        (s.cols, s.rows, s.threshold, s.power_threshold, s.scores),
        (9, 8, 7, 6, true)
    );
    assert_eq!(s.spread_threshold, 12);
    assert_eq!(s.max_defect_lines_per_row, 16);
    assert_eq!(
        (o.min_area, o.min_strength, o.max_missing, o.max_misplaced),
        (5, 4, 3, 2)
    );
    assert_eq!(o.reject_mode, RejectMode::Row);
    assert_eq!((o.pulse_us, o.row_delay), (1000, 11));
    assert!(o.ready_high && !o.reject_high);
    for (k, v) in Key::ALL.into_iter().zip(values) {
        assert_eq!(k.get(&s), v, "{}", k.name());
    }
    // Values a field cannot hold change nothing.
    let before = s;
    assert!(!Key::Scores.set(&mut s, 2));
    assert!(!Key::DefectCap.set(&mut s, 70000));
    assert!(!Key::Cols.set(&mut s, 0));
    assert!(!Key::Rows.set(&mut s, 0));
    assert!(!Key::RejectMode.set(&mut s, 2));
    assert!(!Key::ReadyLevel.set(&mut s, 2));
    // Only the fail-safe levels: READY active high, REJECT active low.
    assert!(!Key::ReadyLevel.set(&mut s, 0));
    assert!(!Key::RejectLevel.set(&mut s, 1));
    assert_eq!(s, before);

    let names: Vec<_> = Key::ALL.iter().map(|k| k.name()).collect();
    assert_eq!(
        names,
        [
            "cols", "rows", "thr", "pthr", "sthr", "scores", "dcap", "area", "peak", "miss",
            "misp", "mode", "pulse", "delay", "ready", "reject"
        ]
    );
    // The spread threshold takes any 32-bit value, as pthr does: above
    // SPREAD_MAX the channel is off, SPREAD_OFF (the default) included.
    assert_eq!(Key::SpreadThreshold.range(&CAP), (0, u32::MAX));
    assert_eq!(
        Key::SpreadThreshold.parse_value(b"92680", &CAP),
        Ok(cvm_core::spread::SPREAD_MAX)
    );
    assert_eq!(
        Key::SpreadThreshold.parse_value(b"4294967295", &CAP),
        Ok(cvm_core::spread::SPREAD_OFF)
    );
    assert_eq!(
        Key::SpreadThreshold.get(&Settings::new(1, 1, 0, 0)),
        cvm_core::spread::SPREAD_OFF
    );
    for (i, k) in Key::ALL.into_iter().enumerate() {
        assert_eq!(Key::from_name(k.name().as_bytes()), Some(k));
        assert_eq!(k.index(), i);
    }
    assert_eq!(Key::RejectMode.kind(), Kind::Choice(["part", "row"]));
    for src in Source::ALL {
        assert_eq!(Source::from_char(src.as_char()), Some(src));
    }
    assert_eq!(
        Source::ALL.map(|s| s.as_char()),
        [b'd', b'f', b'c'],
        "the letters of the protocol document"
    );
}

#[test]
fn row_mode_without_a_pulse_is_a_conflict() {
    let mut s = Settings::new(300, 200, 1, 1);
    assert!(!conflict(&s));
    assert!(Key::RejectMode.set(&mut s, 1));
    assert!(conflict(&s), "row mode with the default pulse of 0");
    assert!(Key::Pulse.set(&mut s, 1));
    assert!(!conflict(&s));
    assert!(Key::RejectMode.set(&mut s, 0));
    assert!(Key::Pulse.set(&mut s, 0));
    assert!(!conflict(&s), "part mode holds REJECT with a pulse of 0");
}

#[test]
fn the_longest_status_fits_a_line() {
    let mut s = status_example();
    s.firmware = "0123456789abcdefghijklmnopqrstuvwxyz";
    s.j1 = 15;
    s.j2 = 15;
    s.max_cols = u16::MAX;
    s.max_rows = u16::MAX;
    s.store = Store::Foreign;
    s.reset_cause = ResetCause::Other;
    s.boots = u32::MAX;
    s.last = LastScan {
        scans: u32::MAX,
        defects: u32::MAX,
        objects: u32::MAX,
        verdict: Some(Verdict::Fault(Fault::Misplaced)),
    };
    let line = reply_line(Some(u32::MAX), &Reply::Status(s));
    let star = line.iter().rposition(|&c| c == b'*').unwrap();
    assert!(star < MAX_LINE - 5, "{star} bytes before the `*`");
    let mut want = s;
    want.firmware = &"0123456789abcdefghijklmnopqrstuvwxyz"[..MAX_FW];
    assert_eq!(
        parse_reply(&line),
        Ok((Some(u32::MAX), Reply::Status(want)))
    );
    // Calibrated, the next longest.
    let c = Calibration {
        scans: MAX_CALIBRATION_SCANS,
        positions: u32::MAX,
        threshold: u32::MAX,
        power_threshold: u32::MAX,
        median: u32::MAX,
        mad: u32::MAX,
        power_median: u32::MAX,
        power_mad: u32::MAX,
        spread_threshold: u32::MAX,
        spread_median: u32::MAX,
        spread_mad: u32::MAX,
        rate_ppm: u32::MAX,
    };
    assert!(reply_line(Some(u32::MAX), &Reply::Calibrated(c)).len() <= MAX_LINE);
    // Every value reply: the longest key with the longest value.
    for k in Key::ALL {
        let (_, hi) = k.range(&CAP);
        let r = Reply::Value {
            key: k,
            value: hi,
            source: Source::Changed,
        };
        let line = reply_line(Some(u32::MAX), &r);
        assert!(line.len() <= MAX_LINE);
        assert_eq!(parse_reply(&line), Ok((Some(u32::MAX), r)));
    }
}

/// A client keeps a reply after its line is gone: `detach` copies the
/// status's firmware text out of the line and keeps every other reply as it
/// is; a later board's setting (`OtherKey`) is the line's bytes, so none.
#[test]
fn a_reply_detached_from_its_line() {
    let line = framed(
        "A,5,ok,status,pv=7,fw=v9-rc,j=3x5,cap=80x60,store=none,rst=wdg,boots=12,last=4/0/0/none,keys=16",
    );
    let (_, r) = parse_reply(&line).unwrap();
    let kept: Reply<'static, String> = r.detach(String::from).unwrap();
    drop(line);
    let Reply::Status(s) = &kept else {
        panic!("{kept:?}")
    };
    assert_eq!(s.firmware, "v9-rc");
    assert_eq!((s.j1, s.j2, s.max_cols, s.max_rows), (3, 5, 80, 60));
    assert_eq!(
        (s.store, s.reset_cause, s.boots),
        (Store::Empty, ResetCause::Watchdog, 12)
    );
    assert_eq!(
        s.last,
        LastScan {
            scans: 4,
            defects: 0,
            objects: 0,
            verdict: None
        }
    );
    for body in [
        "A,6,ok,thr=4194304:f",
        "A,6,ok,calibrate,5",
        "A,6,ok,save",
        "A,6,ok,defaults",
        "A,6,ok,reset",
        "A,6,err,busy",
    ] {
        let line = framed(body);
        let (_, r) = parse_reply(&line).unwrap();
        let kept = r.detach(|fw| fw.len());
        assert_eq!(format!("{kept:?}"), format!("{:?}", Some(r)), "{body}");
    }
    let line = framed("A,6,ok,later_key=3:d");
    let (_, r) = parse_reply(&line).unwrap();
    assert!(matches!(r, Reply::OtherKey { .. }));
    assert_eq!(r.detach(String::from), None);
}

#[test]
fn firmware_characters_that_would_break_the_line_are_replaced() {
    let mut s = status_example();
    s.firmware = "a,b*c d";
    let line = reply_line(Some(1), &Reply::Status(s));
    let Ok((_, Reply::Status(got))) = parse_reply(&line) else {
        panic!("{}", String::from_utf8_lossy(&line))
    };
    assert_eq!(got.firmware, "a?b?c?d");
}

#[test]
fn reply_parser_refuses_what_is_no_reply() {
    let cases: [(&str, ParseError); 10] = [
        ("C,1,status", ParseError::Type),
        ("A,1,maybe", ParseError::Format),
        ("A,-,ok,save", ParseError::Format),
        ("A,1,err,sorry", ParseError::Format),
        ("A,1,err,range,1", ParseError::Format),
        ("A,1,ok,thr=5", ParseError::Format),
        ("A,1,ok,thr=5:x", ParseError::Format),
        ("A,1,ok,save,extra", ParseError::Format),
        ("A,1,ok,status,pv=5", ParseError::Format),
        ("A,1,ok,mode=1:c", ParseError::Format),
    ];
    for (body, e) in cases {
        assert_eq!(parse_reply(&framed(body)), Err(e), "{body}");
    }
    let mut bad = framed("A,1,ok,save");
    bad[4] = b'k';
    assert_eq!(parse_reply(&bad), Err(ParseError::Checksum));
    assert_eq!(parse_reply(b"A,1,ok,save\n"), Err(ParseError::NoChecksum));
}

#[test]
fn line_reader_cuts_lines_and_keeps_errors_with_their_line() {
    let mut r = LineReader::new();
    let mut events = Vec::new();
    let feed = |r: &mut LineReader, bytes: &[u8], events: &mut Vec<String>| {
        for &b in bytes {
            if let Some(e) = r.push(b) {
                events.push(match e {
                    Event::Line(l) => format!("line {}", String::from_utf8_lossy(l)),
                    Event::TooLong => "too long".into(),
                    Event::Damaged(k) => format!("damaged {k:?}"),
                });
            }
        }
    };
    feed(&mut r, b"C,1\n\n\nC,2\r\n", &mut events);
    feed(&mut r, b"C,3", &mut events);
    r.error(LinkError::Framing);
    r.error(LinkError::Overrun);
    feed(&mut r, b",x\n", &mut events);
    feed(&mut r, &[b'y'; 255], &mut events);
    feed(&mut r, b"\n", &mut events);
    feed(&mut r, &[b'z'; 256], &mut events);
    feed(&mut r, b"\nC,4\n", &mut events);
    r.error(LinkError::Noise);
    feed(&mut r, b"\n", &mut events);
    assert_eq!(
        events,
        [
            "line C,1".to_string(),
            "line C,2\r".into(),
            "damaged Framing".into(),
            format!("line {}", "y".repeat(255)),
            "too long".into(),
            "line C,4".into(),
            "damaged Noise".into(),
        ]
    );
    assert_eq!(LinkError::Overrun.refusal(), Refusal::Overrun);
    assert_eq!(LinkError::Framing.refusal(), Refusal::Framing);
    assert_eq!(LinkError::Noise.refusal(), Refusal::Noise);
}

fn key() -> impl Strategy<Value = Key> {
    prop::sample::select(Key::ALL.to_vec())
}

fn valid_request() -> impl Strategy<Value = Request> {
    prop_oneof![
        Just(Request::Status),
        key().prop_map(Request::Get),
        (key(), any::<u32>()).prop_map(|(k, v)| {
            let (lo, hi) = k.range(&CAP);
            Request::Set(
                k,
                lo + (v % (hi - lo).saturating_add(1).max(1)).min(hi - lo),
            )
        }),
        (1..=MAX_CALIBRATION_SCANS, 1..=MAX_CALIBRATION_RATE_PPM)
            .prop_map(|(scans, rate_ppm)| Request::Calibrate { scans, rate_ppm }),
        Just(Request::Save),
        Just(Request::Defaults),
        Just(Request::Reset),
    ]
}

fn source() -> impl Strategy<Value = Source> {
    prop::sample::select(Source::ALL.to_vec())
}

fn refusal() -> impl Strategy<Value = Refusal> {
    prop_oneof![
        prop::sample::select(Refusal::SIMPLE.to_vec()),
        (any::<u32>(), any::<u32>()).prop_map(|(min, max)| Refusal::OutOfRange { min, max }),
    ]
}

fn status(fw: &str) -> impl Strategy<Value = Status<&str>> {
    (
        (1u8..=15, 1u8..=15, any::<u16>(), any::<u16>()),
        prop::sample::select(Store::ALL.to_vec()),
        (prop::sample::select(ResetCause::ALL.to_vec()), any::<u32>()),
        (any::<u32>(), any::<u32>(), any::<u32>()),
        prop::option::of(prop::sample::select(Verdict::ALL.to_vec())),
    )
        .prop_map(
            move |((j1, j2, max_cols, max_rows), store, (rst, boots), (a, b, c), v)| Status {
                firmware: fw,
                j1,
                j2,
                max_cols,
                max_rows,
                store,
                reset_cause: rst,
                boots,
                last: LastScan {
                    scans: a,
                    defects: b,
                    objects: c,
                    verdict: v,
                },
            },
        )
}

proptest! {
    #[test]
    fn every_request_round_trips(id in any::<u32>(), r in valid_request()) {
        let line = request_line(id, &r);
        prop_assert!(line.len() <= MAX_LINE);
        prop_assert_eq!(parse_request(&line, &CAP), Ok((id, r)));
    }

    #[test]
    fn any_changed_byte_of_a_request_is_refused(
        id in any::<u32>(), r in valid_request(), at in any::<prop::sample::Index>(), to in any::<u8>()
    ) {
        let mut line = request_line(id, &r);
        let i = at.index(line.len() - 1); // not the `\n`
        prop_assume!(line[i] != to && to != b'\n');
        line[i] = to;
        prop_assert!(parse_request(&line, &CAP).is_err());
    }

    #[test]
    fn every_reply_round_trips(
        id in any::<u32>(),
        key in key(), v in any::<u32>(), src in source(),
        n in 1..=MAX_CALIBRATION_SCANS,
        cal in prop::array::uniform11(any::<u32>()),
        why in refusal(),
        st in status("0.1.0-rc.1+g3af9"),
    ) {
        // A value of the key's kind: flags and choices are 0 or 1.
        let value = if key.kind() == Kind::Number { v } else { v & 1 };
        let c = Calibration {
            scans: n, positions: cal[0], threshold: cal[1], power_threshold: cal[2],
            median: cal[3], mad: cal[4], power_median: cal[5], power_mad: cal[6],
            spread_threshold: cal[7], spread_median: cal[8], spread_mad: cal[9],
            rate_ppm: cal[10],
        };
        let replies = [
            Reply::Status(st),
            Reply::Value { key, value, source: src },
            Reply::Calibrating(n),
            Reply::Calibrated(c),
            Reply::Saved,
            Reply::Defaults,
            Reply::Resetting,
            Reply::Refused(why),
        ];
        for r in replies {
            let line = reply_line(Some(id), &r);
            prop_assert!(line.len() <= MAX_LINE);
            prop_assert_eq!(parse_reply(&line), Ok((Some(id), r)));
        }
        let line = reply_line(None, &Reply::Refused(why));
        prop_assert_eq!(parse_reply(&line), Ok((None, Reply::Refused(why))));
    }

    #[test]
    fn arbitrary_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..600)) {
        let _ = parse_request(&bytes, &CAP);
        let _ = parse_reply(&bytes);
        let mut r = LineReader::new();
        for &b in &bytes {
            if let Some(Event::Line(l)) = r.push(b) {
                prop_assert!(l.len() < MAX_LINE && !l.is_empty());
                let _ = parse_request(l, &CAP);
            }
        }
    }

    #[test]
    fn framed_garbage_never_panics(body in "C,[0-9]{0,11}(,[a-z=0-9:x/.-]{0,14}){0,4}") {
        let line = framed(&body);
        match parse_request(&line, &CAP) {
            Ok((id, r)) => prop_assert_eq!(parse_request(&request_line(id, &r), &CAP), Ok((id, r))),
            Err((Some(id), _)) => {
                let field = body.split(',').nth(1).unwrap_or("");
                prop_assert_eq!(field.parse::<u64>().ok(), Some(id as u64));
            }
            Err((None, _)) => {}
        }
        let _ = parse_reply(&framed(&body.replacen('C', "A", 1)));
    }
}

/// The refusals docs/commands.md gives for the edges of a request line:
/// an empty command, a `*` inside a field, a readable id on a malformed
/// line, `\r\r\n`, and zero-padded numbers.
#[test]
fn edge_requests_are_refused_as_the_spec_says() {
    for (body, want) in [
        ("C,1,", Err((Some(1), Refusal::UnknownCommand))),
        ("C,1,get,th*r", Err((Some(1), Refusal::UnknownKey))),
        ("C,7,status,now", Err((Some(7), Refusal::Malformed))),
        ("C,x,status", Err((None, Refusal::Malformed))),
        (
            "C,0000000000007,set,thr=000000000000000042",
            Ok((7, Request::Set(Key::Threshold, 42))),
        ),
    ] {
        assert_eq!(parse_request(&framed(body), &CAP), want, "{body}");
    }
    // `\r\r\n`: the line `\r`, after its CRC trailer, is no request.
    let mut l = framed("C,1,status");
    l.pop();
    l.extend_from_slice(b"\r\r\n");
    assert_eq!(parse_request(&l, &CAP), Err((None, Refusal::Malformed)));
}
