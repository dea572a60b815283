//! `dmap console --emulate`: the emulated board (QEMU) over the demo
//! part, part after part: its objects and verdict on the page's state,
//! and no requests (it has no command channel). Needs what
//! tests/emulate.rs needs.

use crate::common;

use common::console::{Console, ask};

#[test]
fn the_emulated_board_scans_the_demo_part_again_and_again() {
    let dir = common::tmp_in("console-emulate", "");
    let scan = common::demo_scan(&dir);
    let console = Console::start(&["--emulate", common::s(&scan), "--pitch-um", "334"]);
    let s = console.wait(600, "two parts", |s| {
        s["counters"]["parts"].as_u64() >= Some(2)
    });
    assert_eq!(s["last"]["verdict"], "obj", "{}", s["last"]);
    assert_eq!(s["last"]["objects"].as_array().unwrap().len(), 2);
    assert!(
        s["last"]["objects"][0]["size_mm"].is_array(),
        "{}",
        s["last"]["objects"][0]
    );
    assert_eq!(s["counters"]["line_errors"], 0, "{}", s["health"]);
    assert_eq!(s["outputs"]["reject"], true);
    let (status, v) = ask(&console.addr, "status", None);
    assert_eq!(status, 409, "{v}");
}
