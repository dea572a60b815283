//! The settings store (cvm_fw_app::settings_store over
//! cvm_fw_app::flash_words) on a model of the H743's bank 2 whose words
//! carry ECC (cvm_fw_app_tests::bank): what a load finds, and a power cut
//! at every flash operation of a save, with pages small enough that saves
//! cross page switches (copy, erase) often, and at the chip's geometry.
//! After each cut the board "reboots": a new store on the same cells.
//! The load must find the record entirely old or entirely new, and the
//! next save must work. No word may ever be programmed twice.

use cvm_core::command::{Key, Store};
use cvm_core::record::{Tag, encode, encoded_len};
use cvm_core::{Config, Geometry};
use cvm_fw_app::flash_words::{POISON, WORD, Words};
use cvm_fw_app::settings_store::{SettingsStore, VALUES, Values};
use cvm_fw_app_tests::bank::{self, Bank, EraseCut, H743_CAPACITY, SECTOR};
use embassy_futures::block_on;

fn tag() -> Tag {
    Tag::new(&Config::paper(Geometry::new(15, 15).unwrap()))
}

/// Distinct values within the H743's ranges, numbered by `n`.
fn values(n: u32) -> Values {
    let mut v = [0u32; VALUES];
    for (slot, k) in v.iter_mut().zip(Key::ALL) {
        let (lo, hi) = k.range(&H743_CAPACITY);
        // The store keeps any value; a key with one allowed value (the
        // outputs' levels) still gets two, so that records differ in it.
        let hi = hi.max(lo + 1);
        *slot = match (hi - lo).checked_add(1) {
            Some(span) => lo + n % span,
            None => n,
        };
    }
    v
}

/// Small erase sectors: 16 flash words, room for a few records per page.
const SMALL: usize = 16 * WORD;

fn small_store(b: &Bank) -> SettingsStore<Words<bank::Window<SMALL>>> {
    let range = 0..2 * SMALL as u32;
    SettingsStore::new(Words::new(b.window::<SMALL>(range.clone())), range).unwrap()
}

fn load_small(b: &Bank) -> (Store, Option<Values>) {
    block_on(small_store(b).load(&tag()))
}

fn load_h743(b: &Bank) -> (Store, Option<Values>) {
    block_on(bank::h743_store(b).load(&tag()))
}

#[test]
fn the_test_values_differ_in_every_key() {
    for k in 0..VALUES {
        assert_ne!(values(1)[k], values(2)[k], "key {k}");
    }
}

#[test]
fn an_erased_bank_is_empty_and_a_save_loads_back() {
    let b = Bank::erased();
    assert_eq!(load_h743(&b), (Store::Empty, None));
    block_on(bank::h743_store(&b).save(&tag(), &values(1))).unwrap();
    assert_eq!(load_h743(&b), (Store::Loaded, Some(values(1))));
    block_on(bank::h743_store(&b).save(&tag(), &values(2))).unwrap();
    assert_eq!(load_h743(&b), (Store::Loaded, Some(values(2))));
    // The first save: the page's start marker, the item's header word and
    // the record's data words (encoded_len rounded up to words).
    let b = Bank::erased();
    block_on(bank::h743_store(&b).save(&tag(), &values(1))).unwrap();
    assert_eq!(b.ops() as usize, 1 + 1 + encoded_len(VALUES).div_ceil(WORD));
}

#[test]
fn the_record_is_stored_as_the_record_module_encodes_it() {
    let b = Bank::erased();
    block_on(bank::h743_store(&b).save(&tag(), &values(5))).unwrap();
    let mut want = [0u8; 256];
    let n = encode(&tag(), &values(5), &mut want).unwrap();
    // Word 0: the page marker; word 1: the item header; then the data.
    assert_eq!(b.bytes(2 * WORD..2 * WORD + n), want[..n]);
    assert!(
        b.bytes(0..WORD).iter().all(|&x| x == 0),
        "the page's start marker"
    );
}

#[test]
fn a_record_of_another_build_is_foreign() {
    let b = Bank::erased();
    let other = Tag::new(&Config::paper(Geometry::new(9, 9).unwrap()));
    block_on(bank::h743_store(&b).save(&other, &values(3))).unwrap();
    assert_eq!(load_h743(&b), (Store::Foreign, None));
    // And a save of this build's record replaces it.
    block_on(bank::h743_store(&b).save(&tag(), &values(4))).unwrap();
    assert_eq!(load_h743(&b), (Store::Loaded, Some(values(4))));
}

/// CRC-32/ISO-HDLC (the zlib CRC), bit by bit: reflected polynomial
/// 0xEDB88320, initial and final XOR 0xFFFFFFFF.
fn crc32(data: &[u8]) -> u32 {
    let mut c = !0u32;
    for &b in data {
        c ^= u32::from(b);
        for _ in 0..8 {
            c = if c & 1 != 0 {
                (c >> 1) ^ 0xEDB8_8320
            } else {
                c >> 1
            };
        }
    }
    !c
}

/// The tag of a build of this configuration before the spread threshold
/// (settings layout 1, fifteen keys), written from the record module's
/// documented layout: layout version, CRC-32 of the keys' names each
/// followed by `,`, the key count, then the configuration bytes, which are
/// this build's.
fn tag_before_sthr() -> Tag {
    tag_of_keys(&[
        "cols", "rows", "thr", "pthr", "scores", "dcap", "area", "peak", "miss", "misp", "mode",
        "pulse", "delay", "ready", "reject",
    ])
}

/// This configuration's tag for a layout-1 build with the keys `names`.
fn tag_of_keys(names: &[&str]) -> Tag {
    let list: String = names.iter().map(|k| format!("{k},")).collect();
    let mut t = *tag().as_bytes();
    t[0..2].copy_from_slice(&1u16.to_le_bytes());
    t[2..6].copy_from_slice(&crc32(list.as_bytes()).to_le_bytes());
    t[6] = names.len() as u8;
    Tag::from_bytes(t)
}

#[test]
fn a_record_of_the_layout_before_the_spread_threshold_is_foreign() {
    // The reference rebuilds this build's own tag from its key list, so
    // it follows the documented layout.
    let names: Vec<&str> = Key::ALL.iter().map(|k| k.name()).collect();
    assert_eq!(tag_of_keys(&names), tag());
    let old = tag_before_sthr();
    assert_ne!(old, tag());
    assert_eq!(old.values(), 15);
    // The old image: fifteen distinct values, nothing of this build's.
    let vals: [u32; 15] = core::array::from_fn(|i| 100 + i as u32);
    let mut rec = [0u8; 256];
    let n = encode(&old, &vals, &mut rec).unwrap();
    assert_eq!(n, encoded_len(15));
    let b = Bank::erased();
    block_on(bank::h743_store(&b).save_bytes(&rec[..n])).unwrap();
    // Read by this build: made for another layout, ignored, not misread
    // (its pthr would land in sthr, its scores in pthr, ...).
    assert_eq!(load_h743(&b), (Store::Foreign, None));
    // The keys' digest alone tells the layouts apart, even at one count.
    let mut same_count = *old.as_bytes();
    same_count[6] = VALUES as u8;
    assert_ne!(Tag::from_bytes(same_count), tag());
    // A save of this build's record replaces the old one.
    block_on(bank::h743_store(&b).save(&tag(), &values(6))).unwrap();
    assert_eq!(load_h743(&b), (Store::Loaded, Some(values(6))));
}

#[test]
fn a_half_programmed_word_reads_as_poison_and_the_old_record_stays() {
    let b = Bank::erased();
    block_on(bank::h743_store(&b).save(&tag(), &values(1))).unwrap();
    let next = (2 + encoded_len(VALUES).div_ceil(WORD)) * WORD;
    // The next item's header, cut while programming.
    b.half_program(next, &[0x12; WORD]);
    assert!(b.unreadable(next));
    let mut store = bank::h743_store(&b);
    assert_eq!(
        block_on(store.load(&tag())),
        (Store::Loaded, Some(values(1)))
    );
    assert!(
        store.flash().poisoned > 0,
        "the bad word was read and poisoned"
    );
    let mut word = [0xAAu8; WORD];
    use embedded_storage_async::nor_flash::ReadNorFlash;
    block_on(store.flash().read(next as u32, &mut word)).unwrap();
    assert_eq!(word, POISON);
    block_on(store.save(&tag(), &values(2))).unwrap();
    assert_eq!(load_h743(&b), (Store::Loaded, Some(values(2))));
    assert_eq!(b.double_programs(), 0);
}

#[test]
fn a_half_programmed_page_marker_on_an_empty_bank() {
    let b = Bank::erased();
    b.half_program(0, &[0; WORD]);
    assert_eq!(load_h743(&b), (Store::Empty, None));
    block_on(bank::h743_store(&b).save(&tag(), &values(7))).unwrap();
    assert_eq!(load_h743(&b), (Store::Loaded, Some(values(7))));
    assert_eq!(b.double_programs(), 0);
}

/// Operations of a save of `v` on a copy of `b`.
fn ops_of_save(b: &Bank, v: &Values, small: bool) -> u32 {
    let copy = b.snapshot();
    let before = copy.ops();
    if small {
        block_on(small_store(&copy).save(&tag(), v)).unwrap();
    } else {
        block_on(bank::h743_store(&copy).save(&tag(), v)).unwrap();
    }
    copy.ops() - before
}

/// Cuts the save of `new` over `b` (which holds `old`) at each of its
/// operations; after each cut the load finds `old` or `new`, and the
/// next save works. Returns the save's operations, how many cuts left the
/// old record and how many the new one.
fn sweep(
    b: &Bank,
    old: Option<Values>,
    new: Values,
    how: EraseCut,
    small: bool,
) -> (u32, u32, u32) {
    let ops = ops_of_save(b, &new, small);
    let (mut olds, mut news) = (0, 0);
    let load = |b: &Bank| if small { load_small(b) } else { load_h743(b) };
    for k in 1..=ops {
        let run = b.snapshot();
        run.cut_at(k, how);
        let r = if small {
            block_on(small_store(&run).save(&tag(), &new))
        } else {
            block_on(bank::h743_store(&run).save(&tag(), &new))
        };
        assert!(r.is_err() && run.was_cut(), "cut at {k} of {ops}");
        run.reboot();
        match (load(&run), old) {
            ((Store::Loaded, Some(v)), _) if v == new => news += 1,
            ((Store::Loaded, Some(v)), Some(o)) if v == o => olds += 1,
            ((Store::Empty, None), None) => olds += 1,
            (got, _) => panic!("cut at {k} of {ops} ({how:?}): {got:?}, neither old nor new"),
        }
        let after = values(9999);
        let r = if small {
            block_on(small_store(&run).save(&tag(), &after))
        } else {
            block_on(bank::h743_store(&run).save(&tag(), &after))
        };
        assert_eq!(r, Ok(()), "the save after the cut at {k}");
        assert_eq!(
            load(&run),
            (Store::Loaded, Some(after)),
            "after the cut at {k}"
        );
        assert_eq!(run.double_programs(), 0, "cut at {k}");
    }
    (ops, olds, news)
}

#[test]
fn a_power_cut_at_any_operation_leaves_the_old_or_the_new_record() {
    for how in [EraseCut::FirstHalf, EraseCut::AllUnreadable] {
        let b = Bank::erased();
        let mut old = None;
        // Enough saves to go round both pages several times: page
        // switches (close, copy, erase) fall on many of them.
        for n in 0..20 {
            let new = values(n);
            // The new record counts once its last word is programmed, the
            // save's last operation: every cut leaves the old one.
            let (ops, olds, news) = sweep(&b, old, new, how, true);
            assert_eq!((olds, news), (ops, 0), "save {n}");
            block_on(small_store(&b).save(&tag(), &new)).unwrap();
            assert_eq!(load_small(&b), (Store::Loaded, Some(new)));
            old = Some(new);
        }
        assert_eq!(b.double_programs(), 0);
    }
}

#[test]
fn at_the_chips_geometry_a_full_page_switches_and_survives_cuts() {
    let b = Bank::erased();
    let item = WORD + encoded_len(VALUES).next_multiple_of(WORD);
    let per_page = (SECTOR - 2 * WORD) / item;
    let mut n = 0;
    // Fill the first page.
    while n < per_page as u32 {
        block_on(bank::h743_store(&b).save(&tag(), &values(n))).unwrap();
        n += 1;
    }
    assert_eq!(load_h743(&b), (Store::Loaded, Some(values(n - 1))));
    assert!(
        b.bytes(SECTOR..SECTOR + WORD).iter().all(|&x| x == 0xFF),
        "page 1 unused so far"
    );
    // The next save switches pages: cut it everywhere.
    for how in [EraseCut::FirstHalf, EraseCut::AllUnreadable] {
        let (ops, olds, news) = sweep(&b, Some(values(n - 1)), values(n), how, false);
        assert_eq!((olds, news), (ops, 0));
    }
    // The firmware's store: loaded at start-up, then the save. The page
    // switch reads each record of the full page once or twice (the
    // caches say where the newest one is), not the page once per record.
    let run = b.snapshot();
    let mut store = bank::h743_store(&run);
    assert_eq!(block_on(store.load(&tag())).0, Store::Loaded);
    let before = run.reads();
    block_on(store.save(&tag(), &values(n))).unwrap();
    let reads = run.reads() - before;
    let words_per_item = (item / WORD) as u64;
    assert!(
        reads <= 3 * words_per_item * per_page as u64,
        "{reads} words read to switch pages ({per_page} records of {words_per_item} words)"
    );
    let ops = ops_of_save(&b, &values(n), false);
    // Close page 0 (its end marker), open page 1 (its start marker), copy
    // the newest record there, erase page 0, then the new record.
    let item_words = 1 + encoded_len(VALUES).div_ceil(WORD) as u32;
    assert_eq!(ops, 2 + item_words + 1 + item_words, "a page switch");
    block_on(bank::h743_store(&b).save(&tag(), &values(n))).unwrap();
    assert_eq!(load_h743(&b), (Store::Loaded, Some(values(n))));
    assert!(b.bytes(0..WORD).iter().all(|&x| x == 0xFF), "page 0 erased");
    assert_eq!(b.double_programs(), 0);
}
