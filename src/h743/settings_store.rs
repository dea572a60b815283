//! The runtime settings kept in flash on this board: the store
//! (`cvm_fw_app::settings_store`) on the range of bank 2 that
//! `memory.x` reserves (`SETTINGS`), through the bank-2 driver
//! (`flash_bank2`). [`open`] takes the flash interface and DMA1 stream 7
//! in `main`; [`load`] reads the record at start-up, [`save`] writes one
//! (the store task's). Any failure is a state or an error, never a stop:
//! the board starts with its compiled values when the record cannot be
//! used.

use cvm_core::command::Store;
use cvm_core::record::Tag;
use cvm_core::settings::KEYS;
use cvm_fw_app::flash_words::Words;
use cvm_fw_app::settings_store::{SettingsStore, StoreError};
use defmt::{info, warn};
use embassy_stm32::Peri;
use embassy_stm32::peripherals::{DMA1_CH7, FLASH};
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::mutex::Mutex;

use super::flash_bank2::Bank2;
use crate::config::h743::CORE;

/// The store of this board.
type BoardStore = SettingsStore<Words<Bank2>>;

/// What this build's records are made for: the settings layout, and the
/// scoring configuration the tables were built for.
const TAG: Tag = Tag::new(&CORE);

/// The store, once [`open`] found its range usable. Only thread mode uses
/// it: `main` at start-up, then the store task.
static STORE: Mutex<CriticalSectionRawMutex, Option<BoardStore>> = Mutex::new(None);

/// The range `memory.x` reserves, from its symbols.
fn range() -> (u32, u32) {
    unsafe extern "C" {
        static __settings_start: u8;
        static __settings_end: u8;
    }
    let start = &raw const __settings_start as u32;
    let end = &raw const __settings_end as u32;
    (start, end.wrapping_sub(start))
}

/// Sets the store up on the reserved range of bank 2 (`main`, once,
/// before [`load`]). Without a usable range, [`load`] says `bad` and
/// [`save`] fails.
pub fn open(flash: Peri<'static, FLASH>, dma: Peri<'static, DMA1_CH7>) {
    let (base, len) = range();
    let store = Bank2::new(flash, dma, base, len)
        .and_then(|bank| SettingsStore::new(Words::new(bank), 0..len).ok());
    if store.is_none() {
        warn!("settings flash: the reserved range is not usable");
    }
    if let Ok(mut s) = STORE.try_lock() {
        *s = store;
    }
}

/// The record read at start-up: [`Store::Loaded`] and its values when it
/// is one of this build (`main` checks the values against the capacity);
/// a few flash reads, or one sector erase when a power cut interrupted
/// one. The flag says that the flash shows a save cut short (a word with
/// an ECC error, or a sector the load had to erase again): the power went
/// while the board was running, so its start is not a clean one.
pub async fn load() -> (Store, Option<[u32; KEYS]>, bool) {
    let mut guard = STORE.lock().await;
    let Some(store) = guard.as_mut() else {
        return (Store::Unreadable, None, false);
    };
    let (state, values) = store.load(&TAG).await;
    let words = store.flash();
    info!(
        "settings flash: {} ({} unreadable flash words, {} sectors erased)",
        state.word(),
        words.poisoned,
        words.erased
    );
    (state, values, words.poisoned > 0 || words.erased > 0)
}

/// Writes `values` as this build's record, from an async task: every
/// wait for the flash yields.
pub async fn save(values: &[u32; KEYS]) -> Result<(), StoreError> {
    let mut guard = STORE.lock().await;
    let store = guard.as_mut().ok_or(StoreError::Internal)?;
    let r = store.save(&TAG, values).await;
    if let Err(e) = r {
        warn!("settings flash: save failed: {}", e);
    }
    r
}
