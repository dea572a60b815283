//! The settings kept in flash, read at start-up by the H743 release
//! firmware on the chip model (`dmap twin --flash FILE`): bank 2 images
//! written by the host side of the same store (cvm_fw_app_tests::bank,
//! the chip model's file format), then the firmware's lines compared with
//! `dmap stream`'s with the settings the firmware should scan with, and
//! its header's sources and store state checked. A record of this build
//! replaces the compiled settings; a record of another build, one beyond
//! this build's ranges, an erased bank, a half-programmed flash word (a
//! power cut while programming) and a half-erased sector (a power cut
//! while erasing) never stop it from starting. Needs what tests/twin.rs
//! needs.

use crate::common;

use common::{counters, framed, s, tmp_in};
use cvm_core::command::{Key, Store};
use cvm_core::protocol::{self, HeaderInfo, Line};
use cvm_core::record::{Tag, encoded_len};
use cvm_core::settings::Source;
use cvm_core::{Config, Geometry, Scorer};
use cvm_fw_app::flash_words::WORD;
use cvm_fw_app::settings_store::{VALUES, Values};
use cvm_fw_app_tests::bank::{self, Bank, EraseCut, H743_STORE, SECTOR};
use dmap::npy::write_scan_u16;
use std::path::Path;
use std::process::{Command, Output};

const ROWS: usize = 5;
const COLS: usize = 10;
const J: usize = 9;

/// A scan with a planted bright blob over a random background.
fn write_scan(path: &Path) {
    let mut state = 99u64;
    let mut data = Vec::with_capacity(ROWS * COLS * J * J);
    for r in 0..ROWS {
        for c in 0..COLS {
            for k in 0..J * J {
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                let mut v = 500 + (state >> 33) as u16 % 300;
                if (r, c) == (2, 4) && k % 2 == 0 {
                    v += 6000;
                }
                data.push(v);
            }
        }
    }
    let g = cvm_reference::Geometry::new(J, J).unwrap();
    write_scan_u16(path, ROWS, COLS, g, &data).unwrap();
}

fn dmap(args: &[&str]) -> Output {
    let out = Command::new(env!("CARGO_BIN_EXE_dmap"))
        .args(args)
        .output()
        .expect("running dmap");
    assert!(
        out.status.success(),
        "dmap {args:?} failed ({}):\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// The configuration `dmap twin` builds the firmware for, for this scan
/// with the default scoring options.
fn config() -> Config {
    Config::paper(Geometry::new(J as u8, J as u8).unwrap())
}

/// A record's values: the settings `dmap stream` takes as `--threshold
/// thr --power-threshold pthr --max-defect-lines dcap` and `--scores`,
/// the scan's size, and the outputs' compiled values.
fn values(thr: f64, pthr: f64, scores: bool, dcap: u16) -> Values {
    let scorer = Scorer::new(&config()).unwrap();
    Key::ALL.map(|k| match k {
        Key::Cols => COLS as u32,
        Key::Rows => ROWS as u32,
        Key::Threshold => scorer.threshold_from_units(thr),
        Key::PowerThreshold => cvm_core::power::threshold_from_units(pthr),
        // `dmap stream`'s default: the spread channel off.
        Key::SpreadThreshold => cvm_core::spread::SPREAD_OFF,
        Key::Scores => scores as u32,
        Key::DefectCap => dcap as u32,
        Key::MinArea
        | Key::MinPeak
        | Key::MaxMissing
        | Key::MaxMisplaced
        | Key::RejectMode
        | Key::Pulse
        | Key::RowDelay => 0,
        Key::ReadyLevel => 1,
        Key::RejectLevel => 0,
    })
}

/// The options of [`values`] for `dmap stream`.
const STORED: (f64, f64, bool, u16) = (0.05, 0.3, true, 2);
const STORED_OPTS: [&str; 7] = [
    "--threshold",
    "0.05",
    "--power-threshold",
    "0.3",
    "--scores",
    "--max-defect-lines",
    "2",
];

fn stored() -> Values {
    values(STORED.0, STORED.1, STORED.2, STORED.3)
}

fn header(line: &str) -> HeaderInfo<'static> {
    let l: &'static str = Box::leak(format!("{line}\n").into_boxed_str());
    match protocol::parse(l.as_bytes()) {
        Ok(Line::Header(h)) => h,
        other => panic!("{other:?}: {l}"),
    }
}

/// `dmap twin` over the scan with the default options and bank 2 from
/// `flash`: its lines after the header must be `dmap stream`'s with
/// `stream_opts`, its header must carry the same settings, each sourced
/// `src`, and the store state `store`. Returns the model's counters.
fn twin_scans_with(
    tag: &str,
    flash: &Path,
    stream_opts: &[&str],
    src: Source,
    store: Store,
) -> serde_json::Value {
    let scan = tmp_in(tag, "scan.npy");
    write_scan(&scan);
    let host = dmap(&[&["stream", s(&scan)], stream_opts].concat());
    // A status request at the first beam: its reply says the same. The
    // first beam 2.5 s after reset: a start that repairs the store erases
    // a sector first (up to 2 s at x64, the model's time for it).
    let twin = dmap(&[
        "twin",
        s(&scan),
        "--flash",
        s(flash),
        "--start-ms",
        "2500",
        "--command",
        "0:status",
    ]);
    let (host, out) = (
        String::from_utf8(host.stdout).unwrap(),
        String::from_utf8(twin.stdout.clone()).unwrap(),
    );
    let (replies, got): (Vec<&str>, Vec<&str>) = out.lines().partition(|l| l.starts_with("A,"));
    let want: Vec<&str> = host.lines().collect();
    assert!(
        replies[0].starts_with("A,1,ok,status,")
            && replies[0].contains(&format!(",store={},", store.word())),
        "{replies:?}"
    );
    assert_eq!(replies.len(), 1 + VALUES, "{replies:?}");
    for r in &replies[1..] {
        let tail = format!(":{}*", src.as_char() as char);
        assert!(r.starts_with("A,1,ok,") && r.contains(&tail), "{r}");
    }
    assert!(
        got.len() > 2 && got[1..] == want[1..],
        "the firmware did not scan with {stream_opts:?}:\n--- stream\n{host}\n--- twin\n{}",
        got.join("\n")
    );
    let (h, w) = (header(got[0]), header(want[0]));
    assert_eq!(
        (
            h.threshold,
            h.power_threshold,
            h.scores,
            h.max_defect_lines,
            h.cols
        ),
        (
            w.threshold,
            w.power_threshold,
            w.scores,
            w.max_defect_lines,
            w.cols
        ),
        "{}",
        got[0]
    );
    let origin = h.origin.expect("a version 6 header");
    assert_eq!(origin.sources, [src; VALUES], "{}", got[0]);
    assert_eq!(origin.store, store, "{}", got[0]);
    let c = counters(&twin);
    assert_eq!(c["status"], "done", "{c}");
    assert_eq!(c["resets"], serde_json::json!([]), "{c}");
    c
}

#[test]
fn the_stored_values_are_not_the_defaults() {
    // Otherwise the tests below could not tell a loaded record from none.
    let defaults = values(0.5, 1e9, false, 0);
    for k in [
        Key::Threshold,
        Key::PowerThreshold,
        Key::Scores,
        Key::DefectCap,
    ] {
        assert_ne!(stored()[k.index()], defaults[k.index()], "{k:?}");
    }
}

#[test]
fn an_erased_bank_leaves_the_compiled_settings() {
    let flash = tmp_in("store-erased", "bank2.bin");
    let _ = std::fs::remove_file(&flash);
    let c = twin_scans_with("store-erased", &flash, &[], Source::Default, Store::Empty);
    assert_eq!(
        c["flash_operations"], 0,
        "the firmware read, and wrote nothing: {c}"
    );
    assert!(c["flash_dma_reads"].as_u64() > Some(0), "{c}");
    assert_eq!(
        bank::read_record(&flash, &Tag::new(&config())).unwrap(),
        (Store::Empty, None)
    );
}

#[test]
fn a_record_of_this_build_replaces_the_compiled_settings() {
    let flash = tmp_in("store-loaded", "bank2.bin");
    let _ = std::fs::remove_file(&flash);
    bank::write_record(&flash, &Tag::new(&config()), &stored()).unwrap();
    let c = twin_scans_with(
        "store-loaded",
        &flash,
        &STORED_OPTS,
        Source::Flash,
        Store::Loaded,
    );
    assert_eq!(c["flash_operations"], 0, "{c}");
    assert_eq!(c["flash_ecc_errors"], 0, "{c}");
}

#[test]
fn a_record_of_another_build_is_ignored() {
    let flash = tmp_in("store-foreign", "bank2.bin");
    let _ = std::fs::remove_file(&flash);
    let other = Config::paper(Geometry::new(J as u8, J as u8 - 1).unwrap());
    bank::write_record(&flash, &Tag::new(&other), &stored()).unwrap();
    twin_scans_with(
        "store-foreign",
        &flash,
        &[],
        Source::Default,
        Store::Foreign,
    );
}

#[test]
fn a_record_beyond_this_builds_capacity_is_ignored() {
    let flash = tmp_in("store-capacity", "bank2.bin");
    let _ = std::fs::remove_file(&flash);
    let mut v = stored();
    v[Key::Cols.index()] = COLS as u32 + 1;
    bank::write_record(&flash, &Tag::new(&config()), &v).unwrap();
    twin_scans_with(
        "store-capacity",
        &flash,
        &[],
        Source::Default,
        Store::Unreadable,
    );
}

/// Where the next item after the first record starts (page marker, header
/// word, data words).
fn after_first_record() -> usize {
    H743_STORE.start as usize + 2 * WORD + encoded_len(VALUES).next_multiple_of(WORD)
}

#[test]
fn a_half_programmed_word_after_the_record_does_not_stop_the_board() {
    let flash = tmp_in("store-torn", "bank2.bin");
    let _ = std::fs::remove_file(&flash);
    bank::write_record(&flash, &Tag::new(&config()), &stored()).unwrap();
    // A second save cut while programming its item header.
    let b = Bank::load(&flash).unwrap();
    b.half_program(after_first_record(), &[0x5A; WORD]);
    b.save(&flash).unwrap();
    let c = twin_scans_with(
        "store-torn",
        &flash,
        &STORED_OPTS,
        Source::Flash,
        Store::Loaded,
    );
    assert!(
        c["flash_ecc_errors"].as_u64() >= Some(1),
        "the torn word was read: {c}"
    );
}

#[test]
fn a_half_programmed_page_marker_leaves_the_compiled_settings() {
    let flash = tmp_in("store-marker", "bank2.bin");
    let b = Bank::erased();
    b.half_program(H743_STORE.start as usize, &[0; WORD]);
    b.save(&flash).unwrap();
    let c = twin_scans_with("store-marker", &flash, &[], Source::Default, Store::Empty);
    assert!(c["flash_ecc_errors"].as_u64() >= Some(1), "{c}");
}

/// A bank whose first page is full of records (the last one `stored()`),
/// whose next save (`next`) was cut while erasing the first page, after
/// the newest record was copied to the second.
fn cut_during_an_erase(next: &Values) -> Bank {
    let tag = Tag::new(&config());
    let b = Bank::erased();
    let item = WORD + encoded_len(VALUES).next_multiple_of(WORD);
    let per_page = (SECTOR - 2 * WORD) / item;
    let mut filler = stored();
    for n in 1..per_page {
        filler[Key::Threshold.index()] = 1000 + n as u32;
        embassy_futures::block_on(bank::h743_store(&b).save(&tag, &filler)).unwrap();
    }
    embassy_futures::block_on(bank::h743_store(&b).save(&tag, &stored())).unwrap();
    // The operation of the next save that erases page 0: the one after
    // which page 0's start marker reads erased.
    for k in 1.. {
        let run = b.snapshot();
        run.cut_at(k, EraseCut::FirstHalf);
        let r = embassy_futures::block_on(bank::h743_store(&run).save(&tag, next));
        assert!(r.is_err(), "the save ended before page 0 was erased");
        if run.bytes(0..WORD).iter().all(|&x| x == 0xFF) {
            run.reboot();
            return run;
        }
    }
    unreachable!()
}

#[test]
fn a_half_erased_sector_is_erased_again_at_start_up_and_the_old_record_loaded() {
    let flash = tmp_in("store-erase-cut", "bank2.bin");
    let next = values(0.9, 0.9, false, 1);
    let b = cut_during_an_erase(&next);
    assert!(
        b.bytes(SECTOR - WORD..SECTOR).iter().any(|&x| x != 0xFF),
        "the second half of page 0, its end marker included, is as it was"
    );
    b.save(&flash).unwrap();
    let c = twin_scans_with(
        "store-erase-cut",
        &flash,
        &STORED_OPTS,
        Source::Flash,
        Store::Loaded,
    );
    // The store's repair erased page 0 again, through the firmware's
    // bank-2 driver: the model's flash file shows it whole.
    assert_eq!(c["flash_operations"], 1, "one sector erase: {c}");
    let after = Bank::load(&flash).unwrap();
    assert!(
        after.bytes(0..SECTOR).iter().all(|&x| x == 0xFF),
        "page 0 erased"
    );
    let got = bank::read_record(&flash, &Tag::new(&config())).unwrap();
    assert_eq!(got, (Store::Loaded, Some(stored())));
}

// ---- `save` on the command channel, and power cuts during it

/// Requests at beam 5: `set` each of `sets` (ids from 1), then `save`.
fn save_requests(tag: &str, sets: &[String]) -> std::path::PathBuf {
    let mut bytes = Vec::new();
    for (i, set) in sets.iter().enumerate() {
        bytes.extend(framed(&format!("C,{},set,{set}", i + 1)));
    }
    bytes.extend(framed(&format!("C,{},save", sets.len() + 1)));
    let path = tmp_in(tag, "requests.txt");
    dmap::twin::requests::write_requests(&path, &[(5, &bytes)]).unwrap();
    path
}

/// `dmap twin` over the scan with `extra` options; its output and
/// counters. Beams 60 ms apart: the scan lasts 3 s, longer than a save
/// that erases a sector (up to 2 s at x64, the model's time for it).
fn twin(tag: &str, extra: &[&str]) -> (String, serde_json::Value) {
    let scan = tmp_in(tag, "scan.npy");
    write_scan(&scan);
    let out = dmap(&[&["twin", s(&scan), "--beam-us", "60000"], extra].concat());
    (
        String::from_utf8(out.stdout.clone()).unwrap(),
        counters(&out),
    )
}

/// The settings of `record` that `B`'s requests change, as `set` values.
fn sets_of(v: &Values) -> Vec<String> {
    [Key::Threshold, Key::DefectCap]
        .iter()
        .map(|k| format!("{}={}", k.name(), v[k.index()]))
        .collect()
}

#[test]
fn set_save_and_a_restart_bring_the_saved_values_from_flash() {
    let flash = tmp_in("store-save", "bank2.bin");
    let _ = std::fs::remove_file(&flash);
    let new = stored();
    let mut sets = sets_of(&new);
    sets.push("scores=1".into());
    sets.push(format!("pthr={}", new[Key::PowerThreshold.index()]));
    let req = save_requests("store-save", &sets);
    let (out, c) = twin("store-save", &["--requests", s(&req), "--flash", s(&flash)]);
    let id = sets.len() + 1;
    assert!(
        out.lines()
            .any(|l| l.starts_with(&format!("A,{id},ok,save"))),
        "{out}"
    );
    assert!(out.contains(",missing=0,"), "a save costs no beam:\n{out}");
    // A header word and the record's words (the first save also opens
    // the page with its start marker).
    let words = 1 + encoded_len(VALUES).div_ceil(WORD) as u64;
    assert_eq!(c["flash_operations"], 1 + words, "{c}");
    assert_eq!(c["flash_double_programs"], 0, "{c}");
    // What the firmware wrote is the record of these settings, as the
    // host side of the store reads it.
    assert_eq!(
        bank::read_record(&flash, &Tag::new(&config())).unwrap(),
        (Store::Loaded, Some(new))
    );
    // The restart: every value from flash.
    twin_scans_with(
        "store-save",
        &flash,
        &STORED_OPTS,
        Source::Flash,
        Store::Loaded,
    );
}

/// The new settings of the cut saves, and their `dmap stream` options.
fn new_values() -> Values {
    values(0.2, STORED.1, STORED.2, 5)
}
const NEW_OPTS: [&str; 7] = [
    "--threshold",
    "0.2",
    "--power-threshold",
    "0.3",
    "--scores",
    "--max-defect-lines",
    "5",
];

/// A save of [`new_values`] over bank 2 `base` (whose newest record is
/// `stored()`), cut at each of its flash operations in turn, each cut in
/// its own run; after each, the record is the old or the new one and a
/// reboot scans with it. Returns the save's operations.
fn cut_every_operation(tag_s: &str, base: &Path) -> u64 {
    let tag = Tag::new(&config());
    let (old, new) = (stored(), new_values());
    let req = save_requests(tag_s, &sets_of(&new));
    // The save uncut: how many flash operations it makes.
    let whole = tmp_in(tag_s, "whole.bin");
    std::fs::copy(base, &whole).unwrap();
    let (out, c) = twin(tag_s, &["--requests", s(&req), "--flash", s(&whole)]);
    assert!(out.contains(",missing=0,"), "a save costs no beam:\n{out}");
    assert_eq!(c["flash_double_programs"], 0, "{c}");
    assert_eq!(
        bank::read_record(&whole, &tag).unwrap(),
        (Store::Loaded, Some(new))
    );
    let ops = c["flash_operations"].as_u64().unwrap();
    // One cut per operation, each on its own copy of the bank and its own
    // scan file, as many at once as the machine has cores: the longest
    // test of the suite, it would otherwise run alone at the end.
    let cut_at = |n: u64| -> bool {
        let tag_n = format!("{tag_s}-cut{n}");
        let cut = tmp_in(&tag_n, "bank.bin");
        std::fs::copy(base, &cut).unwrap();
        let n_s = n.to_string();
        let (_, c) = twin(
            &tag_n,
            &[
                "--requests",
                s(&req),
                "--flash",
                s(&cut),
                "--power-cut",
                &n_s,
            ],
        );
        assert_eq!(c["status"], "power cut", "cut at {n}: {c}");
        let got = bank::read_record(&cut, &tag).unwrap();
        let (is_old, opts) = if got == (Store::Loaded, Some(old)) {
            (true, STORED_OPTS)
        } else if got == (Store::Loaded, Some(new)) {
            (false, NEW_OPTS)
        } else {
            panic!("cut at {n} of {ops}: {got:?}, neither the old settings nor the new");
        };
        // The reboot scans with them, every value from flash.
        twin_scans_with(&tag_n, &cut, &opts, Source::Flash, Store::Loaded);
        is_old
    };
    let workers = std::thread::available_parallelism().map_or(1, |n| n.get()) as u64;
    let olds: u64 = std::thread::scope(|scope| {
        let cut_at = &cut_at;
        let handles: Vec<_> = (0..workers)
            .map(|w| {
                scope.spawn(move || {
                    (1 + w..=ops)
                        .step_by(workers as usize)
                        .filter(|&n| cut_at(n))
                        .count() as u64
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).sum()
    });
    let news = ops - olds;
    // The new record counts once its last word is programmed, the save's
    // last operation: every cut leaves the old one.
    assert_eq!((olds, news), (ops, 0));
    ops
}

#[test]
fn a_power_cut_at_every_flash_operation_of_a_save_leaves_the_old_or_the_new_settings() {
    let base = tmp_in("store-cut", "old.bin");
    let _ = std::fs::remove_file(&base);
    bank::write_record(&base, &Tag::new(&config()), &stored()).unwrap();
    let ops = cut_every_operation("store-cut", &base);
    assert_eq!(ops, 1 + encoded_len(VALUES).div_ceil(WORD) as u64);
}

#[test]
fn a_power_cut_at_every_flash_operation_of_a_save_that_switches_sectors() {
    // The first sector full: the save closes it, opens the second, copies
    // the newest record there, erases the first and writes the new one.
    let base = tmp_in("store-cut-switch", "old.bin");
    let tag = Tag::new(&config());
    let b = Bank::erased();
    let item = WORD + encoded_len(VALUES).next_multiple_of(WORD);
    let mut filler = stored();
    for n in 1..(SECTOR - 2 * WORD) / item {
        filler[Key::Threshold.index()] = 1000 + n as u32;
        embassy_futures::block_on(bank::h743_store(&b).save(&tag, &filler)).unwrap();
    }
    embassy_futures::block_on(bank::h743_store(&b).save(&tag, &stored())).unwrap();
    b.save(&base).unwrap();
    let words = 1 + encoded_len(VALUES).div_ceil(WORD) as u64;
    let ops = cut_every_operation("store-cut-switch", &base);
    assert_eq!(
        ops,
        2 + words + 1 + words,
        "markers, copy, erase, new record"
    );
}
