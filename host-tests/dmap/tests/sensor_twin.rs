//! `dmap twin --command` with the H743 release firmware on the chip
//! model: requests in `dmap sensor`'s words reach the board at their
//! beams, its replies come back between the result lines, and settings
//! changed during a scan show in the next scan's header with their
//! source. The scan holds two parts (`--parts 2`), so that one short run
//! has two scans. Needs what tests/twin.rs needs (python3 with unicorn and
//! pyelftools, the `thumbv7em-none-eabihf` target).

use crate::common;

use common::dmap_ok as dmap;
use cvm_core::command::{Key, Refusal, Reply, parse_reply};
use cvm_core::protocol::{HeaderInfo, Line, parse};
use cvm_core::settings::Source;
use cvm_reference::Geometry;
use dmap::npy::write_scan_u16;

const ROWS: usize = 4;
const COLS: usize = 10;
const J: usize = 9;

#[test]
fn a_set_during_a_scan_shows_in_the_next_header() {
    let dir = tempfile::tempdir().unwrap();
    let scan = dir.path().join("scan.npy");
    let mut state = 7u64;
    let data: Vec<u16> = (0..ROWS * COLS * J * J)
        .map(|_| {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            500 + (state >> 33) as u16 % 300
        })
        .collect();
    write_scan_u16(&scan, ROWS, COLS, Geometry::new(J, J).unwrap(), &data).unwrap();
    let out = dmap(&[
        "twin",
        scan.to_str().unwrap(),
        "--scores",
        "--threshold",
        "0.05",
        // Rows 0 and 1 are the first scan, rows 2 and 3 the second.
        "--parts",
        "2",
        "--command",
        "0:status",
        "--command",
        "5:set thr=100 pthr=5000",
        "--command",
        "6:get thr",
        // Beyond this build's 10 columns: refused with the board's range.
        "--command",
        "7:set cols=400",
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    let headers: Vec<HeaderInfo> = stdout
        .lines()
        .filter(|l| l.starts_with("H,"))
        .map(|l| match parse(l.as_bytes()) {
            Ok(Line::Header(h)) => h,
            other => panic!("{l}: {other:?}"),
        })
        .collect();
    assert_eq!(headers.len(), 2, "{stdout}");
    // The second scan ended after its 2 rows, not at the end of the data.
    let ends: Vec<&str> = stdout.lines().filter(|l| l.starts_with("E,")).collect();
    assert_eq!(ends.len(), 2, "{stdout}");
    assert!(
        ends[1].starts_with("E,rows=2,frames=20,missing=0,"),
        "{stdout}"
    );
    let (first, second) = (&headers[0], &headers[1]);
    let o1 = first.origin.unwrap();
    let o2 = second.origin.unwrap();
    assert_eq!(o1.sources, [Source::Flash; Key::ALL.len()]);
    assert_eq!((o1.rows, o2.rows), (2, 2));
    assert_ne!(first.threshold, 100);
    assert_ne!(first.power_threshold, 5000);
    assert_eq!((second.threshold, second.power_threshold), (100, 5000));
    for k in Key::ALL {
        let want = if matches!(k, Key::Threshold | Key::PowerThreshold) {
            Source::Changed
        } else {
            Source::Flash
        };
        assert_eq!(o2.sources[k.index()], want, "{}: {stdout}", k.name());
    }
    // Every reply: status (1 + 15 lines, id 1), the two sets (2, 3), the
    // get (4), the refusal (5).
    let replies: Vec<(Option<u32>, String)> = stdout
        .lines()
        .filter(|l| l.starts_with("A,"))
        .map(|l| {
            let (id, r) = parse_reply(l.as_bytes()).unwrap_or_else(|e| panic!("{l}: {e}"));
            (id, format!("{r:?}"))
        })
        .collect();
    let ids: Vec<Option<u32>> = replies.iter().map(|r| r.0).collect();
    let mut want = vec![Some(1); 1 + Key::ALL.len()];
    want.extend([Some(2), Some(3), Some(4), Some(5)]);
    assert_eq!(ids, want, "{stdout}");
    assert_eq!(
        replies[replies.len() - 1].1,
        format!(
            "{:?}",
            Reply::<&str>::Refused(Refusal::OutOfRange { min: 1, max: 10 })
        )
    );
    let first_thr = first.threshold;
    let thr_of = |line: &str| match parse_reply(line.as_bytes()) {
        Ok((
            _,
            Reply::Value {
                key: Key::Threshold,
                value,
                source,
            },
        )) => Some((value, source)),
        _ => None,
    };
    let thr: Vec<(u32, Source)> = stdout.lines().filter_map(thr_of).collect();
    assert_eq!(
        thr,
        [
            (first_thr, Source::Flash),
            (100, Source::Changed),
            (100, Source::Changed)
        ]
    );
    // The summary on stderr: one line per request, before the counters.
    let err = String::from_utf8_lossy(&out.stderr);
    for want in [
        "dmap: request 1 (0:status): status: firmware ",
        "dmap: request 2 (5:set thr=100): thr=100 (changed, not saved)",
        "dmap: request 3 (5:set pthr=5000): pthr=5000 (changed, not saved)",
        "dmap: request 4 (6:get thr): thr=100 (changed, not saved)",
        "dmap: request 5 (7:set cols=400): refused: value out of range 1..=10",
    ] {
        assert!(err.contains(want), "no `{want}` in:\n{err}");
    }
}
