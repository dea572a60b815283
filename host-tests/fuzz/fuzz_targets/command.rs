//! The command channel's codec from both ends.
//!
//! 1. Arbitrary bytes go through the line reader (with receiver errors
//!    sprinkled in) and every line through the request and reply parsers,
//!    as received and with its checksum repaired (random bytes almost never
//!    carry a valid CRC): nothing may panic, and a request that parses
//!    must encode to a line that parses back to the same request.
//! 2. Requests and refusal replies built from the same bytes are encoded
//!    and must parse back to exactly what was encoded.
#![no_main]

use cvm_core::command::{
    Capacity, Event, LineReader, LinkError, MAX_LINE, Refusal, Reply, Request, encode_reply,
    encode_request, parse_reply, parse_request,
};
use cvm_core::protocol::{self, LineSink, Priority};
use libfuzzer_sys::arbitrary::{Result, Unstructured};
use libfuzzer_sys::fuzz_target;

#[derive(Default)]
struct Lines(Vec<Vec<u8>>);

impl LineSink for Lines {
    fn line(&mut self, line: &[u8], _priority: Priority) {
        self.0.push(line.to_vec());
    }
}

fn with_crc(body: &[u8]) -> Vec<u8> {
    let mut l = body.to_vec();
    l.extend_from_slice(format!("*{:04X}\n", protocol::crc16(body)).as_bytes());
    l
}

fn check_line(line: &[u8], cap: &Capacity) {
    assert!(!line.is_empty() && line.len() < MAX_LINE);
    let _ = parse_reply(line);
    if let Ok((id, r)) = parse_request(line, cap) {
        let mut out = Lines::default();
        encode_request(id, &r, &mut out);
        assert_eq!(parse_request(&out.0[0], cap), Ok((id, r)));
    }
    let body = match line.iter().rposition(|&b| b == b'*') {
        Some(star) => &line[..star],
        None => line,
    };
    let fixed = with_crc(body);
    let _ = parse_reply(&fixed);
    match parse_request(&fixed, cap) {
        Err((_, Refusal::Checksum)) => panic!("repaired CRC refused"),
        Ok((id, r)) => {
            let mut out = Lines::default();
            encode_request(id, &r, &mut out);
            assert_eq!(parse_request(&out.0[0], cap), Ok((id, r)));
        }
        Err(_) => {}
    }
}

fn decode_raw(data: &[u8]) {
    let (head, rest) = data.split_at(data.len().min(6));
    let mut h = [0u8; 6];
    h[..head.len()].copy_from_slice(head);
    let cap = Capacity {
        max_cols: u16::from_le_bytes([h[0], h[1]]),
        max_rows: u16::from_le_bytes([h[2], h[3]]),
        max_dcap: u16::from_le_bytes([h[4], h[5]]),
        max_pulse_us: u32::from(u16::from_le_bytes([h[4], h[5]])) + 1,
    };
    let mut r = LineReader::new();
    for &b in rest {
        // Bytes 0xF0..=0xF2 stand for the receiver's errors.
        match b {
            0xF0 => r.error(LinkError::Overrun),
            0xF1 => r.error(LinkError::Framing),
            0xF2 => r.error(LinkError::Noise),
            _ => {}
        }
        if let Some(Event::Line(l)) = r.push(b) {
            let l = l.to_vec();
            check_line(&l, &cap);
        }
    }
}

fn round_trip(u: &mut Unstructured) -> Result<()> {
    let cap = Capacity {
        max_cols: u.int_in_range(1..=u16::MAX)?,
        max_rows: u.int_in_range(1..=u16::MAX)?,
        max_dcap: u.arbitrary()?,
        max_pulse_us: u.arbitrary()?,
    };
    let id: u32 = u.arbitrary()?;
    let key = *u.choose(&cvm_core::command::Key::ALL)?;
    let (lo, hi) = key.range(&cap);
    let req = match u.int_in_range(0..=6u8)? {
        0 => Request::Status,
        1 => Request::Get(key),
        2 => Request::Set(key, u.int_in_range(lo..=hi)?),
        3 => Request::Calibrate {
            scans: u.int_in_range(1..=cvm_core::command::MAX_CALIBRATION_SCANS)?,
            rate_ppm: u.int_in_range(1..=cvm_core::command::MAX_CALIBRATION_RATE_PPM)?,
        },
        4 => Request::Save,
        5 => Request::Defaults,
        _ => Request::Reset,
    };
    let mut out = Lines::default();
    encode_request(id, &req, &mut out);
    assert_eq!(parse_request(&out.0[0], &cap), Ok((id, req)));
    let why = if u.arbitrary()? {
        Refusal::OutOfRange {
            min: u.arbitrary()?,
            max: u.arbitrary()?,
        }
    } else {
        *u.choose(&Refusal::SIMPLE)?
    };
    let echo = if u.arbitrary()? { Some(id) } else { None };
    let mut out = Lines::default();
    encode_reply(echo, &Reply::Refused(why), &mut out);
    assert_eq!(parse_reply(&out.0[0]), Ok((echo, Reply::Refused(why))));
    Ok(())
}

fuzz_target!(|data: &[u8]| {
    decode_raw(data);
    let _ = round_trip(&mut Unstructured::new(data));
});
