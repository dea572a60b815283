//! The settings record in flash: a placeholder until the bank-2 store
//! lands. It keeps nothing: every start uses the compiled values, and
//! `save` is refused with `storage`.

use cvm_core::settings::{KEYS, Store};

/// The record read at start-up.
pub async fn load() -> (Store, Option<[u32; KEYS]>) {
    (Store::Empty, None)
}

/// Writes the record.
pub async fn save(_values: &[u32; KEYS]) -> Result<(), ()> {
    Err(())
}
