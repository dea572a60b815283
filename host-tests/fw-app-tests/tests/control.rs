//! The command channel's logic (`cvm_fw_app::control`): each request's
//! reply and effect, the sources of docs/commands.md, refusals that
//! change nothing, and settings reaching the scan driver only between
//! scans. Replies are decoded with the core's reply parser and checked
//! against values written here.

use cvm_core::calibration::rule::{DEFAULT_TAIL_PPM, Rule};
use cvm_core::command::{
    Capacity, Key, Refusal, Reply, Request, Source, Store, encode_request, parse_reply,
};
use cvm_core::protocol::{LineSink, Priority, ResetCause};
use cvm_core::settings::{KEYS, Settings};
use cvm_fw_app::control::{Control, Effect};

#[derive(Default)]
struct Lines(Vec<Vec<u8>>);
impl LineSink for Lines {
    fn line(&mut self, line: &[u8], _p: Priority) {
        self.0.push(line.to_vec());
    }
}

const CAP: Capacity = Capacity {
    max_cols: 300,
    max_rows: 1000,
    max_dcap: 16,
    max_pulse_us: 65536,
};

fn compiled() -> Settings {
    Settings::new(300, 200, 4_194_304, 3277)
}

fn control(store: Store, record: Option<[u32; KEYS]>) -> Control {
    let boot = cvm_core::Boot {
        firmware: "fw-test",
        reset_cause: ResetCause::Watchdog,
        boots: 4,
        store,
    };
    Control::new(compiled(), boot, CAP, (15, 15), record)
}

/// Sends request `r` with id `id`; returns the replies, decoded, and the effect.
fn ask(c: &mut Control, id: u32, r: Request) -> (Vec<Reply<'static>>, Effect) {
    let mut req = Lines::default();
    encode_request(id, &r, &mut req);
    let line = req.0.remove(0);
    let mut out = Lines::default();
    let effect = c.line(&line[..line.len() - 1], &mut out);
    (replies(out, Some(id)), effect)
}

fn replies(out: Lines, id: Option<u32>) -> Vec<Reply<'static>> {
    out.0
        .into_iter()
        .map(|l| {
            let l: &'static [u8] = Vec::leak(l);
            let (got, r) = parse_reply(l).expect("a well-formed reply");
            assert_eq!(got, id);
            r
        })
        .collect()
}

fn value(key: Key, value: u32, source: Source) -> Reply<'static> {
    Reply::Value { key, value, source }
}

#[test]
fn status_lists_every_setting_with_its_source() {
    let mut c = control(Store::Empty, None);
    let (r, e) = ask(&mut c, 3, Request::Status);
    assert_eq!(e, Effect::None);
    assert_eq!(r.len(), 1 + KEYS);
    let Reply::Status(st) = r[0] else {
        panic!("{:?}", r[0])
    };
    assert_eq!(
        (st.j1, st.j2, st.max_cols, st.max_rows),
        (15, 15, 300, 1000)
    );
    assert_eq!(
        (st.store, st.reset_cause, st.boots),
        (Store::Empty, ResetCause::Watchdog, 4)
    );
    assert_eq!((st.last.scans, st.last.verdict), (0, None));
    // The spread channel compiled off (sthr = u32::MAX).
    let want = [
        300,
        200,
        4_194_304,
        3277,
        u32::MAX,
        0,
        0,
        0,
        0,
        0,
        0,
        0,
        0,
        0,
        1,
        0,
    ];
    for ((k, v), got) in Key::ALL.into_iter().zip(want).zip(&r[1..]) {
        assert_eq!(*got, value(k, v, Source::Default), "{}", k.name());
    }
}

#[test]
fn set_changes_the_next_scan_only_and_refusals_change_nothing() {
    let mut c = control(Store::Empty, None);
    assert!(
        c.take_changed().is_some(),
        "the start's settings go to the driver"
    );
    assert!(c.take_changed().is_none());
    let (r, _) = ask(&mut c, 1, Request::Set(Key::Threshold, 99));
    assert_eq!(r, [value(Key::Threshold, 99, Source::Changed)]);
    let s = c.take_changed().expect("changed");
    assert_eq!(s.threshold, 99);
    assert_eq!(s.sources[Key::Threshold.index()], Source::Changed);
    assert_eq!(s.sources[Key::Cols.index()], Source::Default);
    // The start's facts are not settings: a change leaves them.
    let b = c.boot();
    assert_eq!(
        (b.firmware, b.reset_cause, b.boots),
        ("fw-test", ResetCause::Watchdog, 4)
    );

    let before = *c.settings();
    let bad: [&[u8]; 6] = [
        b"C,2,set,cols=301",
        b"C,2,set,mode=sideways",
        b"C,2,set,mode=row", // no pulse width yet: a conflict
        b"C,2,set,speed=3",
        b"C,2,launch",
        b"C,2,set,thr=1*0000",
    ];
    for line in bad {
        let mut out = Lines::default();
        let mut framed = line.to_vec();
        if !line.contains(&b'*') {
            let crc = cvm_core::protocol::crc16(line);
            framed.extend_from_slice(format!("*{crc:04X}").as_bytes());
        }
        assert_eq!(c.line(&framed, &mut out), Effect::None);
        assert_eq!(out.0.len(), 1);
        let reply = parse_reply(&out.0[0]).unwrap().1;
        assert!(matches!(reply, Reply::Refused(_)), "{reply:?}");
        assert_eq!(*c.settings(), before, "{}", String::from_utf8_lossy(line));
    }
    assert!(c.take_changed().is_none());
    let (r, _) = ask(&mut c, 4, Request::Set(Key::RejectMode, 1));
    assert_eq!(r, [Reply::Refused(Refusal::Conflict)]);
    ask(&mut c, 5, Request::Set(Key::Pulse, 500));
    let (r, _) = ask(&mut c, 6, Request::Set(Key::RejectMode, 1));
    assert_eq!(r, [value(Key::RejectMode, 1, Source::Changed)]);
    assert_eq!(c.counts().refused, 7);
}

#[test]
fn save_makes_every_value_flash_and_defaults_brings_the_compiled_ones_back() {
    let mut c = control(Store::Empty, None);
    ask(&mut c, 1, Request::Set(Key::Cols, 120));
    let (r, e) = ask(&mut c, 2, Request::Save);
    assert!(r.is_empty(), "the reply waits for the flash");
    let Effect::Save { id: 2, values } = e else {
        panic!("{e:?}")
    };
    assert_eq!(values[Key::Cols.index()], 120);
    assert_eq!(values[Key::Threshold.index()], 4_194_304);
    // A second save while the first runs is busy.
    assert_eq!(
        ask(&mut c, 3, Request::Save).0,
        [Reply::Refused(Refusal::Busy)]
    );
    // So is a reset: it would cut the erase or program under way.
    let (r, e) = ask(&mut c, 3, Request::Reset);
    assert_eq!((r, e), (vec![Reply::Refused(Refusal::Busy)], Effect::None));
    let mut out = Lines::default();
    c.saved(2, true, &mut out);
    assert_eq!(replies(out, Some(2)), [Reply::Saved]);
    assert!(c.settings().sources.iter().all(|&s| s == Source::Flash));

    let (r, _) = ask(&mut c, 4, Request::Defaults);
    assert_eq!(r, [Reply::Defaults]);
    let s = c.take_changed().unwrap();
    assert_eq!(s.cols, 300);
    // Flash still holds the record: the compiled values are not saved.
    assert!(s.sources.iter().all(|&s| s == Source::Changed));

    let mut out = Lines::default();
    c.saved(5, false, &mut out);
    assert_eq!(replies(out, Some(5)), [Reply::Refused(Refusal::Storage)]);
}

#[test]
fn a_loaded_record_is_used_unless_it_does_not_fit() {
    let mut values = [300, 50, 7, 8, 9, 1, 2, 3, 4, 5, 6, 1, 100, 2, 1, 0];
    let c = control(Store::Loaded, Some(values));
    let s = c.settings();
    assert_eq!(
        (
            s.cols,
            s.rows,
            s.threshold,
            s.power_threshold,
            s.spread_threshold
        ),
        (300, 50, 7, 8, 9)
    );
    assert!(s.scores);
    assert!(s.sources.iter().all(|&x| x == Source::Flash));
    assert_eq!(c.boot().store, Store::Loaded);
    assert_eq!(s.outputs.pulse_us, 100);
    assert!(s.outputs.ready_high && !s.outputs.reject_high);

    // A record of an earlier firmware with the levels that are no longer
    // allowed: its other values load, the levels stay fail-safe, `d`.
    let mut old = values;
    old[Key::ReadyLevel.index()] = 0;
    old[Key::RejectLevel.index()] = 1;
    let c = control(Store::Loaded, Some(old));
    let s = c.settings();
    assert_eq!(c.boot().store, Store::Loaded);
    assert_eq!((s.cols, s.threshold, s.outputs.pulse_us), (300, 7, 100));
    assert!(s.outputs.ready_high && !s.outputs.reject_high);
    for k in Key::ALL {
        let level = matches!(k, Key::ReadyLevel | Key::RejectLevel);
        let want = if level {
            Source::Default
        } else {
            Source::Flash
        };
        assert_eq!(s.sources[k.index()], want, "{}", k.name());
    }

    values[Key::Cols.index()] = 301; // beyond this build's capacity
    let c = control(Store::Loaded, Some(values));
    assert_eq!(c.settings().cols, 300);
    assert_eq!(c.settings().threshold, 4_194_304);
    assert_eq!(c.boot().store, Store::Unreadable);
    assert!(c.settings().sources.iter().all(|&x| x == Source::Default));

    values[Key::Cols.index()] = 300;
    values[Key::Pulse.index()] = 0; // row mode without pulse
    let c = control(Store::Loaded, Some(values));
    assert_eq!(c.boot().store, Store::Unreadable);

    let c = control(Store::Foreign, None);
    assert_eq!(c.boot().store, Store::Foreign);
    assert_eq!(c.settings().threshold, 4_194_304);
}

#[test]
fn calibration_is_armed_once_then_sets_the_three_thresholds() {
    let mut c = control(Store::Empty, None);
    assert_eq!(c.calibration_rule(), Rule::DEFAULT);
    let calibrate = Request::Calibrate {
        scans: 5,
        rate_ppm: 100,
    };
    let (r, _) = ask(&mut c, 9, calibrate);
    assert_eq!(r, [Reply::Calibrating(5)]);
    // The request's target, with the default tail share, until the end.
    assert_eq!(
        c.calibration_rule(),
        Rule::Tail {
            rate_ppm: 100,
            tail_ppm: DEFAULT_TAIL_PPM
        }
    );
    assert_eq!(c.calibration_to_arm(), Some(5));
    assert_eq!(c.calibration_to_arm(), None);
    assert_eq!(
        ask(&mut c, 10, Request::Set(Key::Threshold, 1)).0,
        [Reply::Refused(Refusal::Busy)]
    );
    assert_eq!(ask(&mut c, 11, Request::Get(Key::Threshold)).0.len(), 1);
    c.take_changed();
    let cal = cvm_core::command::Calibration {
        scans: 5,
        positions: 1000,
        threshold: 1234,
        power_threshold: 567,
        median: 10,
        mad: 2,
        power_median: 30,
        power_mad: 4,
        spread_threshold: 890,
        spread_median: 50,
        spread_mad: 6,
        rate_ppm: 100,
    };
    let mut out = Lines::default();
    c.calibrated(&cal, &mut out);
    assert_eq!(replies(out, Some(9)), [Reply::Calibrated(cal)]);
    assert_eq!(c.calibration_rule(), Rule::DEFAULT);
    let s = c.take_changed().unwrap();
    assert_eq!(
        (s.threshold, s.power_threshold, s.spread_threshold),
        (1234, 567, 890)
    );
    assert_eq!(s.sources[Key::Threshold.index()], Source::Changed);
    assert_eq!(s.sources[Key::PowerThreshold.index()], Source::Changed);
    assert_eq!(s.sources[Key::SpreadThreshold.index()], Source::Changed);
    assert_eq!(s.sources[Key::Cols.index()], Source::Default);
}

#[test]
fn reset_answers_first() {
    let mut c = control(Store::Empty, None);
    let (r, e) = ask(&mut c, 1, Request::Reset);
    assert_eq!((r, e), (vec![Reply::Resetting], Effect::Reset));
}
