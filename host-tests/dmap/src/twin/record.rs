//! The settings a `dmap twin` run hands the firmware the way a user
//! deploys them: as the settings record in bank 2 of the flash, which the
//! firmware loads at start-up. The record is written on the host with the
//! product's own code (`cvm_core::record` for the record and its tag,
//! `cvm_fw_app::settings_store` for `sequential-storage`'s layout) over a
//! bank held in memory, into the range `memory.x` reserves
//! (`SETTINGS`: bank 2's first two sectors), and saved in the chip model's
//! `--flash` format (`host-tests/twin/h743twin/flash.py`): the bank's
//! cells, then one byte per flash word (bit 0: programmed since its
//! erase). What the firmware reads is what a board that saved these
//! settings would hold.

use anyhow::{Result, bail};
use cvm_core::command::{Capacity, Key, conflict};
use cvm_core::record::Tag;
use cvm_core::settings::Settings;
use cvm_fw_app::flash_words::{Fault, FlashWords, WORD, Words};
use cvm_fw_app::settings_store::{SettingsStore, Values};
use std::ops::Range;

/// Bytes of bank 2.
const BANK: usize = 1 << 20;
/// The chip's erase sector.
const SECTOR: usize = 128 << 10;
/// The settings range in bank 2 (`memory.x`, `SETTINGS`).
const STORE: Range<u32> = 0..2 * SECTOR as u32;

/// What an H743 build for scans of `cols` columns may be set to
/// (`src/h743/mod.rs`, `CAPACITY`).
pub fn h743_capacity(cols: u16) -> Capacity {
    Capacity {
        max_cols: cols,
        max_rows: u16::MAX,
        max_dcap: 16,
        max_pulse_us: 1 << 16,
    }
}

/// The record's values for `settings` on a board of capacity `cap`,
/// refused (naming the key) where the firmware would refuse the record
/// and fall back to its compiled values.
pub fn values(settings: &Settings, cap: &Capacity) -> Result<Values> {
    let values = Key::ALL.map(|k| k.get(settings));
    for (k, &v) in Key::ALL.iter().zip(&values) {
        let (lo, hi) = k.range(cap);
        if v < lo || v > hi {
            bail!(
                "the H743 firmware takes {}={v} only in {lo}..={hi}",
                k.name()
            );
        }
    }
    if conflict(settings) {
        bail!("REJECT's row mode needs a pulse width");
    }
    Ok(values)
}

/// Bank 2 holding the settings record of a run: `settings` (the run's,
/// as `dmap stream` scores with them, the outputs' options applied) for one
/// part's scan (`part`), made for the build of `part`
/// ([`crate::twin::h743_build_config`]).
pub fn settings_record(
    settings: &cvm_core::Settings,
    part: &cvm_fw_app::emufile::ScanHeader,
) -> Result<Vec<u8>> {
    let mut s = *settings;
    s.rows = part.rows;
    let cols = u16::try_from(part.cols)
        .map_err(|_| anyhow::anyhow!("the H743 firmware takes at most 65535 columns"))?;
    let values = values(&s, &h743_capacity(cols))?;
    bank_image(&cvm_core::record::Tag::new(&part.config), &values)
}

/// Bank 2 held in memory: its cells and which flash words were programmed.
struct Bank {
    cells: Vec<u8>,
    programmed: Vec<bool>,
}

impl FlashWords for Bank {
    const SECTOR: usize = SECTOR;

    fn capacity(&self) -> usize {
        STORE.end as usize
    }

    async fn read(&mut self, offset: u32, buf: &mut [u8]) -> Result<(), Fault> {
        let at = offset as usize;
        let src = self.cells.get(at..at + buf.len()).ok_or(Fault::Bounds)?;
        buf.copy_from_slice(src);
        Ok(())
    }

    async fn program(&mut self, offset: u32, word: &[u8; WORD]) -> Result<(), Fault> {
        let at = offset as usize;
        let cells = self.cells.get_mut(at..at + WORD).ok_or(Fault::Bounds)?;
        for (c, w) in cells.iter_mut().zip(word) {
            *c &= w;
        }
        // Programmed once per erase, as the chip's ECC requires.
        if std::mem::replace(&mut self.programmed[at / WORD], true) {
            return Err(Fault::Program(0));
        }
        Ok(())
    }

    async fn erase(&mut self, offset: u32) -> Result<(), Fault> {
        let at = offset as usize;
        self.cells
            .get_mut(at..at + SECTOR)
            .ok_or(Fault::Bounds)?
            .fill(0xFF);
        self.programmed[at / WORD..(at + SECTOR) / WORD].fill(false);
        Ok(())
    }
}

/// Runs a future of the in-memory bank, which never waits, to its end.
fn block_on<F: std::future::Future>(f: F) -> F::Output {
    let mut f = std::pin::pin!(f);
    let mut cx = std::task::Context::from_waker(std::task::Waker::noop());
    loop {
        if let std::task::Poll::Ready(v) = f.as_mut().poll(&mut cx) {
            return v;
        }
    }
}

/// The chip model's bank 2 image of an erased bank into which a firmware
/// built for `tag` saved `values`.
pub fn bank_image(tag: &Tag, values: &Values) -> Result<Vec<u8>> {
    let bank = Bank {
        cells: vec![0xFF; BANK],
        programmed: vec![false; BANK / WORD],
    };
    let mut store = SettingsStore::new(Words::new(bank), STORE)
        .map_err(|e| anyhow::anyhow!("the settings range is refused: {e:?}"))?;
    block_on(store.save(tag, values))
        .map_err(|e| anyhow::anyhow!("saving the settings record: {e:?}"))?;
    let bank = &store.flash().flash;
    let mut image = bank.cells.clone();
    image.extend(bank.programmed.iter().map(|&p| u8::from(p)));
    Ok(image)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_image_holds_the_record_where_the_firmware_reads_it() {
        let config = cvm_core::Config {
            geometry: cvm_core::Geometry::new(9, 9).unwrap(),
            kernels: cvm_core::Kernels::Paper { bmax: 0 },
            weights: cvm_core::Weights::Uniform,
            normalise: true,
            full_scale: u16::MAX,
        };
        let tag = Tag::new(&config);
        let mut settings = Settings::new(12, 6, 1234, 3277);
        settings.scores = true;
        let v = values(&settings, &h743_capacity(12)).unwrap();
        assert_eq!(v[Key::Threshold.index()], 1234);
        let image = bank_image(&tag, &v).unwrap();
        assert_eq!(image.len() as u64, crate::twin::requests::FLASH_IMAGE_BYTES);
        // Read back by the product's store over the same cells.
        let bank = Bank {
            cells: image[..BANK].to_vec(),
            programmed: image[BANK..].iter().map(|&b| b != 0).collect(),
        };
        let mut store = SettingsStore::new(Words::new(bank), STORE).unwrap();
        let (state, got) = block_on(store.load(&tag));
        assert_eq!(state, cvm_core::command::Store::Loaded);
        assert_eq!(got, Some(v));
        // Nothing outside the settings range is touched.
        assert!(image[STORE.end as usize..BANK].iter().all(|&b| b == 0xFF));
        // A value the board would refuse is refused here.
        assert!(values(&settings, &h743_capacity(11)).is_err());
    }
}
