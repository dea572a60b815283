//! `--set KEY=VALUE`: a runtime setting by its name and in its unit on the
//! wire, checked as the board checks a `set` request. The float options
//! (`--threshold`, `--power-threshold`, `--spread-threshold`) are the same
//! settings in calibration units; both routes must make the same bytes.

use crate::common::{self, dmap, dmap_ok, one_line_error, s, tmp_in};
use cvm_core::command::{Key, Kind};

/// The value of `name=` in the header line of `out`.
fn header(out: &[u8], name: &str) -> String {
    let text = String::from_utf8_lossy(out);
    let h = text.lines().next().unwrap();
    let body = h.split('*').next().unwrap();
    body.split(',')
        .find_map(|f| f.strip_prefix(&format!("{name}=")))
        .unwrap_or_else(|| panic!("no {name} in {h}"))
        .to_string()
}

fn scan() -> std::path::PathBuf {
    let p = tmp_in("settings-set", "blob.npy");
    common::blob_scan(&p, 6, 8, 5, 7);
    p
}

#[test]
fn wire_values_make_the_same_bytes_as_the_calibration_units() {
    let p = scan();
    let floats = dmap_ok(&[
        "stream",
        s(&p),
        "--threshold",
        "0.3",
        "--power-threshold",
        "0.2",
        "--spread-threshold",
        "0.05",
        "--max-defect-lines",
        "3",
        "--scores",
    ])
    .stdout;
    // The wire's integers, computed here from the formats the spec states:
    // thr = ceil(units * 2^q), pthr = ceil(c * 2^15), sthr = ceil(s * 2^16).
    let q: i32 = header(&floats, "q").parse().unwrap();
    let thr = (0.3 * 2f64.powi(q)).ceil() as u32;
    let pthr = (0.2 * 32768f64).ceil() as u32;
    let sthr = (0.05 * 65536f64).ceil() as u32;
    assert_eq!(header(&floats, "thr"), thr.to_string());
    assert_eq!(header(&floats, "pthr"), pthr.to_string());
    assert_eq!(header(&floats, "sthr"), sthr.to_string());
    let wire = dmap_ok(&[
        "stream",
        s(&p),
        "--set",
        &format!("thr={thr}"),
        "--set",
        &format!("pthr={pthr}"),
        "--set",
        &format!("sthr={sthr}"),
        "--set",
        "dcap=3",
        "--set",
        "scores=1",
    ])
    .stdout;
    assert_eq!(
        String::from_utf8_lossy(&wire),
        String::from_utf8_lossy(&floats)
    );
    // A later --set wins over the option it overrides.
    let later = dmap_ok(&["stream", s(&p), "--threshold", "0.3", "--set", "thr=7"]).stdout;
    assert_eq!(header(&later, "thr"), "7");
}

#[test]
fn the_verdict_keys_reach_the_end_line() {
    let p = scan();
    let base = [
        "stream",
        s(&p),
        "--threshold",
        "0.05",
        "--set",
        "dcap=65535",
    ];
    let out = dmap_ok(&base).stdout;
    let text = String::from_utf8_lossy(&out).to_string();
    // One object, whose area is every defect the D lines list.
    let defects = text.lines().filter(|l| l.starts_with("D,")).count();
    let objects: Vec<_> = text.lines().filter(|l| l.starts_with("O,")).collect();
    assert_eq!(objects.len(), 1, "{text}");
    assert!(
        text.contains(&format!(",defects={defects},obj=1,")),
        "{text}"
    );
    let area: usize = objects[0].split(',').nth(6).unwrap().parse().unwrap();
    assert_eq!(area, defects, "{text}");
    let verdict = |extra: &[&str]| {
        let out = dmap_ok(&[&base[..], extra].concat()).stdout;
        let text = String::from_utf8_lossy(&out).to_string();
        let e = text
            .lines()
            .find(|l| l.starts_with("E,"))
            .unwrap()
            .to_string();
        e.split(",verdict=")
            .nth(1)
            .unwrap()
            .split('*')
            .next()
            .unwrap()
            .to_string()
    };
    // The area rule: an object rejects its part from `area` positions on.
    assert_eq!(verdict(&["--set", &format!("area={area}")]), "obj");
    assert_eq!(verdict(&["--set", &format!("area={}", area + 1)]), "good");
}

#[test]
fn every_key_is_checked_as_the_board_checks_it() {
    let p = scan();
    for key in Key::ALL {
        let name = key.name();
        let bad = dmap(&["stream", s(&p), "--set", &format!("{name}=x")]);
        if matches!(key, Key::Cols | Key::Rows) {
            one_line_error(&bad, "are its scan's");
            continue;
        }
        one_line_error(&bad, &format!("--set {name}=x: value of the wrong type"));
        // The largest value the board takes (the host holds any): accepted.
        let top = match key.kind() {
            Kind::Number => match key {
                Key::PowerThreshold | Key::SpreadThreshold => "4294967295".to_string(),
                Key::DefectCap => "65535".to_string(),
                _ => "4294967295".to_string(),
            },
            Kind::Flag => "1".to_string(),
            Kind::Choice(words) => {
                let (lo, _) = key.range(&cvm_core::command::Capacity {
                    max_cols: 1,
                    max_rows: 1,
                    max_dcap: 1,
                    max_pulse_us: 1,
                });
                words[lo as usize].to_string()
            }
        };
        let mut args = vec!["stream".to_string(), s(&p).to_string()];
        if key == Key::RejectMode {
            args.extend(["--set".into(), "pulse=100".into()]);
        }
        args.extend(["--set".into(), format!("{name}={top}")]);
        let a: Vec<&str> = args.iter().map(String::as_str).collect();
        let out = dmap_ok(&a);
        if let Some(h) = ["thr", "pthr", "sthr", "dcap", "scores"]
            .iter()
            .find(|h| **h == name)
        {
            assert_eq!(header(&out.stdout, h), top, "{name}");
        }
    }
    one_line_error(
        &dmap(&["stream", s(&p), "--set", "ready=low"]),
        "out of range 1..=1",
    );
    one_line_error(
        &dmap(&["stream", s(&p), "--set", "dcap=65536"]),
        "out of range 0..=65535",
    );
    one_line_error(
        &dmap(&["stream", s(&p), "--set", "mode=row"]),
        "needs a pulse width",
    );
    one_line_error(
        &dmap(&["stream", s(&p), "--set", "pthr=46341"]),
        "the channel is off",
    );
    let unknown = dmap(&["stream", s(&p), "--set", "nope=1"]);
    let names: Vec<_> = Key::ALL.iter().map(|k| k.name()).collect();
    one_line_error(&unknown, &names.join(", "));
    one_line_error(
        &dmap(&["stream", s(&p), "--set", "thr"]),
        "expected KEY=VALUE",
    );
}

#[test]
fn the_emulated_board_carries_the_scan_file_keys_and_refuses_the_others() {
    let p = scan();
    let args = ["--set", "thr=1000", "--set", "dcap=2", "--set", "scores=1"];
    let host = dmap_ok(&[&["stream", s(&p)][..], &args].concat()).stdout;
    let board = dmap_ok(&[&["emulate", s(&p)][..], &args].concat()).stdout;
    assert_eq!(
        String::from_utf8_lossy(&board),
        String::from_utf8_lossy(&host)
    );
    one_line_error(
        &dmap(&["emulate", s(&p), "--set", "area=3"]),
        "the verdict's and the outputs' settings",
    );
}

/// The chip model's board takes every key through its settings record:
/// the verdict's and the outputs' settings too, and its bytes are `dmap
/// stream --from-flash`'s with the same `--set`.
#[test]
fn the_h743_takes_every_key_through_its_settings_record() {
    let p = scan();
    let sets = [
        "--threshold",
        "0.05",
        "--set",
        "dcap=65535",
        "--set",
        "dcap=5",
        "--set",
        "area=4",
        "--set",
        "pulse=300",
        "--set",
        "mode=row",
    ];
    let host = dmap_ok(&[&["stream", s(&p), "--from-flash"][..], &sets].concat()).stdout;
    let board = dmap_ok(&[&["twin", s(&p)][..], &sets].concat()).stdout;
    assert_eq!(
        String::from_utf8_lossy(&board),
        String::from_utf8_lossy(&host)
    );
    let text = String::from_utf8_lossy(&host).to_string();
    assert!(
        text.contains(",dcap=5,") && text.contains(",src=ffff"),
        "{text}"
    );
}
