//! `dmap eval`'s object metrics on hand-made masks, through the real binary.

use std::path::PathBuf;

use dmap::npy;

use crate::common;
use common::{dmap, ok, s};

fn tmp(name: &str) -> PathBuf {
    common::tmp_in("obj", name)
}

#[test]
fn eval_reports_objects_on_hand_made_masks() {
    // 5x8. Truth: a 2x3 block at rows 1-2, cols 1-3, and (3, 6).
    // Scores >= 2: rows 1-3, cols 1-3 (found, one object, one row too many)
    // and (0, 7) (false); (3, 6) scores 1.5 (missed).
    let (rows, cols) = (5, 8);
    let mut mag = vec![0.5; rows * cols];
    for r in 1..4 {
        for c in 1..4 {
            mag[r * cols + c] = 3.0;
        }
    }
    mag[7] = 2.0;
    mag[3 * cols + 6] = 1.5;
    let g = tmp("obj-g.npy");
    let data: Vec<f64> = mag.iter().flat_map(|&m| [m, m, m]).collect();
    npy::write_gradient(&g, rows, cols, &data).unwrap();
    let mut t = vec![false; rows * cols];
    for (r, c) in [(1, 1), (1, 2), (1, 3), (2, 1), (2, 2), (2, 3), (3, 6)] {
        t[r * cols + c] = true;
    }
    let m = tmp("obj-m.npy");
    npy::write_mask(
        &m,
        &npy::Mask {
            rows,
            cols,
            data: t,
        },
    )
    .unwrap();
    let out = dmap(&[
        "eval",
        s(&g),
        "--truth",
        s(&m),
        "--threshold",
        "2",
        "--pitch-um",
        "500",
        "--json",
    ]);
    ok(&out);
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let o = &v["objects"];
    assert_eq!(o["truth_objects"], 2);
    assert_eq!(o["found"], 1);
    assert_eq!(o["missed"], 1);
    assert_eq!(o["detected_objects"], 2);
    assert_eq!(o["false_objects"], 1);
    let d = &o["defects"][0];
    assert_eq!(d["found"], true);
    assert_eq!(d["objects"], 1);
    assert_eq!(d["truth"]["rows"], serde_json::json!([1, 2]));
    assert_eq!(d["detected"]["rows"], serde_json::json!([1, 3]));
    assert_eq!(d["detected"]["cols"], serde_json::json!([1, 3]));
    assert_eq!(d["detected"]["area"], 9);
    assert_eq!(d["detected"]["size_mm"], serde_json::json!([1.5, 1.5]));
    assert_eq!(d["size_error"]["rows"], 0.5);
    assert_eq!(d["size_error"]["cols"], 0.0);
    assert_eq!(d["size_error"]["area"], 0.5);
    assert_eq!(o["defects"][1]["found"], false);
    assert_eq!(o["defects"][1]["detected"], serde_json::Value::Null);
    assert_eq!(o["false"][0]["rows"], serde_json::json!([0, 0]));
    assert_eq!(o["false"][0]["cols"], serde_json::json!([7, 7]));
    // The table says the same.
    let out = dmap(&["eval", s(&g), "--truth", s(&m), "--threshold", "2"]);
    ok(&out);
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(
        text.contains("2 defects, 1 found, 1 missed; 2 detected objects, 1 false"),
        "{text}"
    );
}
