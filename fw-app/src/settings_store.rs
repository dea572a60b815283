//! The runtime settings kept in flash: one `sequential-storage` map item
//! that holds the whole settings record (`cvm_core::record`).
//!
//! `sequential-storage` appends each saved record to the current page and,
//! when the page is full, copies the newest record to the next page before
//! it erases the old one; an item counts only when its header and data
//! CRCs check. One item holds every value, so a power cut at any point of
//! a save leaves the previous record or the new one, never a mix of the
//! two. The map needs at least two erase sectors.
//!
//! Nothing here stops a board from starting: [`SettingsStore::load`]
//! turns every failure into a [`Store`] state with no values, and the
//! board then scans with its compiled defaults.

use core::ops::Range;

use cvm_core::command::{Key, Store};
use cvm_core::record::{self, Decoded, Tag};
use embedded_storage_async::nor_flash::NorFlash;
use sequential_storage::Error;
use sequential_storage::cache::Cache;
use sequential_storage::cache::key_pointers::ArrayKeyPointers;
use sequential_storage::cache::page_pointers::ArrayPagePointers;
use sequential_storage::cache::page_states::ArrayPageStates;
use sequential_storage::map::{MapConfig, MapStorage};

/// Values in a record: one per runtime setting, in [`Key::ALL`]'s order.
pub const VALUES: usize = Key::ALL.len();
/// The runtime settings' values, in [`Key::ALL`]'s order.
pub type Values = [u32; VALUES];
/// Bytes of this build's record.
pub const RECORD_LEN: usize = record::encoded_len(VALUES);
/// `sequential-storage`'s work buffer: the item's data, rounded up to the
/// flash's word (32 bytes on the H743; up to 64 accepted).
const BUF: usize = RECORD_LEN.next_multiple_of(64);

/// Why a save failed. The record in flash is then the previous one or
/// the new one, as after a power cut.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StoreError {
    /// The flash refused an operation (program, erase or read).
    Flash,
    /// The store's state could not be repaired; even after erasing its
    /// range the record could not be written.
    Corrupted,
    /// The record read back after the save is not the one written.
    Verify,
    /// No room (cannot happen with one item; reported, not assumed).
    Full,
    /// A misuse the code does not make (buffer sizes, a bad range).
    Internal,
}

impl<E> From<Error<E>> for StoreError {
    fn from(e: Error<E>) -> Self {
        match e {
            Error::Storage { .. } => StoreError::Flash,
            Error::Corrupted { .. } => StoreError::Corrupted,
            Error::FullStorage => StoreError::Full,
            _ => StoreError::Internal,
        }
    }
}

/// Erase sectors the store may span (the caches' size).
pub const MAX_PAGES: usize = 8;

/// `sequential-storage`'s caches (about 80 bytes): each page's state, each
/// page's first free word, and where the newest record is. Without them a
/// save that fills a sector copies the newest record after looking up, for
/// each of the sector's records, whether it is the newest, each lookup
/// reading the sector again: a sector of 1 000 records costs a million
/// reads. The caches start empty at every start-up, so the first load reads
/// the flash in full.
type Caches =
    Cache<ArrayPageStates<MAX_PAGES>, ArrayPagePointers<MAX_PAGES>, ArrayKeyPointers<(), 1>, ()>;

/// The single key of the map: the record is its only item.
type Map<S> = MapStorage<(), S, Caches>;

/// The settings record in a range of a NOR flash.
pub struct SettingsStore<S: NorFlash> {
    map: Map<S>,
    buf: [u8; BUF],
}

impl<S: NorFlash> SettingsStore<S> {
    /// The store on `range` of `flash` (whole erase sectors, at least
    /// two).
    pub fn new(flash: S, range: Range<u32>) -> Result<Self, StoreError> {
        let pages = (range.end.saturating_sub(range.start) as usize) / S::ERASE_SIZE;
        if S::READ_SIZE > 64 || S::WRITE_SIZE > 64 || pages > MAX_PAGES {
            return Err(StoreError::Internal);
        }
        let config = MapConfig::try_new(range).map_err(|_| StoreError::Internal)?;
        let caches = Cache::new(
            ArrayPageStates::new(),
            ArrayPagePointers::new(),
            ArrayKeyPointers::new(),
        );
        Ok(SettingsStore {
            map: MapStorage::new(flash, config, caches),
            buf: [0; BUF],
        })
    }

    /// The stored record, if it is one of this build (`tag`):
    /// [`Store::Loaded`] and its values (whether they fit the board's
    /// ranges is the caller's to check); otherwise the state and no values
    /// ([`Store::Empty`]: nothing stored; [`Store::Foreign`]: made by
    /// another build; [`Store::Unreadable`]: the flash or the record could
    /// not be read). May repair what a power cut during an erase left (one
    /// sector erase).
    pub async fn load(&mut self, tag: &Tag) -> (Store, Option<Values>) {
        match self.map.fetch_item::<&[u8]>(&mut self.buf, &()).await {
            Ok(None) => (Store::Empty, None),
            Ok(Some(bytes)) => match record::decode::<VALUES>(bytes, tag) {
                Decoded::Valid(v) => (Store::Loaded, Some(v)),
                Decoded::Foreign => (Store::Foreign, None),
                Decoded::Corrupt => (Store::Unreadable, None),
            },
            Err(_) => (Store::Unreadable, None),
        }
    }

    /// Stores `values` as this build's record (`tag`), then reads it back.
    /// Should the store's state be beyond `sequential-storage`'s repair,
    /// its range is erased and the record written afresh.
    pub async fn save(&mut self, tag: &Tag, values: &Values) -> Result<(), StoreError> {
        let mut rec = [0u8; RECORD_LEN];
        record::encode(tag, values, &mut rec).map_err(|_| StoreError::Internal)?;
        self.save_bytes(&rec).await
    }

    /// Stores `rec` as the record whatever it holds, then reads it back:
    /// [`SettingsStore::save`]'s write, and what tests use to leave the
    /// record of another build or layout (at most the work buffer's
    /// length).
    pub async fn save_bytes(&mut self, rec: &[u8]) -> Result<(), StoreError> {
        if rec.len() > BUF {
            return Err(StoreError::Internal);
        }
        match self.map.store_item(&mut self.buf, &(), &rec).await {
            Ok(()) => {}
            Err(Error::Corrupted { .. }) => {
                self.map.erase_all().await?;
                self.map.store_item(&mut self.buf, &(), &rec).await?;
            }
            Err(e) => return Err(e.into()),
        }
        match self.map.fetch_item::<&[u8]>(&mut self.buf, &()).await? {
            Some(back) if back == rec => Ok(()),
            _ => Err(StoreError::Verify),
        }
    }

    /// The flash, for its counters.
    pub fn flash(&mut self) -> &mut S {
        self.map.flash()
    }
}
