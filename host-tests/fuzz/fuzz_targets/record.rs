//! The settings record's decoder (cvm_core::record) on arbitrary bytes.
//!
//! The input is decoded as it is, and again with its last four bytes
//! replaced by the CRC of the rest (random bytes almost never carry a
//! valid CRC), against the running build's tag and against the tag the
//! input itself carries (so that the `Valid` path is reached too).
//! Nothing may panic, and a record that decodes to values must be made
//! for a tag of that many values and be exactly the encoding of those
//! values: decoding is one-to-one.
#![no_main]

use cvm_core::command::Key;
use cvm_core::record::{Decoded, TAG_LEN, Tag, decode, encode, encoded_len};
use cvm_core::{Config, Geometry};
use libfuzzer_sys::fuzz_target;

const N: usize = Key::ALL.len();

fn check(bytes: &[u8], tag: &Tag) {
    check_n::<N>(bytes, tag);
    check_n::<3>(bytes, tag);
}

/// A record that decodes to `M` values was made for a tag of `M` values
/// and is exactly their encoding.
fn check_n<const M: usize>(bytes: &[u8], tag: &Tag) {
    if let Decoded::Valid(v) = decode::<M>(bytes, tag) {
        assert_eq!(tag.values(), M);
        let mut out = [0u8; 256];
        assert_eq!(encode(tag, &v, &mut out), Ok(encoded_len(M)));
        assert_eq!(&out[..encoded_len(M)], bytes);
    }
}

fuzz_target!(|data: &[u8]| {
    let ours = Tag::new(&Config::paper(Geometry { j1: 15, j2: 15 }));
    let mut sealed = data.to_vec();
    if let Some(body) = data.len().checked_sub(4) {
        let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(&data[..body]);
        sealed[body..].copy_from_slice(&crc.to_le_bytes());
    }
    for bytes in [data, &sealed[..]] {
        check(bytes, &ours);
        if let Some(t) = bytes.get(5..5 + TAG_LEN) {
            check(bytes, &Tag::from_bytes(t.try_into().unwrap()));
        }
    }
});
