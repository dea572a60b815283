//! The settings record a board keeps in flash: the runtime settings'
//! values and what they were made for, in a fixed byte encoding.
//!
//! ```text
//! offset  bytes  field
//! 0       4      magic "CVMS"
//! 4       1      record format (FORMAT)
//! 5       20     tag: what the values were made for (Tag)
//! 25      4 N    the values, u32 little-endian, in `Key::ALL`'s order
//! 25+4N   4      CRC-32 (ISO-HDLC) of every byte before it, little-endian
//! ```
//!
//! The tag holds the settings layout (its version, the keys' names and how
//! many there are), the detector geometry, the kernels, the weights and
//! normalisation, and the full scale: a record whose tag is not the
//! running firmware's was made for another build ([`Decoded::Foreign`]),
//! and its values mean nothing here. A record that does not decode (wrong
//! length, magic or CRC) is [`Decoded::Corrupt`]. The CRC is the record's
//! own, so that the decoder needs nothing around it to reject a damaged
//! record: CRC-32 detects every change of up to 32 consecutive bits, so a
//! record with any one byte changed is never taken for another valid set
//! of values (tested exhaustively). The flash store wraps the record in
//! its own item CRC as well.
//!
//! Decoding never panics on any input (fuzzed: `host-tests/fuzz`,
//! `record`).

use crate::command::Key;
use crate::config::{Config, Kernels, MAX_J, Weights};

/// The record's first four bytes.
pub const MAGIC: [u8; 4] = *b"CVMS";
/// The byte encoding above; a record with another is [`Decoded::Foreign`].
pub const FORMAT: u8 = 1;
/// Version of the settings layout: bump it when a key keeps its name but
/// changes its meaning or unit (a renamed, added, removed or reordered key
/// changes the tag by itself, through the keys' digest).
pub const SETTINGS_LAYOUT: u16 = 1;
/// Bytes of a [`Tag`].
pub const TAG_LEN: usize = 20;
/// Bytes before the values: magic, format, tag.
const HEAD: usize = 4 + 1 + TAG_LEN;

/// CRC-32/ISO-HDLC (the zlib CRC) without a lookup table: a record is
/// checked once per start-up and per save, and the table would cost 1 KiB
/// of flash.
const CRC32: crc::Crc<u32, crc::NoTable> =
    crc::Crc::<u32, crc::NoTable>::new(&crc::CRC_32_ISO_HDLC);

/// Bytes of the record of `n` values.
pub const fn encoded_len(n: usize) -> usize {
    HEAD + 4 * n + 4
}

/// What a record was made for (see the module docs); compare two with `==`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Tag([u8; TAG_LEN]);

impl Tag {
    /// The tag of a firmware that scores with `config` and keeps the
    /// runtime settings of [`Key::ALL`], at [`SETTINGS_LAYOUT`].
    pub const fn new(config: &Config) -> Tag {
        let mut t = [0u8; TAG_LEN];
        put(&mut t, 0, &SETTINGS_LAYOUT.to_le_bytes());
        put(&mut t, 2, &keys_digest().to_le_bytes());
        t[6] = Key::ALL.len() as u8;
        t[7] = config.geometry.j1;
        t[8] = config.geometry.j2;
        (t[9], t[10]) = match config.kernels {
            Kernels::Paper { bmax } => (0, bmax),
            Kernels::Square { kmax } => (1, kmax),
        };
        let (kind, digest) = match &config.weights {
            Weights::Uniform => (0, 0),
            Weights::Unit => (1, 0),
            Weights::Separable { w1, w2 } => (2, weights_digest(w1, w2)),
        };
        t[11] = kind;
        put(&mut t, 12, &digest.to_le_bytes());
        t[16] = config.normalise as u8;
        put(&mut t, 17, &config.full_scale.to_le_bytes());
        Tag(t)
    }

    /// The tag's bytes, as a record carries them.
    pub const fn as_bytes(&self) -> &[u8; TAG_LEN] {
        &self.0
    }

    /// A tag from its bytes (tools and tests that write records of other
    /// builds).
    pub const fn from_bytes(bytes: [u8; TAG_LEN]) -> Tag {
        Tag(bytes)
    }

    /// How many values its records hold.
    pub const fn values(&self) -> usize {
        self.0[6] as usize
    }
}

const fn put(t: &mut [u8; TAG_LEN], at: usize, bytes: &[u8]) {
    let mut i = 0;
    while i < bytes.len() {
        t[at + i] = bytes[i];
        i += 1;
    }
}

/// CRC-32 of the keys' names, each followed by `,`, in [`Key::ALL`]'s order.
const fn keys_digest() -> u32 {
    let crc = CRC32;
    let mut d = crc.digest();
    let mut i = 0;
    while i < Key::ALL.len() {
        d.update(Key::ALL[i].name().as_bytes());
        d.update(b",");
        i += 1;
    }
    d.finalize()
}

/// CRC-32 of the separable weights' bit patterns (`w1` then `w2`, each
/// `f64` little-endian).
const fn weights_digest(w1: &[f64; MAX_J], w2: &[f64; MAX_J]) -> u32 {
    let crc = CRC32;
    let mut d = crc.digest();
    let mut i = 0;
    while i < MAX_J {
        d.update(&w1[i].to_bits().to_le_bytes());
        i += 1;
    }
    i = 0;
    while i < MAX_J {
        d.update(&w2[i].to_bits().to_le_bytes());
        i += 1;
    }
    d.finalize()
}

/// What a stored record turned out to be.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Decoded<const N: usize> {
    /// A record of this build: its values, in [`Key::ALL`]'s order.
    Valid([u32; N]),
    /// A well-formed record made for another build (another tag or record
    /// format).
    Foreign,
    /// Not a record: wrong length, magic or CRC.
    Corrupt,
}

/// The output buffer is shorter than [`encoded_len`] of the values.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TooShort;

/// Writes the record of `values` made for `tag` at the start of `out`;
/// returns its length, [`encoded_len`]`(N)`.
pub fn encode<const N: usize>(
    tag: &Tag,
    values: &[u32; N],
    out: &mut [u8],
) -> Result<usize, TooShort> {
    let len = encoded_len(N);
    let rec = out.get_mut(..len).ok_or(TooShort)?;
    let (body, crc) = rec.split_at_mut(len - 4);
    let (head, vals) = body.split_at_mut(HEAD);
    head[..4].copy_from_slice(&MAGIC);
    head[4] = FORMAT;
    head[5..].copy_from_slice(tag.as_bytes());
    for (slot, v) in vals.chunks_exact_mut(4).zip(values) {
        slot.copy_from_slice(&v.to_le_bytes());
    }
    crc.copy_from_slice(&CRC32.checksum(body).to_le_bytes());
    Ok(len)
}

/// Reads a record, checking it against the running firmware's `tag`
/// (order: length and CRC, magic, format, tag, then the length the tag
/// implies).
pub fn decode<const N: usize>(bytes: &[u8], tag: &Tag) -> Decoded<N> {
    let Some(body_len) = bytes.len().checked_sub(4) else {
        return Decoded::Corrupt;
    };
    let (body, crc) = bytes.split_at(body_len);
    if body_len < HEAD || crc[..] != CRC32.checksum(body).to_le_bytes()[..] {
        return Decoded::Corrupt;
    }
    let (head, vals) = body.split_at(HEAD);
    if head[..4] != MAGIC {
        return Decoded::Corrupt;
    }
    if head[4] != FORMAT || head[5..] != tag.as_bytes()[..] || tag.values() != N {
        return Decoded::Foreign;
    }
    if vals.len() != 4 * N {
        // Only a CRC collision gets here: the tag says N values.
        return Decoded::Corrupt;
    }
    let mut out = [0u32; N];
    for (v, b) in out.iter_mut().zip(vals.chunks_exact(4)) {
        let mut w = [0u8; 4];
        w.copy_from_slice(b);
        *v = u32::from_le_bytes(w);
    }
    Decoded::Valid(out)
}
