//! The command channel's framing rules on the H743 release firmware, run
//! on the chip model (docs/commands.md, "Framing"): numbers with any
//! number of leading zeros, an empty line ended by `\r\n`, a request
//! after an overrun that cut a line's `\n`, and a commanded reset that
//! lets the result line on the wire finish.

use crate::common;

use common::dmap_ok as dmap;
use common::{counters, framed};
use cvm_core::command::{Key, Refusal, Reply, Source, parse_reply};
use dmap::twin::requests::write_requests;

/// Every line of the twin's output: replies decoded, result lines checked.
fn lines(out: &[u8]) -> Vec<Result<(Option<u32>, Reply<'_>), String>> {
    out.split_inclusive(|&b| b == b'\n')
        .filter(|l| l.starts_with(b"A,"))
        .map(|l| parse_reply(l).map_err(|e| format!("{e}: {}", String::from_utf8_lossy(l))))
        .collect()
}

#[test]
fn leading_zeros_an_empty_crlf_line_and_a_request_after_an_overrun_are_answered() {
    let dir = tempfile::tempdir().unwrap();
    let scan = dir.path().join("scan.npy");
    // 9x9 maps, 30 rows of 12 beams at 400 us: 144 ms of beams.
    common::blob_scan(&scan, 30, 12, 9, 5);
    let scan_s = scan.to_str().unwrap();
    let opts = ["--threshold", "0.05"];
    let host = dmap(&[&["stream", scan_s, "--from-flash"][..], &opts].concat());
    let thr: u32 = String::from_utf8_lossy(&host.stdout)
        .split(',')
        .find_map(|f| f.strip_prefix("thr="))
        .unwrap()
        .parse()
        .unwrap();
    // The long request arrives while a debugger holds the core (2 ms from
    // beam 20): the receiver's FIFO keeps 16 bytes, the rest, `\n`
    // included, is lost (an overrun). The next request comes 40 beams
    // (16 ms) later, and after the idle gap (20 ms) ends the damaged line.
    let long = framed(&format!("C,3,set,thr={}1", "0".repeat(60)));
    let crlf_then_set = [b"\r\n".to_vec(), framed("C,2,set,dcap=00000000002")].concat();
    let bursts: [(u64, &[u8]); 4] = [
        (2, &framed("C,0001,get,thr")),
        (8, &crlf_then_set),
        (20, &long),
        (100, &framed("C,4,get,dcap")),
    ];
    let req = dir.path().join("requests.txt");
    write_requests(&req, &bursts).unwrap();
    let twin = dmap(
        &[
            &["twin", scan_s][..],
            &opts,
            &["--beam-us", "400", "--fault", "halt@20:2"],
            &["--requests", req.to_str().unwrap()],
        ]
        .concat(),
    );
    let c = counters(&twin);
    assert_eq!(c["status"], "done", "{c}");
    assert!(
        c["uart_rx_overruns"].as_u64().unwrap() >= 1,
        "the halt must overrun the receiver: {c}"
    );
    let got: Vec<_> = lines(&twin.stdout)
        .into_iter()
        .map(|r| r.unwrap())
        .collect();
    let value = |key, value, source| Reply::Value { key, value, source };
    assert_eq!(
        got,
        vec![
            (Some(1), value(Key::Threshold, thr, Source::Flash)),
            (Some(2), value(Key::DefectCap, 2, Source::Changed)),
            (None, Reply::Refused(Refusal::Overrun)),
            (Some(4), value(Key::DefectCap, 2, Source::Changed)),
        ],
        "{}",
        String::from_utf8_lossy(&twin.stdout)
    );
}

#[test]
fn a_commanded_reset_lets_the_result_line_on_the_wire_finish() {
    let dir = tempfile::tempdir().unwrap();
    let scan = dir.path().join("scan.npy");
    common::blob_scan(&scan, 20, 12, 9, 9);
    let scan_s = scan.to_str().unwrap();
    // Score lines at a beam every 100 us keep the link busy (about 200
    // bytes a row of 1.2 ms, with the replies, beyond its 92 bytes a
    // millisecond), so a result line is on the wire whenever the reset's
    // reply has gone.
    let req = dir.path().join("requests.txt");
    write_requests(&req, &[(30, &framed("C,1,reset"))]).unwrap();
    let twin = dmap(&[
        "twin",
        scan_s,
        "--threshold",
        "0.05",
        "--scores",
        "--beam-us",
        "100",
        "--settle-ms",
        "3000",
        "--requests",
        req.to_str().unwrap(),
    ]);
    let c = counters(&twin);
    assert_eq!(c["status"], "done", "{c}");
    let out = &twin.stdout;
    let mut headers = 0;
    for l in out.split_inclusive(|&b| b == b'\n') {
        let text = String::from_utf8_lossy(l);
        if l.starts_with(b"A,") {
            assert_eq!(parse_reply(l), Ok((Some(1), Reply::Resetting)), "{text}");
            continue;
        }
        headers += usize::from(l.starts_with(b"H,"));
        assert!(
            cvm_core::protocol::parse(l).is_ok(),
            "a cut or damaged line: {text:?}\n{}",
            String::from_utf8_lossy(out)
        );
    }
    assert_eq!(headers, 2, "the scan before the reset and the one after");
}
