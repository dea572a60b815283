//! The command channel on the H743 release firmware, run on the chip
//! model (`dmap twin --requests`): a flood of requests at the beam rates
//! the SPI allows costs no beam and leaves the result lines
//! byte-identical to `dmap stream`'s; every request is answered, in
//! order, with the reply the protocol document gives it; malformed and
//! damaged lines of every kind are refused with their reason and change
//! nothing. The replies are decoded with the core's parser and checked
//! against what each request asks, written out here.

use crate::common;

use common::dmap_ok as dmap;
use common::{counters, crc16_bitwise, framed};
use cvm_core::command::{Key, Refusal, Reply, Source, parse_reply};
use dmap::twin::requests::write_requests;
use std::path::Path;

/// A scan of noise with one bright blob (an object) in row 1.
/// The twin's output split: the reply lines, and everything else.
fn split(out: &[u8]) -> (Vec<Vec<u8>>, Vec<u8>) {
    let (mut replies, mut results) = (Vec::new(), Vec::new());
    for l in out.split_inclusive(|&b| b == b'\n') {
        if l.starts_with(b"A,") {
            replies.push(l.to_vec());
        } else {
            results.extend_from_slice(l);
        }
    }
    (replies, results)
}

/// What a request must be answered with.
#[derive(Clone, Debug, PartialEq)]
enum Want {
    /// `ok`, a value reply of this key with this value and source.
    Value(Key, u32, Source),
    /// `status`: the status line then one value line per key.
    Status,
    /// `err` with this reason and id (`None`: `-`).
    Refused(Option<u32>, Refusal),
}

/// A burst of request bytes: its beam, the bytes, which of them arrive
/// damaged (`fe@N` and the like, as the requests file writes it).
type Burst = (u64, Vec<u8>, Option<&'static str>);

/// Runs the scan with these request bursts; checks the result lines
/// against `dmap stream` and every reply against `want`, in order.
fn run(scan: &Path, opts: &[&str], beam_us: &str, bursts: &[Burst], want: &[Want]) {
    let dir = scan.parent().unwrap();
    let scan_s = scan.to_str().unwrap();
    let host = dmap(&[&["stream", scan_s, "--from-flash"][..], opts].concat());
    let req = dir.join("requests.txt");
    let refs: Vec<(u64, &[u8])> = bursts.iter().map(|(b, v, _)| (*b, &v[..])).collect();
    write_requests(&req, &refs).unwrap();
    // Damage marks follow the hex of their burst.
    let text = std::fs::read_to_string(&req).unwrap();
    let marked: String = text
        .lines()
        .zip(bursts)
        .map(|(l, (_, _, d))| match d {
            Some(d) => format!("{l} {d}\n"),
            None => format!("{l}\n"),
        })
        .collect();
    std::fs::write(&req, marked).unwrap();
    let twin = dmap(
        &[
            &["twin", scan_s][..],
            opts,
            &["--beam-us", beam_us, "--requests", req.to_str().unwrap()],
        ]
        .concat(),
    );
    let c = counters(&twin);
    assert_eq!(c["status"], "done", "{c}");
    assert_eq!(c["spi_overruns"], 0, "{c}");
    assert_eq!(c["uart_rx_overruns"], 0, "{c}");
    let (replies, results) = split(&twin.stdout);
    assert!(
        results == host.stdout,
        "requests changed the result lines:\n--- stream\n{}\n--- twin\n{}",
        String::from_utf8_lossy(&host.stdout),
        String::from_utf8_lossy(&results)
    );
    let mut it = replies.iter();
    let mut next = |what: &Want| {
        let l = it
            .next()
            .unwrap_or_else(|| panic!("no reply left for {what:?}"));
        parse_reply(l).unwrap_or_else(|e| panic!("{e:?}: {}", String::from_utf8_lossy(l)))
    };
    for (n, w) in want.iter().enumerate() {
        let id = n as u32 + 1;
        match w {
            Want::Value(k, v, s) => {
                let got = next(w);
                let want = Reply::Value {
                    key: *k,
                    value: *v,
                    source: *s,
                };
                assert_eq!(got, (Some(id), want), "request {id}");
            }
            Want::Status => {
                let (got_id, r) = next(w);
                assert_eq!(got_id, Some(id));
                let Reply::Status(st) = r else {
                    panic!("{r:?}")
                };
                assert!(st.last.scans <= 1, "one scan");
                for k in Key::ALL {
                    let (got_id, r) = next(w);
                    assert_eq!(got_id, Some(id));
                    let Reply::Value { key, source, .. } = r else {
                        panic!("{r:?}")
                    };
                    assert_eq!((key, source), (k, Source::Flash));
                }
            }
            Want::Refused(rid, why) => {
                let rid = rid.map(|_| id);
                assert_eq!(next(w), (rid, Reply::Refused(*why)), "request {id}");
            }
        }
    }
    assert!(it.next().is_none(), "more replies than requests");
}

/// `n` valid requests (gets, a status every 250th), one every `every`
/// beams from beam 1 on. The replies are a little longer than the
/// requests, and share the link with the result lines: `every` keeps
/// their bytes within the link's 92 160 bytes a second (beyond, the
/// requests wait in the board's receive ring, then overrun).
fn flood(n: u32, every: u64, thr: u32) -> (Vec<Burst>, Vec<Want>) {
    let defaults = |k: Key| match k {
        Key::Threshold => thr,
        Key::ReadyLevel => 1,
        Key::RejectLevel => 0,
        _ => 0,
    };
    let (mut bursts, mut want) = (Vec::new(), Vec::new());
    for id in 1..=n {
        let beam = 1 + (id as u64 - 1) * every;
        if id % 250 == 0 {
            bursts.push((beam, framed(&format!("C,{id},status")), None));
            want.push(Want::Status);
            continue;
        }
        // Keys whose value does not depend on the scan's size.
        let k = [Key::Threshold, Key::Scores, Key::DefectCap, Key::RejectMode][id as usize % 4];
        bursts.push((beam, framed(&format!("C,{id},get,{}", k.name())), None));
        want.push(Want::Value(k, defaults(k), Source::Flash));
    }
    (bursts, want)
}

/// The header's threshold, which the gets must report.
fn header_thr(stream: &[u8]) -> u32 {
    let head = String::from_utf8_lossy(stream);
    let f = head.split(",thr=").nth(1).unwrap();
    f.split(',').next().unwrap().parse().unwrap()
}

#[test]
fn a_flood_of_requests_at_the_spi_limit_costs_no_beam_15x15() {
    let dir = tempfile::tempdir().unwrap();
    let scan = dir.path().join("scan.npy");
    // 2000 beams at 146 µs: 0.29 s, a request every 2 beams (one every
    // 292 µs: about 90 % of the link's capacity with the replies and
    // result lines).
    common::blob_scan(&scan, 50, 40, 15, 11);
    let opts = ["--threshold", "0.05"];
    let thr = header_thr(&dmap(&[&["stream", scan.to_str().unwrap()][..], &opts].concat()).stdout);
    let (bursts, want) = flood(1000, 2, thr);
    run(&scan, &opts, "146", &bursts, &want);
}

#[test]
fn a_flood_of_requests_at_the_spi_limit_costs_no_beam_9x9_and_malformed_ones_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let scan = dir.path().join("scan.npy");
    // 7600 beams at 53 µs: 0.40 s, a request every 7 beams (371 µs),
    // then the malformed ones.
    common::blob_scan(&scan, 76, 100, 9, 11);
    let opts = ["--threshold", "0.05"];
    let thr = header_thr(&dmap(&[&["stream", scan.to_str().unwrap()][..], &opts].concat()).stdout);
    let (mut bursts, mut want) = flood(1000, 7, thr);
    let first_bad = bursts.len() as u32 + 1;
    let (bad, bad_want) = malformed(first_bad, 7001);
    assert!(bad.len() >= 50);
    bursts.extend(bad);
    want.extend(bad_want);
    // Nothing changed: every value still the compiled one.
    let id = want.len() + 1;
    bursts.push((7560, framed(&format!("C,{id},status")), None));
    want.push(Want::Status);
    run(&scan, &opts, "53", &bursts, &want);
}

/// Malformed and damaged request lines of every kind, each a burst at
/// its own beam from `beam` on, with ids from `first` on (as far as a
/// line has one), and the refusal each must get.
fn malformed(first: u32, beam: u64) -> (Vec<Burst>, Vec<Want>) {
    use Refusal::*;
    let mut out: Vec<(Vec<u8>, Option<&str>, Want)> = Vec::new();
    let mut id = first;
    let mut add =
        |line: &dyn Fn(u32) -> Vec<u8>, damage: Option<&'static str>, why, has_id: bool| {
            out.push((line(id), damage, Want::Refused(has_id.then_some(id), why)));
            id += 1;
        };
    let with_id = |body: &str| {
        let body = body.to_string();
        move |id: u32| framed(&body.replace('#', &id.to_string()))
    };
    for cmd in ["launch", "STATUS", "get_all", "stat"] {
        add(&with_id(&format!("C,#,{cmd}")), None, UnknownCommand, true);
    }
    for key in ["get,speed", "get,THR", "get,threshold", "set,gain=3"] {
        add(&with_id(&format!("C,#,{key}")), None, UnknownKey, true);
    }
    for v in [
        "thr=abc",
        "thr=-1",
        "thr=0.5",
        "thr=",
        "scores=2",
        "mode=sideways",
        "ready=HIGH",
    ] {
        add(&with_id(&format!("C,#,set,{v}")), None, WrongType, true);
    }
    add(&with_id("C,#,calibrate,five"), None, WrongType, true);
    for (v, min, max) in [
        ("set,cols=0", 1, 100),
        ("set,cols=101", 1, 100),
        ("set,rows=0", 1, 65535),
        ("set,dcap=17", 0, 16),
        ("set,pulse=70000", 0, 65536),
        ("set,thr=4294967296", 0, u32::MAX),
        ("calibrate,0", 1, 100),
        ("calibrate,101", 1, 100),
    ] {
        add(
            &with_id(&format!("C,#,{v}")),
            None,
            OutOfRange { min, max },
            true,
        );
    }
    add(&with_id("C,#,set,mode=row"), None, Conflict, true);
    for s in [
        "C,#",
        "C,#,status,now",
        "C,#,get",
        "C,#,set,thr",
        "C,#,save,1",
    ] {
        add(&with_id(s), None, Malformed, true);
    }
    for s in [
        "C,x,status",
        "C,,status",
        "C,-1,status",
        "A,1,ok,save",
        "H,v=6",
    ] {
        add(&with_id(s), None, Malformed, false);
    }
    // No trailer, a short one, lower-case hex.
    add(
        &|id| format!("C,{id},status\n").into_bytes(),
        None,
        Malformed,
        false,
    );
    add(
        &|id| format!("C,{id},status*12\n").into_bytes(),
        None,
        Malformed,
        false,
    );
    add(
        &|id| {
            let body = format!("C,{id},status");
            format!("{body}*{:04x}\n", crc16_bitwise(body.as_bytes()) | 0xA0A0).into_bytes()
        },
        None,
        Malformed,
        false,
    );
    // A CRC that does not match: one bit flipped in one of five places.
    for n in 0..5 {
        add(
            &move |id| {
                let mut l = framed(&format!("C,{id},get,thr"));
                l[n + 2] ^= 0x01;
                l
            },
            None,
            Checksum,
            false,
        );
    }
    // Too long: 300 bytes before the `\n`.
    for _ in 0..2 {
        add(
            &|_| [vec![b'C'; 300], vec![b'\n']].concat(),
            None,
            TooLong,
            false,
        );
    }
    // Bytes damaged on the link: framing errors, noise, parity errors
    // (refused as noise).
    for (k, why) in [
        ("fe@3", Framing),
        ("fe@0", Framing),
        ("fe@9", Framing),
        ("ne@2", Noise),
        ("ne@5", Noise),
        ("ne@0", Noise),
        ("pe@1", Noise),
        ("pe@4", Noise),
    ] {
        add(&|id| framed(&format!("C,{id},status")), Some(k), why, false);
    }
    // Binary garbage.
    add(
        &|_| (0u8..10).chain(200..=255).chain([b'\n']).collect(),
        None,
        Malformed,
        false,
    );
    let mut bursts = Vec::new();
    let mut want = Vec::new();
    for (k, (bytes, damage, w)) in out.into_iter().enumerate() {
        bursts.push((beam + 2 * k as u64, bytes, damage));
        want.push(w);
    }
    (bursts, want)
}

#[test]
fn requests_beyond_the_links_capacity_are_refused_as_overruns_and_cost_no_beam() {
    let dir = tempfile::tempdir().unwrap();
    let scan = dir.path().join("scan.npy");
    // The 15x15 scan of the flood test (the same build): 300 status
    // requests back to back from beam 1, 5.4 KB in 59 ms, whose replies
    // (16 lines each, 135 KB) would take the link 1.5 s: the receive ring
    // fills, and what it cannot hold is lost and refused as an overrun.
    common::blob_scan(&scan, 50, 40, 15, 11);
    let opts = ["--threshold", "0.05"];
    let scan_s = scan.to_str().unwrap();
    let host = dmap(&[&["stream", scan_s, "--from-flash"][..], &opts].concat());
    let burst: Vec<u8> = (1..=300u32)
        .flat_map(|id| framed(&format!("C,{id},status")))
        .collect();
    let req = dir.path().join("requests.txt");
    write_requests(&req, &[(1, &burst)]).unwrap();
    let twin = dmap(
        &[
            &["twin", scan_s][..],
            &opts,
            &["--beam-us", "146", "--settle-ms", "3000"],
            &["--requests", req.to_str().unwrap()],
        ]
        .concat(),
    );
    let c = counters(&twin);
    assert_eq!(c["status"], "done", "{c}");
    assert_eq!(c["spi_overruns"], 0, "{c}");
    let (replies, results) = split(&twin.stdout);
    assert!(results == host.stdout, "the flood changed the result lines");
    // Every reply is a whole status (its line and 15 values, ids in
    // increasing order) or a refusal without id: an overrun, or a
    // fragment of a request after one.
    let mut it = replies.iter().map(|l| parse_reply(l).unwrap());
    let (mut answered, mut overruns, mut last_id) = (0, 0, 0);
    while let Some((id, r)) = it.next() {
        match (id, r) {
            (Some(id), Reply::Status(_)) => {
                assert!(id > last_id, "ids in order");
                last_id = id;
                answered += 1;
                for k in Key::ALL {
                    let (vid, v) = it.next().expect("the status's value lines");
                    assert_eq!(vid, Some(id));
                    assert!(matches!(v, Reply::Value { key, .. } if key == k), "{v:?}");
                }
            }
            (None, Reply::Refused(Refusal::Overrun)) => overruns += 1,
            (None, Reply::Refused(Refusal::Malformed | Refusal::Checksum)) => {}
            other => panic!("{other:?}"),
        }
    }
    assert!(overruns >= 1, "the ring overflowed: {answered} answered");
    assert!(
        answered >= 50,
        "requests were answered meanwhile: {answered}"
    );
    assert!(answered < 300);
}
