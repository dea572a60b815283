//! The runtime settings kept in flash on this board: the store
//! (`cvm_fw_app::settings_store`) on the range of bank 2 that
//! `boards/h743/memory.x` reserves (`SETTINGS`), through the bank-2 driver
//! (`flash_bank2`). At start-up the record is read before the scoring
//! side is built, and its values replace the compiled ones; a save is
//! [`save`], from an async task. Any failure leaves the compiled values in
//! place: the board always starts.

use cvm_core::command::{Capacity, Store};
use cvm_core::record::Tag;
use cvm_fw_app::flash_words::Words;
use cvm_fw_app::settings_store::{SettingsStore, StoreError, Values};
use defmt::{info, warn};
use embassy_stm32::Peri;
use embassy_stm32::peripherals::{DMA1_CH7, FLASH};

use super::flash_bank2::Bank2;
use crate::config::MAX_DEFECT_LINES_PER_ROW;
use crate::config::h743::{CORE, MAX_COLS};

/// The store of this board.
pub type BoardStore = SettingsStore<Words<Bank2>>;

/// What this build's records are made for: the settings layout, and the
/// scoring configuration the tables were built for.
pub const TAG: Tag = Tag::new(&CORE);

/// The ranges stored values must fit (the record's values are checked
/// against them before they are applied): the columns the row buffers
/// hold, and the defect lines per row the queue's reserve is sized for
/// (not this build's default, `config::h743::MAX_DEFECT_LINES_PER_ROW`).
pub const CAPACITY: Capacity = {
    assert!(MAX_COLS <= u16::MAX as usize, "cols must fit 16 bits");
    Capacity {
        max_cols: MAX_COLS as u16,
        max_rows: u16::MAX,
        max_dcap: MAX_DEFECT_LINES_PER_ROW,
    }
};

/// The range `boards/h743/memory.x` reserves, from its symbols.
fn range() -> (u32, u32) {
    unsafe extern "C" {
        static __settings_start: u8;
        static __settings_end: u8;
    }
    let start = &raw const __settings_start as u32;
    let end = &raw const __settings_end as u32;
    (start, end.wrapping_sub(start))
}

/// Opens the store and reads the record (blocking: `main`, before the
/// executor runs; a few flash reads, or one sector erase when a power cut
/// interrupted one). The store is `None` when its range is unusable.
pub fn load_at_boot(
    flash: Peri<'static, FLASH>,
    dma: Peri<'static, DMA1_CH7>,
) -> (Option<BoardStore>, Store, Option<Values>) {
    let (base, len) = range();
    let store = Bank2::new(flash, dma, base, len)
        .and_then(|bank| SettingsStore::new(Words::new(bank), 0..len, CAPACITY).ok());
    let Some(mut store) = store else {
        warn!("settings flash: the reserved range is not usable; compiled settings");
        return (None, Store::Unreadable, None);
    };
    let (state, values) = embassy_futures::block_on(store.load(&TAG));
    let poisoned = store.flash().poisoned;
    info!(
        "settings flash: {} ({} unreadable flash words)",
        state.word(),
        poisoned
    );
    (Some(store), state, values)
}

/// Saves `values` as this build's record (from an async task: every wait
/// for the flash yields).
#[allow(dead_code, reason = "the command channel's `save` calls it")]
pub async fn save(store: &mut BoardStore, values: &Values) -> Result<(), StoreError> {
    let r = store.save(&TAG, values).await;
    if let Err(e) = r {
        warn!("settings flash: save failed: {}", e);
    }
    r
}
