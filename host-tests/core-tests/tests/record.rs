//! The settings record kept in flash (cvm_core::record): a record built
//! by hand from its documented layout (its CRC from a bit-by-bit CRC-32
//! written here, not the crate's), round trips, every single-byte change
//! of a record rejected, other builds' records foreign.

use cvm_core::command::Key;
use cvm_core::record::{
    Decoded, FORMAT, MAGIC, SETTINGS_LAYOUT, TAG_LEN, Tag, TooShort, decode, encode, encoded_len,
};
use cvm_core::{Config, Geometry, Kernels, MAX_J, Weights};
use proptest::prelude::*;

const N: usize = Key::ALL.len();

/// CRC-32/ISO-HDLC bit by bit (reflected polynomial 0xEDB88320, initial
/// and final XOR 0xFFFFFFFF; check value 0xCBF43926 for "123456789").
fn crc32_bitwise(data: &[u8]) -> u32 {
    let mut crc = 0xFFFF_FFFFu32;
    for &b in data {
        crc ^= b as u32;
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0xEDB8_8320
            } else {
                crc >> 1
            };
        }
    }
    !crc
}

fn paper(j1: u8, j2: u8) -> Config {
    Config::paper(Geometry::new(j1, j2).unwrap())
}

/// The tag's bytes as the module documents them, assembled here.
fn tag_by_hand(c: &Config) -> [u8; TAG_LEN] {
    let names: String = Key::ALL.iter().map(|k| format!("{},", k.name())).collect();
    let mut t = Vec::new();
    t.extend(SETTINGS_LAYOUT.to_le_bytes());
    t.extend(crc32_bitwise(names.as_bytes()).to_le_bytes());
    t.push(N as u8);
    t.extend([c.geometry.j1, c.geometry.j2]);
    t.extend(match c.kernels {
        Kernels::Paper { bmax } => [0, bmax],
        Kernels::Square { kmax } => [1, kmax],
    });
    match c.weights {
        Weights::Uniform => t.extend([0, 0, 0, 0, 0]),
        Weights::Unit => t.extend([1, 0, 0, 0, 0]),
        Weights::Separable { w1, w2 } => {
            let bits: Vec<u8> = w1
                .iter()
                .chain(&w2)
                .flat_map(|w| w.to_bits().to_le_bytes())
                .collect();
            t.push(2);
            t.extend(crc32_bitwise(&bits).to_le_bytes());
        }
    }
    t.push(c.normalise as u8);
    t.extend(c.full_scale.to_le_bytes());
    t.push(0);
    t.try_into().unwrap()
}

/// A record assembled from the documented layout, sealed with `crc32_bitwise`.
fn record_by_hand(magic: &[u8], format: u8, tag: &[u8], values: &[u32]) -> Vec<u8> {
    let mut r = magic.to_vec();
    r.push(format);
    r.extend(tag);
    for v in values {
        r.extend(v.to_le_bytes());
    }
    let crc = crc32_bitwise(&r);
    r.extend(crc.to_le_bytes());
    r
}

fn encoded(tag: &Tag, values: &[u32; N]) -> Vec<u8> {
    let mut out = [0u8; 256];
    let n = encode(tag, values, &mut out).unwrap();
    out[..n].to_vec()
}

fn values(seed: u32) -> [u32; N] {
    core::array::from_fn(|i| seed.wrapping_mul(2_654_435_761).wrapping_add(i as u32 * 77))
}

#[test]
fn the_bitwise_crc_is_crc32_iso_hdlc() {
    assert_eq!(crc32_bitwise(b"123456789"), 0xCBF4_3926);
}

#[test]
fn a_record_is_its_documented_layout() {
    for c in [
        paper(15, 15),
        paper(9, 9),
        Config {
            kernels: Kernels::Square { kmax: 6 },
            weights: Weights::Unit,
            normalise: false,
            full_scale: 4095,
            ..paper(7, 12)
        },
        Config {
            weights: Weights::Separable {
                w1: [0.5; MAX_J],
                w2: core::array::from_fn(|i| i as f64),
            },
            ..paper(16, 3)
        },
    ] {
        let tag = Tag::new(&c);
        assert_eq!(tag.as_bytes(), &tag_by_hand(&c), "{c:?}");
        let v = values(7);
        let bytes = encoded(&tag, &v);
        assert_eq!(bytes.len(), encoded_len(N));
        assert_eq!(bytes.len(), 4 + 1 + 20 + 4 * N + 4);
        assert_eq!(bytes, record_by_hand(&MAGIC, FORMAT, tag.as_bytes(), &v));
        assert_eq!(&bytes[..5], b"CVMS\x01");
        assert_eq!(decode::<N>(&bytes, &tag), Decoded::Valid(v));
    }
}

#[test]
fn every_single_byte_change_is_rejected() {
    // CRC-32 detects every burst of up to 32 bits: whatever one byte is
    // changed to, the record does not decode, so no change of one byte
    // can pass for another set of values.
    let tag = Tag::new(&paper(15, 15));
    for seed in [0, 1, 0xFFFF_FFFF] {
        let good = encoded(&tag, &values(seed));
        for at in 0..good.len() {
            for x in 1..=255u8 {
                let mut bad = good.clone();
                bad[at] ^= x;
                assert_eq!(
                    decode::<N>(&bad, &tag),
                    Decoded::Corrupt,
                    "byte {at} ^ {x:#04x}"
                );
            }
        }
    }
}

#[test]
fn a_record_of_another_length_is_corrupt() {
    let tag = Tag::new(&paper(15, 15));
    let good = encoded(&tag, &values(3));
    for len in 0..good.len() {
        assert_eq!(
            decode::<N>(&good[..len], &tag),
            Decoded::Corrupt,
            "cut to {len}"
        );
    }
    let mut longer = good.clone();
    longer.push(0);
    assert_eq!(decode::<N>(&longer, &tag), Decoded::Corrupt);
    // A well-sealed record whose tag says N values but that holds one more.
    let mut v = values(3).to_vec();
    v.push(9);
    let sealed = record_by_hand(&MAGIC, FORMAT, tag.as_bytes(), &v);
    assert_eq!(decode::<N>(&sealed, &tag), Decoded::Corrupt);
    let sealed = record_by_hand(b"CVMT", FORMAT, tag.as_bytes(), &values(3));
    assert_eq!(decode::<N>(&sealed, &tag), Decoded::Corrupt, "magic");
}

#[test]
fn records_of_other_builds_are_foreign() {
    let ours = paper(15, 15);
    let tag = Tag::new(&ours);
    let v = values(11);
    let others = [
        paper(9, 9),
        paper(15, 14),
        Config {
            kernels: Kernels::Paper { bmax: 4 },
            ..ours
        },
        Config {
            kernels: Kernels::square_default(ours.geometry),
            ..ours
        },
        Config {
            weights: Weights::Unit,
            ..ours
        },
        Config {
            weights: Weights::Separable {
                w1: [1.0; MAX_J],
                w2: [1.0; MAX_J],
            },
            ..ours
        },
        Config {
            normalise: false,
            ..ours
        },
        Config {
            full_scale: 65534,
            ..ours
        },
    ];
    for other in others {
        let theirs = Tag::new(&other);
        assert_ne!(theirs, tag, "{other:?}");
        assert_eq!(
            decode::<N>(&encoded(&theirs, &v), &tag),
            Decoded::Foreign,
            "{other:?}"
        );
    }
    // Two separable weight sets that differ in one weight.
    let a = Weights::Separable {
        w1: [1.0; MAX_J],
        w2: [1.0; MAX_J],
    };
    let mut w2 = [1.0; MAX_J];
    w2[15] = 1.0 + f64::EPSILON;
    let b = Weights::Separable {
        w1: [1.0; MAX_J],
        w2,
    };
    assert_ne!(
        Tag::new(&Config { weights: a, ..ours }),
        Tag::new(&Config { weights: b, ..ours })
    );
    // Another settings layout, another count of values, another format.
    let mut t = *tag.as_bytes();
    t[0] ^= 1;
    let sealed = record_by_hand(&MAGIC, FORMAT, &t, &v);
    assert_eq!(decode::<N>(&sealed, &tag), Decoded::Foreign, "layout");
    let mut t = *tag.as_bytes();
    t[2] ^= 1;
    let sealed = record_by_hand(&MAGIC, FORMAT, &t, &v);
    assert_eq!(decode::<N>(&sealed, &tag), Decoded::Foreign, "keys");
    let mut t = *tag.as_bytes();
    t[6] = N as u8 + 1;
    let mut more = v.to_vec();
    more.push(1);
    let sealed = record_by_hand(&MAGIC, FORMAT, &t, &more);
    assert_eq!(decode::<N>(&sealed, &tag), Decoded::Foreign, "count");
    let sealed = record_by_hand(&MAGIC, FORMAT + 1, tag.as_bytes(), &v);
    assert_eq!(decode::<N>(&sealed, &tag), Decoded::Foreign, "format");
}

#[test]
fn encode_needs_room_for_the_whole_record() {
    let tag = Tag::new(&paper(15, 15));
    let mut out = vec![0u8; encoded_len(N) - 1];
    assert_eq!(encode(&tag, &values(1), &mut out), Err(TooShort));
    let mut out = vec![0u8; encoded_len(N)];
    assert_eq!(encode(&tag, &values(1), &mut out), Ok(encoded_len(N)));
}

fn arb_config() -> impl Strategy<Value = Config> {
    (
        1u8..=16,
        1u8..=16,
        any::<bool>(),
        0u8..16,
        0u8..3,
        any::<bool>(),
        any::<u16>(),
    )
        .prop_map(
            |(j1, j2, square, k, weights, normalise, full_scale)| Config {
                geometry: Geometry::new(j1, j2).unwrap(),
                kernels: if square {
                    Kernels::Square { kmax: k }
                } else {
                    Kernels::Paper { bmax: k }
                },
                weights: match weights {
                    0 => Weights::Uniform,
                    1 => Weights::Unit,
                    _ => Weights::Separable {
                        w1: core::array::from_fn(|i| i as f64 / j1 as f64),
                        w2: [1.0; MAX_J],
                    },
                },
                normalise,
                full_scale,
            },
        )
}

proptest! {
    #[test]
    fn round_trip(c in arb_config(), v in proptest::array::uniform::<_, N>(any::<u32>())) {
        let tag = Tag::new(&c);
        prop_assert_eq!(tag.as_bytes(), &tag_by_hand(&c));
        prop_assert_eq!(decode::<N>(&encoded(&tag, &v), &tag), Decoded::Valid(v));
    }

    #[test]
    fn a_record_is_valid_only_for_its_own_tag(a in arb_config(), b in arb_config(), seed in any::<u32>()) {
        let (ta, tb) = (Tag::new(&a), Tag::new(&b));
        let got = decode::<N>(&encoded(&ta, &values(seed)), &tb);
        if ta == tb {
            prop_assert_eq!(got, Decoded::Valid(values(seed)));
        } else {
            prop_assert_eq!(got, Decoded::Foreign);
        }
    }

    #[test]
    fn arbitrary_bytes_never_decode_to_values_they_do_not_encode(bytes in proptest::collection::vec(any::<u8>(), 0..128)) {
        let tag = Tag::new(&paper(15, 15));
        if let Decoded::Valid(v) = decode::<N>(&bytes, &tag) {
            prop_assert_eq!(encoded(&tag, &v), bytes);
        }
    }

    #[test]
    fn changes_of_several_bytes_are_rejected(seed in any::<u32>(), changes in proptest::collection::vec((any::<usize>(), 1u8..=255), 1..6)) {
        let tag = Tag::new(&paper(15, 15));
        let good = encoded(&tag, &values(seed));
        let mut bad = good.clone();
        for (at, x) in changes {
            bad[at % good.len()] ^= x;
        }
        prop_assume!(bad != good);
        prop_assert_eq!(decode::<N>(&bad, &tag), Decoded::Corrupt);
    }
}
