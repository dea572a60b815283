//! Editing a stream's lines to damage it on purpose: a changed byte (the
//! CRC fails), a field or key changed and the line sealed again with a
//! valid CRC (the content is wrong), lines removed, repeated, moved or cut.

use cvm_core::protocol::{self, layout};

/// A stream as lines, each with its own line end.
#[derive(Clone, Debug)]
pub struct Lines(pub Vec<Vec<u8>>);

impl Lines {
    pub fn of(bytes: &[u8]) -> Self {
        Lines(
            bytes
                .split_inclusive(|&b| b == b'\n')
                .map(<[u8]>::to_vec)
                .collect(),
        )
    }

    pub fn bytes(&self) -> Vec<u8> {
        self.0.concat()
    }

    /// Index of the `n`-th line (from 0) of type `kind`.
    pub fn nth(&self, kind: u8, n: usize) -> usize {
        self.0
            .iter()
            .enumerate()
            .filter(|(_, l)| l.first() == Some(&kind) && l.get(1) == Some(&b','))
            .nth(n)
            .map(|(i, _)| i)
            .unwrap_or_else(|| panic!("no line {n} of type {}", kind as char))
    }

    /// Index of the first line starting with `prefix`.
    pub fn find(&self, prefix: &str) -> usize {
        self.0
            .iter()
            .position(|l| l.starts_with(prefix.as_bytes()))
            .unwrap_or_else(|| panic!("no line starting {prefix:?}"))
    }

    /// Line `i`'s body: the bytes before its `*`.
    pub fn body(&self, i: usize) -> String {
        let l = String::from_utf8_lossy(&self.0[i]).into_owned();
        l.rsplit_once('*').map_or(l.clone(), |(b, _)| b.to_string())
    }

    /// Field `k` (0 = the type letter) of line `i`.
    pub fn field(&self, i: usize, k: usize) -> String {
        self.body(i)
            .split(',')
            .nth(k)
            .unwrap_or_default()
            .to_string()
    }

    /// The type letter of line `i`.
    pub fn kind(&self, i: usize) -> u8 {
        self.0[i].first().copied().unwrap_or(0)
    }

    /// Where field `name` stands in line `i`, by the protocol's layout.
    fn place(&self, i: usize, name: &str) -> usize {
        layout::place(self.kind(i), name)
            .unwrap_or_else(|| panic!("the {} line has no field {name}", char::from(self.kind(i))))
    }

    /// Field `name` of line `i` as a number.
    pub fn num_of(&self, i: usize, name: &str) -> u64 {
        self.num(i, self.place(i, name))
    }

    /// Field `name` of line `i` (the layout's name; `key=` for `H` and `E`).
    pub fn get(&self, i: usize, name: &str) -> String {
        match self.kind(i) {
            b'H' | b'E' => self.key(i, name),
            _ => self.field(i, self.place(i, name)),
        }
    }

    /// Field `name` of line `i` set to `v`, the line sealed again.
    pub fn set_field(&mut self, i: usize, name: &str, v: &str) -> &mut Self {
        match self.kind(i) {
            b'H' | b'E' => {
                // The key must be there: a vector never adds one.
                self.place(i, name);
                self.set_key(i, name, v)
            }
            _ => {
                let k = self.place(i, name);
                self.set(i, k, v)
            }
        }
    }

    /// Field `k` of line `i` as a number.
    pub fn num(&self, i: usize, k: usize) -> u64 {
        self.field(i, k).parse().unwrap_or(0)
    }

    /// Line `i` replaced by `body`, sealed with its CRC.
    pub fn seal(&mut self, i: usize, body: &str) {
        self.0[i] = sealed(body);
    }

    /// Field `k` of line `i` set to `v`, the line sealed again.
    pub fn set(&mut self, i: usize, k: usize, v: &str) -> &mut Self {
        let mut f: Vec<String> = self.body(i).split(',').map(String::from).collect();
        f[k] = v.to_string();
        self.seal(i, &f.join(","));
        self
    }

    /// The value of `key=` in line `i` set to `v`, the line sealed again.
    pub fn set_key(&mut self, i: usize, key: &str, v: &str) -> &mut Self {
        let f: Vec<String> = self
            .body(i)
            .split(',')
            .map(|f| match f.split_once('=') {
                Some((k, _)) if k == key => format!("{k}={v}"),
                _ => f.to_string(),
            })
            .collect();
        self.seal(i, &f.join(","));
        self
    }

    /// The value of `key=` in line `i`.
    pub fn key(&self, i: usize, key: &str) -> String {
        self.body(i)
            .split(',')
            .find_map(|f| {
                f.split_once('=')
                    .filter(|(k, _)| *k == key)
                    .map(|(_, v)| v.to_string())
            })
            .unwrap_or_default()
    }

    /// One byte in the middle of line `i` changed (the CRC no longer matches).
    pub fn corrupt(&mut self, i: usize) -> &mut Self {
        let l = &mut self.0[i];
        let at = l.len() / 2;
        l[at] = if l[at] == b'7' { b'3' } else { b'7' };
        self
    }

    pub fn remove(&mut self, i: usize) -> Vec<u8> {
        self.0.remove(i)
    }

    pub fn insert(&mut self, i: usize, line: Vec<u8>) -> &mut Self {
        self.0.insert(i, line);
        self
    }

    /// Line `from` moved to stand at index `to` of the result.
    pub fn mv(&mut self, from: usize, to: usize) -> &mut Self {
        let l = self.0.remove(from);
        self.0.insert(to, l);
        self
    }
}

/// `body*XXXX\n` with the body's CRC.
pub fn sealed(body: &str) -> Vec<u8> {
    format!("{body}*{:04X}\n", protocol::crc16(body.as_bytes())).into_bytes()
}
