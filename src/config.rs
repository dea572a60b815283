//! Every setting of the firmware, in one place.
//!
//! The H743 board's scan configuration is a compile-time constant: its
//! scoring tables are built by the compiler (a configuration the core
//! refuses fails the build), and its buffers are sized from it, so a
//! configuration whose buffers do not fit the RAM banks fails the link
//! ("region ... overflowed"). The sizes both boards share are
//! `cvm_fw_app::sizing`'s.

pub use cvm_fw_app::sizing::{BEAM_LOG, MAX_DEFECT_LINES_PER_ROW, keep_reserve, queue_fits};

/// Announced in the header line (printable ASCII without `,` or `*`).
pub const FIRMWARE_VERSION: &str = concat!("cvm-fw-", env!("CARGO_PKG_VERSION"));

pub mod h743 {
    use cvm_core::{Config, Geometry, Kernels, Outputs, RejectMode, Weights};

    /// The part verdict's rules and the READY and REJECT outputs
    /// (docs/firmware.md, "READY and REJECT outputs"), from `CVM_H743_SCAN`
    /// (`area`, `peak`, `miss`, `misp`, `mode`, `pulse`, `delay`; by
    /// default `dmap stream`'s and the emulated board's, so that the three
    /// end lines agree). The command channel sets the same values at run
    /// time.
    pub const OUTPUTS: Outputs = Outputs {
        min_area: MIN_AREA,
        min_strength: MIN_PEAK,
        max_missing: MAX_MISSING,
        max_misplaced: MAX_MISPLACED,
        reject_mode: if REJECT_ROW {
            RejectMode::Row
        } else {
            RejectMode::Part
        },
        pulse_us: PULSE_US,
        row_delay: ROW_DELAY,
        ..Outputs::DEFAULT
    };

    // The scan configuration: J1, J2 (detector geometry), COLS (beams per
    // row), ROWS (rows per scan: after this many the end line goes out),
    // KERNELS, WEIGHTS, NORMALISE, THRESHOLD_UNITS (defect threshold on the
    // gradient magnitude, in `dmap` units), SCORES (emit per-position score
    // lines, dropped first when the UART lags), MAX_DEFECT_LINES_PER_ROW.
    // Defaults: 15x15 maps, 300 x 200 beams, paper kernels, uniform weights,
    // normalised, threshold 0.5, scores on, 16 defect lines per row, full
    // scale 65535, the package's version in the header; build.rs
    // writes them, or the `CVM_H743_SCAN` override (docs/firmware.md).
    include!(concat!(env!("OUT_DIR"), "/h743_scan.rs"));
    const _: () = assert!(
        // (`checked_sub` rather than `<=`, which is trivially true for the
        // default of 0 and trips the absurd-comparison lint.)
        super::MAX_DEFECT_LINES_PER_ROW
            .checked_sub(MAX_DEFECT_LINES_PER_ROW)
            .is_some(),
        "the queue reserve is sized for at most super::MAX_DEFECT_LINES_PER_ROW defect lines per row"
    );

    /// The columns the row buffers are sized for.
    pub const MAX_COLS: usize = COLS;

    /// Bytes of the output queue (about 1.4 s of lines at 921600 baud).
    pub const QUEUE_BYTES: usize = 128 * 1024;
    pub const KEEP_RESERVE: usize = super::keep_reserve(MAX_COLS);
    const _: () = assert!(super::queue_fits(QUEUE_BYTES, MAX_COLS));

    pub const GEOMETRY: Geometry = match Geometry::new(J1, J2) {
        Ok(g) => g,
        Err(_) => panic!("J1 and J2 must be 1..=16"),
    };

    /// Kernels, weights and normalisation (docs/method.md §3).
    pub const CORE: Config = Config {
        geometry: GEOMETRY,
        kernels: KERNELS,
        weights: WEIGHTS,
        normalise: NORMALISE,
        full_scale: FULL_SCALE,
    };

    /// The version the header announces.
    pub const FIRMWARE_VERSION: &str = match FIRMWARE_VERSION_OVERRIDE {
        Some(v) => v,
        None => super::FIRMWARE_VERSION,
    };

    /// Core clock (PLL1 P) and the SPI kernel clock (PLL1 Q).
    pub const SYSCLK_HZ: u32 = 400_000_000;
    pub const SPI_KERNEL_HZ: u32 = 200_000_000;
    /// SPI clock to the detector (the kernel clock divided by a power of
    /// two). 25 MHz leaves 20 ns of the 40 ns SCK period for the detector's
    /// output delay, the wiring and the input set-up; 50 MHz only 10 ns
    /// (docs/firmware.md, bring-up).
    pub const SPI_HZ: u32 = 25_000_000;
    /// SPI1's `CFG1.MBR` divider for [`SPI_HZ`].
    pub const SPI_DIV: embassy_stm32::pac::spi::vals::Mbr = match SPI_KERNEL_HZ / SPI_HZ {
        2 => embassy_stm32::pac::spi::vals::Mbr::DIV2,
        4 => embassy_stm32::pac::spi::vals::Mbr::DIV4,
        8 => embassy_stm32::pac::spi::vals::Mbr::DIV8,
        16 => embassy_stm32::pac::spi::vals::Mbr::DIV16,
        32 => embassy_stm32::pac::spi::vals::Mbr::DIV32,
        64 => embassy_stm32::pac::spi::vals::Mbr::DIV64,
        128 => embassy_stm32::pac::spi::vals::Mbr::DIV128,
        _ => embassy_stm32::pac::spi::vals::Mbr::DIV256,
    };
    /// A frame read that has not finished after twice its bus time plus
    /// 100 us is a lost beam (a 15x15 frame takes 144 us at 25 MHz).
    /// It is counted by a 16-bit timer in microseconds.
    pub const READ_TIMEOUT_US: u32 = {
        let us = 2 * (GEOMETRY.cells() as u64 * 16 * 1_000_000).div_ceil(SPI_HZ as u64) + 100;
        assert!(
            us <= 1 << 16,
            "the read timeout must fit TIM13's 16-bit count"
        );
        us as u32
    };
    /// Frame buffers: one for the SPI to fill, one being scored, and one
    /// for every beam that can arrive while the scoring task is busy with
    /// the end of a scan. Twice per row and scan the scoring task has a
    /// burst between two beams (docs/firmware.md, "Beam rate"):
    /// - when the row below a row is complete, that row's magnitudes,
    ///   decisions and lines ([`ROW_END_CYCLES_PER_COL`]);
    /// - at the end of a scan, its last two rows' and the last row's
    ///   vertical distances, whose lower neighbour is the map itself by the
    ///   border rule ([`SCAN_END_CYCLES_PER_CELL`]); the next scan's
    ///   beams may follow without a pause.
    ///
    /// Sized for the second with beams one frame's bus time apart, but at
    /// least [`MIN_BEAM_CYCLES`] (a beam costs the scoring task more than
    /// that), at most what the beam log can track. (Two buffers lose beams
    /// well below the SPI's rate: docs/firmware.md, "SPI1 configuration and
    /// measured costs".)
    pub const FRAME_BUFFERS: usize = {
        let cells = GEOMETRY.cells() as u64;
        let frame_cycles = (cells * 16 * SYSCLK_HZ as u64).div_ceil(SPI_HZ as u64);
        let beam = if frame_cycles > MIN_BEAM_CYCLES {
            frame_cycles
        } else {
            MIN_BEAM_CYCLES
        };
        let burst = COLS as u64 * (2 * ROW_END_CYCLES_PER_COL + SCAN_END_CYCLES_PER_CELL * cells);
        let n = 2 + burst.div_ceil(beam) as usize;
        if n < super::BEAM_LOG - 2 {
            n
        } else {
            super::BEAM_LOG - 2
        }
    };
    /// A row's magnitudes, decisions and lines, cycles per column: the
    /// chip model's count at a scan's end (where the score lines are
    /// promoted to keep lines, the dearest case) with a margin; mostly
    /// DTCM and the stack, so few stalls (figures: docs/firmware.md, "SPI1
    /// configuration and measured costs").
    pub const ROW_END_CYCLES_PER_COL: u64 = 1_000;
    /// The last row's vertical distances at the end of a scan, cycles per
    /// column and cell: a few instructions and two words read from the row
    /// buffers, whose stalls with the D-cache off dominate (figures from
    /// the chip model and its bus cost model: docs/firmware.md, "SPI1
    /// configuration and measured costs").
    pub const SCAN_END_CYCLES_PER_CELL: u64 = 20;
    /// Cycles below which no beam is scored, whatever the map size:
    /// sequencing, the engine's bookkeeping, the interrupts and the tasks.
    pub const MIN_BEAM_CYCLES: u64 = 3_000;
    /// Samples per frame buffer: the map's cells rounded up to 16 (32
    /// bytes), so that every buffer starts word- and line-aligned.
    pub const FRAME_SAMPLES: usize = GEOMETRY.cells().next_multiple_of(16);
    /// Beams scored between two yields of the scoring task.
    pub const SCORE_BURST: u32 = 8;
    const _: () = assert!(
        SPI_KERNEL_HZ.is_multiple_of(SPI_HZ)
            && (SPI_KERNEL_HZ / SPI_HZ).is_power_of_two()
            && SPI_KERNEL_HZ / SPI_HZ >= 2,
        "the SPI clock must be the kernel clock divided by a power of two (2..=256)"
    );
    /// USART3 (ST-LINK virtual COM port).
    pub const BAUD: u32 = 921_600;

    /// A scan with no beam for this long is ended (rest reported missing).
    pub const IDLE_END_MS: u64 = 500;
    /// Independent watchdog timeout; the scoring loop feeds it at least
    /// every [`IDLE_END_MS`] / 5.
    pub const WATCHDOG_US: u32 = 1_000_000;
    pub const FEED_MS: u64 = 100;
}
