//! What the linker script (memory.x) places outside `.data`
//! and `.bss`, and what `main` must do before that memory can be used.
//!
//! `.dtcm`, `.sram123` and `.dma_buffers` are NOLOAD: the reset handler
//! neither zeroes nor initialises them, so a static there starts as
//! whatever the RAM held. `static_cell`'s cells keep their "taken" flag
//! inside the static, where it would start as noise too; those statics are
//! therefore [`Noload`] cells, taken once by code that runs once.

use core::cell::UnsafeCell;
use core::mem::MaybeUninit;

/// A static in a NOLOAD section (see the module docs).
pub struct Noload<T>(UnsafeCell<MaybeUninit<T>>);

// SAFETY: the content is reached only through `take`/`take_zeroed`, whose
// callers hand it out once; after that one `&mut` owns it.
unsafe impl<T: Send> Sync for Noload<T> {}

impl<T> Noload<T> {
    pub const fn new() -> Self {
        Noload(UnsafeCell::new(MaybeUninit::uninit()))
    }

    /// # Safety
    /// At most one call per static, and no other access to it.
    #[allow(clippy::mut_from_ref)]
    pub unsafe fn take(&'static self) -> &'static mut MaybeUninit<T> {
        // SAFETY: the caller hands the static out once.
        unsafe { &mut *self.0.get() }
    }

    /// The static, every byte zeroed first: a known start whatever the RAM
    /// held, so that runs are reproducible.
    ///
    /// # Safety
    /// As for [`Noload::take`], and all-zero bytes must be a valid `T`
    /// (integer arrays).
    #[allow(clippy::mut_from_ref)]
    pub unsafe fn take_zeroed(&'static self) -> &'static mut T {
        // SAFETY: the caller hands the static out once and vouches that
        // zero bytes are a `T`.
        unsafe {
            let p = self.0.get().cast::<T>();
            core::ptr::write_bytes(p, 0, 1);
            &mut *p
        }
    }
}

/// Copies `.dtcm_rodata` (the line encoder's tables) from its load image
/// in flash to DTCM, which the reset handler does not initialise. First
/// thing in `main`: the encoder runs in the tasks.
pub fn load_dtcm_rodata() {
    unsafe extern "C" {
        static __sidtcm_rodata: u32;
        static mut __sdtcm_rodata: u32;
        static mut __edtcm_rodata: u32;
    }
    // SAFETY: the linker script places the section in DTCM, word-aligned,
    // with a load image of the same length in flash; nothing reads it
    // before this copy.
    unsafe {
        let src = &raw const __sidtcm_rodata;
        let dst = &raw mut __sdtcm_rodata;
        let words = (&raw mut __edtcm_rodata).offset_from(dst) as usize;
        core::ptr::copy_nonoverlapping(src, dst, words);
    }
}

/// SRAM1..3 (`.sram123`) can hold a row buffer; their clocks are off after
/// reset, and an access while they are off faults.
pub fn enable_sram123() {
    super::clocks::enable_clock(embassy_stm32::pac::RCC.ahb2enr(), |w| {
        w.set_sram1en(true);
        w.set_sram2en(true);
        w.set_sram3en(true);
    });
}
