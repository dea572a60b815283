//! Bank-2 images for `scripts/measure.sh store-boot`, in the chip model's
//! `--flash` format, for the H743 release build (15x15 paper kernels, 300
//! columns): `cargo run -p cvm-fw-app-tests --example store_images -- DIR`
//! writes `one.bin` (one record), `full.bin` (the first page full of
//! records: the longest load) and `erase-cut.bin` (the save after that cut
//! while erasing the first page: the load repairs it with one erase).

use cvm_core::command::Key;
use cvm_core::record::{Tag, encoded_len};
use cvm_core::{Config, Geometry};
use cvm_fw_app::flash_words::WORD;
use cvm_fw_app::settings_store::{VALUES, Values};
use cvm_fw_app_tests::bank::{Bank, EraseCut, SECTOR, h743_store};
use embassy_futures::block_on;
use std::path::PathBuf;

/// Values within the release build's ranges, the threshold numbered.
fn values(n: u32) -> Values {
    Key::ALL.map(|k| match k {
        Key::Cols => 300,
        Key::Rows => 200,
        Key::Threshold => 1_000_000 + n,
        Key::PowerThreshold => 9831,
        Key::SpreadThreshold => 6554,
        Key::Scores | Key::ReadyLevel => 1,
        Key::RejectLevel => 0,
        Key::DefectCap => 4,
        Key::MinArea
        | Key::MinPeak
        | Key::MaxMissing
        | Key::MaxMisplaced
        | Key::RejectMode
        | Key::Pulse
        | Key::RowDelay => 0,
    })
}

fn save(b: &Bank, tag: &Tag, n: u32) -> Result<(), String> {
    block_on(h743_store(b).save(tag, &values(n))).map_err(|e| format!("save {n}: {e:?}"))
}

fn main() -> Result<(), String> {
    let dir = PathBuf::from(std::env::args().nth(1).ok_or("usage: store_images DIR")?);
    let tag = Tag::new(&Config::paper(Geometry::new(15, 15).unwrap()));
    let b = Bank::erased();
    save(&b, &tag, 0)?;
    b.save(&dir.join("one.bin"))?;
    let per_page = (SECTOR - 2 * WORD) / (WORD + encoded_len(VALUES).next_multiple_of(WORD));
    for n in 1..per_page as u32 {
        save(&b, &tag, n)?;
    }
    b.save(&dir.join("full.bin"))?;
    for k in 1.. {
        let run = b.snapshot();
        run.cut_at(k, EraseCut::FirstHalf);
        if save(&run, &tag, per_page as u32).is_ok() {
            return Err("the save ended before erasing the first page".into());
        }
        if run.bytes(0..WORD).iter().all(|&x| x == 0xFF) {
            run.reboot();
            return run.save(&dir.join("erase-cut.bin"));
        }
    }
    unreachable!()
}
