//! Conformance vectors of the command channel (`commands.json`): request
//! lines as a board reads them (`cvm_core::command::parse_request`, under
//! the capacity [`CAP`]) and reply lines as a host reads them
//! (`parse_reply`), each with its decode in a form any language can
//! compare: an accepted line written again by the encoder (canonical: no
//! leading zeros, no `\r`), a refused request as the reply the board sends
//! for it, a refused reply as the reason it does not parse.

use super::edit::sealed;
use crate::stream::VecSink;
use cvm_core::command::{
    Calibration, Capacity, Key, LastScan, Refusal, Reply, Status, Store, encode_reply,
    encode_request, parse_reply, parse_request,
};
use cvm_core::protocol::{ParseError, ResetCause};
use cvm_core::settings::Source;
use serde_json::{Value, json};

/// The capacity requests are checked against: a build of 300 columns and
/// 1000 rows, at most 16 defect lines per row, REJECT pulses up to 65536 µs.
pub const CAP: Capacity = Capacity {
    max_cols: 300,
    max_rows: 1000,
    max_dcap: 16,
    max_pulse_us: 65536,
};

fn text(line: &[u8]) -> String {
    String::from_utf8_lossy(line).into_owned()
}

fn reply_line(id: Option<u32>, r: &Reply) -> String {
    let mut sink = VecSink::default();
    encode_reply(id, r, &mut sink);
    text(&sink.0)
}

/// A request line and what the board makes of it.
fn request(about: &str, line: &[u8]) -> Value {
    let decoded = match parse_request(line, &CAP) {
        Ok((id, r)) => {
            let mut sink = VecSink::default();
            encode_request(id, &r, &mut sink);
            json!({"accepted": text(&sink.0)})
        }
        Err((id, why)) => json!({"refused": reply_line(id, &Reply::Refused(why))}),
    };
    json!({"about": about, "line": text(line), "decode": decoded})
}

/// A reply line and what a host makes of it.
fn reply(about: &str, line: &[u8]) -> Value {
    let decoded = match parse_reply(line) {
        Ok((id, r)) => json!({"accepted": reply_line(id, &r)}),
        Err(e) => json!({"error": match e {
            ParseError::NoChecksum => "no-checksum",
            ParseError::Checksum => "checksum",
            ParseError::Type => "unknown-type",
            _ => "malformed",
        }}),
    };
    json!({"about": about, "line": text(line), "decode": decoded})
}

/// The first of `C,<id>,save` (ids from `id`) whose CRC has a letter
/// among its digits, written with them in lower case.
fn lower_crc(id: u32) -> Vec<u8> {
    (id..)
        .map(|i| sealed(&format!("C,{i},save")))
        .find(|l| l.iter().rev().take(5).any(|b| b.is_ascii_uppercase()))
        .map(|l| {
            let star = l.iter().rposition(|&b| b == b'*').unwrap_or(0);
            let (body, tail) = l.split_at(star);
            [body, &tail.to_ascii_lowercase()].concat()
        })
        .unwrap_or_default()
}

/// `line` with its last byte before the newline's CRC digit changed.
fn bad_crc(body: &str) -> Vec<u8> {
    let mut l = sealed(body);
    let at = l.len() - 2;
    l[at] = if l[at] == b'0' { b'1' } else { b'0' };
    l
}

fn requests() -> Vec<Value> {
    // 256 bytes before the newline, one more than a request may have.
    let long = format!("C,1,set,thr={}", "0".repeat(256 - 5 - 12));
    vec![
        request("status", &sealed("C,1,status")),
        request("get a setting", &sealed("C,2,get,thr")),
        request("set a number", &sealed("C,3,set,thr=4194304")),
        request("set a flag", &sealed("C,4,set,scores=1")),
        request("set a word", &sealed("C,5,set,mode=row")),
        request("calibrate on 10 scans", &sealed("C,6,calibrate,10")),
        request("save", &sealed("C,7,save")),
        request("defaults", &sealed("C,8,defaults")),
        request("reset", &sealed("C,9,reset")),
        request(
            "leading zeros in the id and value: accepted",
            &sealed("C,0010,set,thr=0042"),
        ),
        request(
            "more than 10 digits, the value in range: accepted (leading zeros count for nothing)",
            &sealed("C,11,set,thr=00000000001"),
        ),
        request(
            "more than 10 digits and a value beyond 32 bits: range",
            &sealed("C,11,set,thr=04294967296"),
        ),
        request("the largest id", &sealed("C,4294967295,status")),
        request(
            "\\r\\n line end: accepted",
            &[
                sealed("C,11,status")
                    .strip_suffix(b"\n")
                    .unwrap_or_default(),
                b"\r\n",
            ]
            .concat(),
        ),
        request("an id past 32 bits: no id", &sealed("C,4294967296,status")),
        request(
            "cols above the capacity: range with its limits",
            &sealed("C,12,set,cols=301"),
        ),
        request("a calibration of 0 scans", &sealed("C,13,calibrate,0")),
        request("a negative number", &sealed("C,14,set,thr=-1")),
        request("an empty value", &sealed("C,15,set,thr=")),
        request("a flag that is not 0 or 1", &sealed("C,16,set,scores=2")),
        request(
            "a word not among the key's",
            &sealed("C,17,set,mode=sideways"),
        ),
        request("set without =", &sealed("C,18,set,thr")),
        request("an unknown key", &sealed("C,19,get,speed")),
        request("an unknown command", &sealed("C,20,jump")),
        request("upper-case command", &sealed("C,21,STATUS")),
        request("an extra field", &sealed("C,22,status,now")),
        request(
            "a wrong checksum: the id is not trusted",
            &bad_crc("C,23,status"),
        ),
        request("no trailer", b"C,24,status\n"),
        request("lower-case checksum digits", &lower_crc(25)),
        request("not a C line", &sealed("A,26,status")),
        request("256 bytes before the newline: too long", &sealed(&long)),
        request(
            "calibrate for a target of 1 false position in 10 000 parts",
            &sealed("C,27,calibrate,10,100"),
        ),
        request(
            "the default target said: written again without it",
            &sealed("C,28,calibrate,10,1000"),
        ),
        request(
            "a target of 0: range with its limits",
            &sealed("C,29,calibrate,10,0"),
        ),
        request(
            "a target above one per part: range",
            &sealed("C,30,calibrate,10,1000001"),
        ),
        request(
            "a target as a fraction: wrong type (millionths only)",
            &sealed("C,31,calibrate,10,0.001"),
        ),
        request(
            "a third calibrate argument",
            &sealed("C,32,calibrate,10,100,5"),
        ),
        request(
            "a second argument to another command",
            &sealed("C,33,get,thr,pthr"),
        ),
    ]
}

fn replies() -> Vec<Value> {
    let status = Status {
        firmware: "cvm-fw-0.1.0",
        j1: 15,
        j2: 15,
        max_cols: 300,
        max_rows: 1000,
        store: Store::Loaded,
        reset_cause: ResetCause::Watchdog,
        boots: 3,
        last: LastScan {
            scans: 12,
            defects: 40,
            objects: 2,
            verdict: Some(cvm_core::Verdict::Objects),
        },
    };
    let calibrated = Calibration {
        scans: 10,
        positions: 90000,
        threshold: 5033165,
        power_threshold: 3277,
        median: 1200000,
        mad: 300000,
        power_median: 800,
        power_mad: 200,
        spread_threshold: 9830,
        spread_median: 1311,
        spread_mad: 655,
        rate_ppm: 1000,
    };
    let value = Reply::Value {
        key: Key::Threshold,
        value: 4194304,
        source: Source::Changed,
    };
    let line = |id, r: &Reply| reply_line(id, r).into_bytes();
    vec![
        reply("a value and its source", &line(Some(3), &value)),
        reply("status", &line(Some(1), &Reply::Status(status))),
        reply("calibrating", &line(Some(6), &Reply::Calibrating(10))),
        reply("calibrated", &line(Some(6), &Reply::Calibrated(calibrated))),
        reply("saved", &line(Some(7), &Reply::Saved)),
        reply("defaults", &line(Some(8), &Reply::Defaults)),
        reply("resetting", &line(Some(9), &Reply::Resetting)),
        reply(
            "refused: range with its limits",
            &line(
                Some(12),
                &Reply::Refused(Refusal::OutOfRange { min: 1, max: 300 }),
            ),
        ),
        reply(
            "refused: conflict (row mode without a pulse width)",
            &line(Some(13), &Reply::Refused(Refusal::Conflict)),
        ),
        reply(
            "refused: a calibration without a result",
            &line(Some(6), &Reply::Refused(Refusal::NoResult)),
        ),
        reply(
            "refused, no id: checksum",
            &line(None, &Reply::Refused(Refusal::Checksum)),
        ),
        reply(
            "refused, no id: overrun",
            &line(None, &Reply::Refused(Refusal::Overrun)),
        ),
        reply(
            "calibrated without its rate (a board before the field): the default",
            &sealed(
                "A,6,ok,calibrated,scans=10,positions=90000,thr=5033165,pthr=3277,sthr=9830,med=1200000,mad=300000,pmed=800,pmad=200,smed=1311,smad=655",
            ),
        ),
        reply(
            "calibrated with a field after the rate",
            &sealed(
                "A,6,ok,calibrated,scans=10,positions=90000,thr=5033165,pthr=3277,sthr=9830,med=1200000,mad=300000,pmed=800,pmad=200,smed=1311,smad=655,rate=100,x=1",
            ),
        ),
        reply("ok with no id", &sealed("A,-,ok,save")),
        reply("an unknown reason", &sealed("A,1,err,sorry")),
        reply("range without its limits", &sealed("A,1,err,range,1")),
        reply(
            "a value of a key this decoder does not know (a later board's setting): well formed, a client passes over it",
            &sealed("A,5,ok,foo=1:d"),
        ),
        reply(
            "an unknown key in capitals: malformed",
            &sealed("A,5,ok,Foo=1:d"),
        ),
        reply("an unknown key without a value", &sealed("A,5,ok,foo=:d")),
        reply("a value without its source", &sealed("A,1,ok,thr=5")),
        reply("a source that is no source", &sealed("A,1,ok,thr=5:x")),
        reply("neither ok nor err", &sealed("A,1,maybe")),
        reply("an extra field", &sealed("A,1,ok,save,extra")),
        reply("a wrong checksum", &bad_crc("A,1,ok,save")),
        reply("no trailer", b"A,1,ok,save\n"),
        reply("not an A line", &sealed("C,1,status")),
    ]
}

/// The command channel's vectors, one JSON document.
pub fn document() -> Value {
    json!({
        "about": "Command channel lines (docs/commands.md): requests as the board decodes them under the capacity below (accepted: the request written again canonically; refused: the reply the board sends), replies as a host decodes them (accepted: written again canonically; error: why not)",
        "capacity": {"cols": CAP.max_cols, "rows": CAP.max_rows, "dcap": CAP.max_dcap, "pulse_us": CAP.max_pulse_us},
        "requests": requests(),
        "replies": replies(),
    })
}
