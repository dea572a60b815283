//! The settings kept in flash, read at start-up by the H743 release
//! firmware on the chip model (`dmap twin --flash FILE`): bank 2 images
//! written by the host side of the same store (cvm_fw_app_tests::bank,
//! the chip model's file format), then the firmware's output compared
//! byte for byte with `dmap stream`'s. A record of this build replaces
//! the compiled settings; a record of another build, an erased bank, a
//! half-programmed flash word (a power cut while programming) and a
//! half-erased sector (a power cut while erasing) never stop it from
//! starting. Needs what tests/twin.rs needs.

mod common;

use common::{s, tmp_in};
use cvm_core::command::{Key, Store};
use cvm_core::record::{Tag, encoded_len};
use cvm_core::{Config, Geometry, Scorer};
use cvm_fw_app::flash_words::WORD;
use cvm_fw_app::settings_store::{VALUES, Values};
use cvm_fw_app_tests::bank::{self, Bank, EraseCut, H743_STORE, SECTOR, h743_capacity};
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

/// The model's counters: the last line of standard error.
fn counters(out: &Output) -> serde_json::Value {
    let err = String::from_utf8_lossy(&out.stderr);
    let last = err.lines().rfind(|l| !l.trim().is_empty()).unwrap_or("");
    serde_json::from_str(last).unwrap_or_else(|e| panic!("no JSON counters ({e}) in:\n{err}"))
}

/// The configuration `dmap twin` builds the firmware for, for this scan
/// with the default scoring options.
fn config() -> Config {
    Config::paper(Geometry::new(J as u8, J as u8).unwrap())
}

/// A record's values: the settings `dmap stream` takes as `--threshold
/// thr --power-threshold pthr --max-defect-lines dcap` and `--scores`.
fn values(thr: f64, pthr: f64, scores: bool, dcap: u16) -> Values {
    let scorer = Scorer::new(&config()).unwrap();
    Key::ALL.map(|k| match k {
        Key::Cols => COLS as u32,
        Key::Rows => ROWS as u32,
        Key::Threshold => scorer.threshold_from_units(thr),
        Key::PowerThreshold => cvm_core::power::threshold_from_units(pthr),
        Key::Scores => scores as u32,
        Key::DefectCap => dcap as u32,
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

/// `dmap twin` over the scan with the default options and bank 2 from
/// `flash`; its output must be `dmap stream`'s with `stream_opts`.
fn twin_is_stream(tag: &str, flash: &Path, stream_opts: &[&str]) -> serde_json::Value {
    let scan = tmp_in(tag, "scan.npy");
    write_scan(&scan);
    let host = dmap(&[&["stream", s(&scan)], stream_opts].concat());
    let twin = dmap(&["twin", s(&scan), "--flash", s(flash)]);
    assert!(
        twin.stdout == host.stdout,
        "the firmware did not scan with {stream_opts:?}:\n--- stream\n{}\n--- twin\n{}",
        String::from_utf8_lossy(&host.stdout),
        String::from_utf8_lossy(&twin.stdout)
    );
    let c = counters(&twin);
    assert_eq!(c["status"], "done", "{c}");
    assert_eq!(c["resets"], serde_json::json!([]), "{c}");
    c
}

#[test]
fn the_stored_values_are_not_the_defaults() {
    // Otherwise the tests below could not tell a loaded record from none.
    let defaults = values(0.5, 1e9, false, 0);
    for (i, k) in Key::ALL.iter().enumerate() {
        if !matches!(k, Key::Cols | Key::Rows) {
            assert_ne!(stored()[i], defaults[i], "{k:?}");
        }
    }
}

#[test]
fn an_erased_bank_leaves_the_compiled_settings() {
    let flash = tmp_in("store-erased", "bank2.bin");
    let _ = std::fs::remove_file(&flash);
    let c = twin_is_stream("store-erased", &flash, &[]);
    assert_eq!(
        c["flash_operations"], 0,
        "the firmware read, and wrote nothing: {c}"
    );
    assert!(c["flash_dma_reads"].as_u64() > Some(0), "{c}");
    let (state, _) =
        bank::read_record(&flash, &Tag::new(&config()), h743_capacity(COLS as u16)).unwrap();
    assert_eq!(state, Store::Empty);
}

#[test]
fn a_record_of_this_build_replaces_the_compiled_settings() {
    let flash = tmp_in("store-loaded", "bank2.bin");
    let _ = std::fs::remove_file(&flash);
    bank::write_record(&flash, &Tag::new(&config()), &stored()).unwrap();
    let c = twin_is_stream("store-loaded", &flash, &STORED_OPTS);
    assert_eq!(c["flash_operations"], 0, "{c}");
    assert_eq!(c["flash_ecc_errors"], 0, "{c}");
}

#[test]
fn a_record_of_another_build_is_ignored() {
    let flash = tmp_in("store-foreign", "bank2.bin");
    let _ = std::fs::remove_file(&flash);
    let other = Config::paper(Geometry::new(J as u8, J as u8 - 1).unwrap());
    bank::write_record(&flash, &Tag::new(&other), &stored()).unwrap();
    let (state, _) =
        bank::read_record(&flash, &Tag::new(&config()), h743_capacity(COLS as u16)).unwrap();
    assert_eq!(state, Store::Foreign);
    twin_is_stream("store-foreign", &flash, &[]);
}

#[test]
fn a_record_beyond_this_builds_capacity_is_ignored() {
    let flash = tmp_in("store-capacity", "bank2.bin");
    let _ = std::fs::remove_file(&flash);
    let mut v = stored();
    v[Key::ALL.iter().position(|&k| k == Key::Cols).unwrap()] = COLS as u32 + 1;
    bank::write_record(&flash, &Tag::new(&config()), &v).unwrap();
    twin_is_stream("store-capacity", &flash, &[]);
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
    let c = twin_is_stream("store-torn", &flash, &STORED_OPTS);
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
    let c = twin_is_stream("store-marker", &flash, &[]);
    assert!(c["flash_ecc_errors"].as_u64() >= Some(1), "{c}");
}

/// A bank whose first page is full of records (the last one `stored()`),
/// whose next save (`next`) was cut while erasing the first page, after
/// the newest record was copied to the second.
fn cut_during_an_erase(next: &Values) -> Bank {
    let tag = Tag::new(&config());
    let cap = h743_capacity(COLS as u16);
    let b = Bank::erased();
    let item = WORD + encoded_len(VALUES).next_multiple_of(WORD);
    let per_page = (SECTOR - 2 * WORD) / item;
    let mut filler = stored();
    let thr = Key::ALL.iter().position(|&k| k == Key::Threshold).unwrap();
    for n in 1..per_page {
        filler[thr] = 1000 + n as u32;
        embassy_futures::block_on(bank::h743_store(&b, cap).save(&tag, &filler)).unwrap();
    }
    embassy_futures::block_on(bank::h743_store(&b, cap).save(&tag, &stored())).unwrap();
    // The operation of the next save that erases page 0: the one after
    // which page 0's start marker reads erased.
    for k in 1.. {
        let run = b.snapshot();
        run.cut_at(k, EraseCut::FirstHalf);
        let r = embassy_futures::block_on(bank::h743_store(&run, cap).save(&tag, next));
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
    let c = twin_is_stream("store-erase-cut", &flash, &STORED_OPTS);
    // The store's repair erased page 0 again, through the firmware's
    // bank-2 driver: the model's flash file shows it whole.
    assert_eq!(c["flash_operations"], 1, "one sector erase: {c}");
    let after = Bank::load(&flash).unwrap();
    assert!(
        after.bytes(0..SECTOR).iter().all(|&x| x == 0xFF),
        "page 0 erased"
    );
    let got = bank::read_record(&flash, &Tag::new(&config()), h743_capacity(COLS as u16)).unwrap();
    assert_eq!(got, (Store::Loaded, Some(stored())));
}
