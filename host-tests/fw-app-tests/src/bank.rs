//! Bank 2 of the H743's flash, as the chip model keeps it
//! (`host-tests/twin/h743twin/flash.py`) and in the same file format, for
//! the settings store's host tests and for preparing and reading the chip
//! model's `--flash` files.
//!
//! What the chip does and this model follows: a flash word (32 bytes)
//! carries ECC over its 256 bits, so it is programmed once per erase;
//! programming it again leaves cells and ECC that disagree, and a read of
//! it is a double ECC error. A power cut at the N-th operation (erase or
//! word program, counted from 1 after [`Bank::cut_at`]) leaves it half
//! done, as the chip model does: the first half of the word programmed
//! (its ECC wrong), or the first half of the sector erased. One more
//! outcome of a cut erase, not in the chip model: every word of the
//! sector unreadable ([`EraseCut::AllUnreadable`]). After a cut every
//! operation fails until [`Bank::reboot`].
//!
//! The file: the bank's 1 MiB of cells, then one byte per flash word
//! (bit 0: programmed since its erase; bit 1: ECC wrong).

use std::cell::RefCell;
use std::ops::Range;
use std::path::Path;
use std::rc::Rc;

use cvm_core::command::{Capacity, Store};
use cvm_core::record::Tag;
use cvm_fw_app::flash_words::{Fault, FlashWords, WORD, Words};
use cvm_fw_app::settings_store::{SettingsStore, StoreError, Values};

pub const BANK: usize = 1 << 20;
/// The chip's erase sector.
pub const SECTOR: usize = 128 << 10;
/// The range of bank 2 the H743 firmware keeps its settings in (its first
/// two sectors; `memory.x`, `SETTINGS`), as offsets in the bank.
pub const H743_STORE: Range<u32> = 0..2 * SECTOR as u32;

/// What a power cut during a sector erase leaves.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EraseCut {
    /// The first half of the sector erased, the rest as it was (the chip
    /// model's choice).
    FirstHalf,
    /// Every word of the sector reads with a double ECC error.
    AllUnreadable,
}

#[derive(Clone)]
struct Cells {
    data: Vec<u8>,
    programmed: Vec<bool>,
    bad: Vec<bool>,
    ops: u32,
    cut_at: Option<u32>,
    erase_cut: EraseCut,
    dead: bool,
    double_programs: u32,
    reads: u64,
}

/// Bank 2's cells; clones share them (a store and the test that watches it).
#[derive(Clone)]
pub struct Bank(Rc<RefCell<Cells>>);

impl Default for Bank {
    fn default() -> Self {
        Bank::erased()
    }
}

impl Bank {
    pub fn erased() -> Bank {
        let words = BANK / WORD;
        Bank(Rc::new(RefCell::new(Cells {
            data: vec![0xFF; BANK],
            programmed: vec![false; words],
            bad: vec![false; words],
            ops: 0,
            cut_at: None,
            erase_cut: EraseCut::FirstHalf,
            dead: false,
            double_programs: 0,
            reads: 0,
        })))
    }

    /// A bank from a chip-model file; a missing file is an erased bank.
    pub fn load(path: &Path) -> Result<Bank, String> {
        let raw = match std::fs::read(path) {
            Ok(raw) => raw,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Bank::erased()),
            Err(e) => return Err(format!("{}: {e}", path.display())),
        };
        if raw.len() != BANK + BANK / WORD {
            return Err(format!(
                "{}: not a bank 2 image ({} bytes)",
                path.display(),
                raw.len()
            ));
        }
        let b = Bank::erased();
        {
            let mut c = b.0.borrow_mut();
            c.data.copy_from_slice(&raw[..BANK]);
            for (w, &s) in raw[BANK..].iter().enumerate() {
                c.programmed[w] = s & 1 != 0;
                c.bad[w] = s & 2 != 0;
            }
        }
        Ok(b)
    }

    pub fn save(&self, path: &Path) -> Result<(), String> {
        let c = self.0.borrow();
        let mut raw = c.data.clone();
        raw.extend(
            c.programmed
                .iter()
                .zip(&c.bad)
                .map(|(&p, &b)| p as u8 | (b as u8) << 1),
        );
        std::fs::write(path, raw).map_err(|e| format!("{}: {e}", path.display()))
    }

    /// An independent copy of the cells.
    pub fn snapshot(&self) -> Bank {
        Bank(Rc::new(RefCell::new(self.0.borrow().clone())))
    }

    /// Cuts the power at the `n`-th operation from now (1: the next one).
    pub fn cut_at(&self, n: u32, how: EraseCut) {
        let mut c = self.0.borrow_mut();
        c.cut_at = Some(c.ops + n);
        c.erase_cut = how;
    }

    /// Power back: operations work again (the cells stay as they are).
    pub fn reboot(&self) {
        let mut c = self.0.borrow_mut();
        c.cut_at = None;
        c.dead = false;
    }

    /// Whether the power was cut.
    pub fn was_cut(&self) -> bool {
        self.0.borrow().dead
    }

    /// Erases and programs so far.
    pub fn ops(&self) -> u32 {
        self.0.borrow().ops
    }

    /// Words programmed a second time since their erase (never by a
    /// correct store).
    pub fn double_programs(&self) -> u32 {
        self.0.borrow().double_programs
    }

    /// Flash words read so far.
    pub fn reads(&self) -> u64 {
        self.0.borrow().reads
    }

    /// Whether the flash word at byte `offset` of the bank reads with a
    /// double ECC error.
    pub fn unreadable(&self, offset: usize) -> bool {
        self.0.borrow().bad[offset / WORD]
    }

    /// Programs a word as a cut program leaves it (first half, ECC wrong).
    pub fn half_program(&self, offset: usize, word: &[u8; WORD]) {
        let mut c = self.0.borrow_mut();
        for (cell, &w) in c.data[offset..offset + WORD / 2].iter_mut().zip(word) {
            *cell &= w;
        }
        c.programmed[offset / WORD] = true;
        c.bad[offset / WORD] = true;
    }

    /// The cells of `range` of the bank.
    pub fn bytes(&self, range: Range<usize>) -> Vec<u8> {
        self.0.borrow().data[range].to_vec()
    }

    /// `range` of the bank (offsets from its start) as a flash with
    /// erase sectors of `S` bytes.
    pub fn window<const S: usize>(&self, range: Range<u32>) -> Window<S> {
        Window {
            bank: self.clone(),
            base: range.start,
            len: range.end - range.start,
        }
    }

    /// Starts an operation: false if the power is (or goes) off now.
    fn operation(c: &mut Cells) -> Result<bool, Fault> {
        if c.dead {
            return Err(Fault::Read);
        }
        c.ops += 1;
        Ok(c.cut_at.is_some_and(|n| c.ops >= n))
    }
}

/// A range of the bank, as the firmware's flash driver sees its range.
pub struct Window<const S: usize> {
    bank: Bank,
    base: u32,
    len: u32,
}

impl<const S: usize> FlashWords for Window<S> {
    const SECTOR: usize = S;

    fn capacity(&self) -> usize {
        self.len as usize
    }

    async fn read(&mut self, offset: u32, buf: &mut [u8]) -> Result<(), Fault> {
        let mut c = self.bank.0.borrow_mut();
        if c.dead {
            return Err(Fault::Read);
        }
        c.reads += (buf.len() / WORD) as u64;
        let at = (self.base + offset) as usize;
        if (at / WORD..(at + buf.len()).div_ceil(WORD)).any(|w| c.bad[w]) {
            return Err(Fault::Ecc);
        }
        buf.copy_from_slice(&c.data[at..at + buf.len()]);
        Ok(())
    }

    async fn program(&mut self, offset: u32, word: &[u8; WORD]) -> Result<(), Fault> {
        let mut c = self.bank.0.borrow_mut();
        let cut = Bank::operation(&mut c)?;
        let at = (self.base + offset) as usize;
        let w = at / WORD;
        let upto = if cut { WORD / 2 } else { WORD };
        for (cell, &w) in c.data[at..at + upto].iter_mut().zip(word) {
            *cell &= w;
        }
        if c.programmed[w] {
            c.double_programs += 1;
            c.bad[w] = true;
        }
        c.programmed[w] = true;
        if cut {
            c.bad[w] = true;
            c.dead = true;
            return Err(Fault::Program(0));
        }
        Ok(())
    }

    async fn erase(&mut self, offset: u32) -> Result<(), Fault> {
        let mut c = self.bank.0.borrow_mut();
        let cut = Bank::operation(&mut c)?;
        let at = (self.base + offset) as usize;
        let upto = match (cut, c.erase_cut) {
            (false, _) => S,
            (true, EraseCut::FirstHalf) => S / 2,
            (true, EraseCut::AllUnreadable) => 0,
        };
        c.data[at..at + upto].fill(0xFF);
        for w in at / WORD..(at + upto) / WORD {
            c.programmed[w] = false;
            c.bad[w] = false;
        }
        if cut {
            if c.erase_cut == EraseCut::AllUnreadable {
                c.bad[at / WORD..(at + S) / WORD].fill(true);
            }
            c.dead = true;
            return Err(Fault::Erase(0));
        }
        Ok(())
    }
}

/// The capacity of the H743 release build with its default configuration
/// (`src/h743/mod.rs`, `CAPACITY`: 300 columns); a build for another scan
/// has that scan's columns.
pub const H743_CAPACITY: Capacity = h743_capacity(300);

/// The capacity of an H743 build for scans of `cols` columns.
pub const fn h743_capacity(cols: u16) -> Capacity {
    Capacity {
        max_cols: cols,
        max_rows: u16::MAX,
        max_dcap: 16,
        max_pulse_us: 1 << 16,
    }
}

/// The settings store of the H743 firmware on this bank.
pub fn h743_store(bank: &Bank) -> SettingsStore<Words<Window<SECTOR>>> {
    let flash = Words::new(bank.window::<SECTOR>(H743_STORE));
    match SettingsStore::new(flash, 0..H743_STORE.end) {
        Ok(s) => s,
        Err(e) => panic!("the H743 store's range is refused: {e:?}"),
    }
}

/// What an H743 firmware built for `tag` finds in the chip-model file
/// `path` at start-up (the same code: `cvm_fw_app::settings_store`).
pub fn read_record(path: &Path, tag: &Tag) -> Result<(Store, Option<Values>), String> {
    let bank = Bank::load(path)?;
    Ok(embassy_futures::block_on(h743_store(&bank).load(tag)))
}

/// Saves `values` for `tag` into the chip-model file `path` (created
/// erased if missing), as the H743 firmware would.
pub fn write_record(path: &Path, tag: &Tag, values: &Values) -> Result<(), String> {
    let bank = Bank::load(path)?;
    embassy_futures::block_on(h743_store(&bank).save(tag, values))
        .map_err(|e: StoreError| format!("save: {e:?}"))?;
    bank.save(path)
}
