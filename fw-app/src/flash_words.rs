//! A NOR flash programmed by 256-bit words that carry ECC (the H743's
//! embedded flash), as `sequential-storage` needs it
//! (`embedded_storage_async::nor_flash::NorFlash`).
//!
//! A board provides the three operations ([`FlashWords`]); [`Words`] adds
//! the bounds and alignment checks and the one thing that makes such a
//! flash safe to read after a power cut. A flash word whose programming
//! was cut short holds cells that do not agree with its ECC; reading it is
//! a double ECC error, which the chip answers with a bus error (a fault
//! for the CPU, a transfer error for a DMA stream). [`Words::read`]
//! gives every such word to its caller as 32 zero bytes ([`POISON`])
//! instead of failing the whole read: `sequential-storage` checks what it
//! reads (the item header's length CRC, the item's data CRC, the page
//! markers) and was built to step over the garbage that a cut write
//! leaves, so an unreadable word becomes one more damaged item or marker
//! to step over, and the rest of the flash stays readable. Zeros, not
//! `0xFF`: a word that reads as erased would be programmed again, and a
//! word can be programmed once per erase.

use embedded_storage_async::nor_flash::{
    ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash,
};

/// Bytes of a flash word: the unit of programming and of ECC.
pub const WORD: usize = 32;
/// What a read returns for a flash word whose ECC reports a double error.
pub const POISON: [u8; WORD] = [0; WORD];

/// Why a flash operation failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Fault {
    /// A word read back with a double ECC error (cut or repeated
    /// programming since its erase).
    Ecc,
    /// The read failed for another reason (a bus or DMA error).
    Read,
    /// Programming failed; the flash interface's error flags.
    Program(u32),
    /// A sector erase failed; the flash interface's error flags.
    Erase(u32),
    /// Outside the flash, or not aligned to its words or sectors.
    Bounds,
}

impl NorFlashError for Fault {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            Fault::Bounds => NorFlashErrorKind::OutOfBounds,
            _ => NorFlashErrorKind::Other,
        }
    }
}

/// The operations of a word-programmed flash with ECC. Offsets count from
/// the start of the flash range the store owns.
#[allow(async_fn_in_trait)] // used with concrete types only; no Send bound needed
pub trait FlashWords {
    /// Bytes of an erase sector.
    const SECTOR: usize;
    /// Bytes of the range.
    fn capacity(&self) -> usize;
    /// Reads whole words at `offset` (both multiples of [`WORD`]); any
    /// word with a double ECC error fails the read with [`Fault::Ecc`].
    async fn read(&mut self, offset: u32, buf: &mut [u8]) -> Result<(), Fault>;
    /// Programs one erased word.
    async fn program(&mut self, offset: u32, word: &[u8; WORD]) -> Result<(), Fault>;
    /// Erases the sector that starts at `offset`.
    async fn erase(&mut self, offset: u32) -> Result<(), Fault>;
}

/// A [`FlashWords`] as an `embedded-storage-async` NOR flash (see the
/// module docs).
pub struct Words<F> {
    pub flash: F,
    /// Word reads that met a double ECC error and returned [`POISON`].
    pub poisoned: u32,
    /// Sector erases done.
    pub erased: u32,
}

impl<F: FlashWords> Words<F> {
    pub fn new(flash: F) -> Self {
        Words {
            flash,
            poisoned: 0,
            erased: 0,
        }
    }

    fn check(&self, offset: u32, len: usize, align: usize) -> Result<(), Fault> {
        let start = offset as usize;
        let aligned = start.is_multiple_of(align) && len.is_multiple_of(align);
        match start.checked_add(len) {
            Some(end) if aligned && end <= self.flash.capacity() => Ok(()),
            _ => Err(Fault::Bounds),
        }
    }
}

impl<F> ErrorType for Words<F> {
    type Error = Fault;
}

impl<F: FlashWords> ReadNorFlash for Words<F> {
    const READ_SIZE: usize = WORD;

    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Fault> {
        self.check(offset, bytes.len(), WORD)?;
        match self.flash.read(offset, bytes).await {
            Err(Fault::Ecc) => {}
            other => return other,
        }
        // One word at a time, to find the words that fail.
        let mut at = offset;
        for word in bytes.chunks_exact_mut(WORD) {
            match self.flash.read(at, word).await {
                Ok(()) => {}
                Err(Fault::Ecc) => {
                    word.copy_from_slice(&POISON);
                    self.poisoned = self.poisoned.wrapping_add(1);
                }
                Err(e) => return Err(e),
            }
            at += WORD as u32;
        }
        Ok(())
    }

    fn capacity(&self) -> usize {
        self.flash.capacity()
    }
}

impl<F: FlashWords> NorFlash for Words<F> {
    const WRITE_SIZE: usize = WORD;
    const ERASE_SIZE: usize = F::SECTOR;

    async fn erase(&mut self, from: u32, to: u32) -> Result<(), Fault> {
        let len = (to as usize)
            .checked_sub(from as usize)
            .ok_or(Fault::Bounds)?;
        self.check(from, len, F::SECTOR)?;
        let mut at = from;
        while at < to {
            self.flash.erase(at).await?;
            self.erased = self.erased.wrapping_add(1);
            at += F::SECTOR as u32;
        }
        Ok(())
    }

    async fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Fault> {
        self.check(offset, bytes.len(), WORD)?;
        let mut at = offset;
        for chunk in bytes.chunks_exact(WORD) {
            let mut word = [0u8; WORD];
            word.copy_from_slice(chunk);
            self.flash.program(at, &word).await?;
            at += WORD as u32;
        }
        Ok(())
    }
}
