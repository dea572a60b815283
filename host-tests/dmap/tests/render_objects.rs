//! `dmap render --objects` and `--pitch-um`: the demo part's objects,
//! from its result lines or from `dmap listen --json`, drawn as boxes in
//! the boxes' colour over the map (every pixel that differs from the
//! render without them is a box pixel, and each object's edges have
//! them), and millimetre axes.

use crate::common;

use common::s;

fn rgb(path: &std::path::Path) -> (usize, Vec<u8>) {
    let dec = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut r = dec.read_info().unwrap();
    let mut buf = vec![0; r.output_buffer_size().unwrap()];
    let info = r.next_frame(&mut buf).unwrap();
    assert_eq!(info.color_type, png::ColorType::Rgb);
    buf.truncate(info.buffer_size());
    (info.width as usize, buf)
}

#[test]
fn object_boxes_and_mm_axes_are_drawn_where_the_lines_put_them() {
    let dir = common::tmp_in("render-objects", "");
    let scan = common::demo_scan(&dir);
    let lines = dir.join("lines.txt");
    std::fs::write(
        &lines,
        common::dmap_ok(&["stream", s(&scan), "--scores"]).stdout,
    )
    .unwrap();
    let scores = dir.join("scores.npy");
    common::dmap_ok(&["listen", "--input", s(&lines), "-o", s(&scores)]);
    let json = dir.join("listen.json");
    std::fs::write(
        &json,
        common::dmap(&["listen", "--input", s(&lines), "--json"]).stdout,
    )
    .unwrap();
    let plain = dir.join("plain.png");
    let boxed = dir.join("boxed.png");
    let from_json = dir.join("json.png");
    let axes = ["--pitch-um", "334", "--scale", "10"];
    common::dmap_ok(&[&["render", s(&scores), "-o", s(&plain)][..], &axes].concat());
    common::dmap_ok(
        &[
            &[
                "render",
                s(&scores),
                "-o",
                s(&boxed),
                "--objects",
                s(&lines),
            ][..],
            &axes,
        ]
        .concat(),
    );
    common::dmap_ok(
        &[
            &[
                "render",
                s(&scores),
                "-o",
                s(&from_json),
                "--objects",
                s(&json),
            ][..],
            &axes,
        ]
        .concat(),
    );
    assert_eq!(
        std::fs::read(&boxed).unwrap(),
        std::fs::read(&from_json).unwrap()
    );
    let (w, a) = rgb(&plain);
    let (_, b) = rgb(&boxed);
    let red = dmap::render_marks::BOX_RGB;
    let mut changed = Vec::new();
    for (i, (pa, pb)) in a.chunks(3).zip(b.chunks(3)).enumerate() {
        if pa != pb {
            assert_eq!(pb, red, "a changed pixel that is not a box's at {}", i);
            changed.push((i % w, i / w));
        }
    }
    // The demo's two objects, rows and columns 5-15 and 21-35: at 10
    // pixels a position, each box's top edge runs 110 and 150 pixels.
    let doc: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    let objects = doc["objects"].as_array().unwrap();
    assert_eq!(objects.len(), 2);
    for o in objects {
        let width = (o["cols"][1].as_u64().unwrap() - o["cols"][0].as_u64().unwrap() + 1) * 10;
        let rows_with_a_full_edge = changed
            .iter()
            .fold(
                std::collections::BTreeMap::<usize, u64>::new(),
                |mut m, &(_, y)| {
                    *m.entry(y).or_default() += 1;
                    m
                },
            )
            .into_values()
            .filter(|&n| n >= width)
            .count();
        assert!(rows_with_a_full_edge >= 2, "no edge {width} pixels wide");
    }
    // Millimetre axes: the image with them is wider than one without.
    let bare = dir.join("bare.png");
    common::dmap_ok(&["render", s(&scores), "-o", s(&bare), "--scale", "10"]);
    assert!(rgb(&bare).0 < w, "no room made for the mm axis");
}
