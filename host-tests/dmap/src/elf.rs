//! A firmware ELF as `dmap twin --elf` and `dmap emulate --elf` take it:
//! checked to be a whole 32-bit little-endian ARM executable before a
//! model or QEMU is started on it (either would fail on a bad one with a
//! dump of its own, or wait forever), and the configuration the H743 build
//! wrote into its `.cvm_config` section (not loaded: no flash).

use anyhow::{Result, bail};
use std::io::Read;
use std::path::Path;

/// The most of an ELF that is read: the release firmware's is a few
/// hundred KB with its symbols.
const MAX_ELF_BYTES: u64 = 64 << 20;

/// `EM_ARM`.
const MACHINE_ARM: u16 = 40;

/// The section the H743 build writes its configuration to (build.rs).
pub const CONFIG_SECTION: &str = ".cvm_config";

fn u16_at(b: &[u8], at: usize) -> Option<u16> {
    Some(u16::from_le_bytes(b.get(at..at + 2)?.try_into().ok()?))
}

fn u32_at(b: &[u8], at: usize) -> Option<u32> {
    Some(u32::from_le_bytes(b.get(at..at + 4)?.try_into().ok()?))
}

/// A table of `count` entries of `size` bytes at `off`: whether it lies
/// within the file.
fn table_fits(len: usize, off: u32, size: u16, count: u16) -> bool {
    (off as usize)
        .checked_add(usize::from(size) * usize::from(count))
        .is_some_and(|end| end <= len)
}

/// Reads the ELF at `path` and checks that it is a complete 32-bit
/// little-endian ARM executable: headers, program headers, loaded
/// segments and section headers all within the file.
pub fn read(path: &Path) -> Result<Vec<u8>> {
    let p = path.display();
    let meta = match std::fs::metadata(path) {
        Ok(m) => m,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            bail!("firmware ELF {p} not found")
        }
        Err(e) => bail!("firmware ELF {p}: {e}"),
    };
    if meta.is_dir() {
        bail!("firmware ELF {p} is a directory, not an ELF file");
    }
    let mut bytes = Vec::new();
    std::fs::File::open(path)
        .and_then(|f| f.take(MAX_ELF_BYTES + 1).read_to_end(&mut bytes))
        .map_err(|e| anyhow::anyhow!("firmware ELF {p}: {e}"))?;
    if bytes.len() as u64 > MAX_ELF_BYTES {
        bail!(
            "firmware ELF {p} is larger than {} MiB: not a firmware image",
            MAX_ELF_BYTES >> 20
        );
    }
    check(&bytes).map_err(|why| anyhow::anyhow!("firmware ELF {p}: {why}"))?;
    Ok(bytes)
}

/// Why `b` is not a complete 32-bit little-endian ARM executable, if not.
fn check(b: &[u8]) -> std::result::Result<(), String> {
    if b.get(..4) != Some(b"\x7fELF") {
        return Err("not an ELF file".into());
    }
    if b.len() < 52 {
        return Err("truncated (shorter than an ELF header)".into());
    }
    if b[4] != 1 || b[5] != 1 {
        return Err(
            "not a 32-bit little-endian ELF (the firmware is built for ARM Cortex-M)".into(),
        );
    }
    let machine = u16_at(b, 18).unwrap_or(0);
    if machine != MACHINE_ARM {
        return Err(format!(
            "built for machine {machine}, not ARM (the firmware is built for ARM Cortex-M)"
        ));
    }
    if u16_at(b, 16) != Some(2) {
        return Err("not an executable".into());
    }
    let (phoff, shoff) = (u32_at(b, 28).unwrap_or(0), u32_at(b, 32).unwrap_or(0));
    let (phsize, phnum) = (u16_at(b, 42).unwrap_or(0), u16_at(b, 44).unwrap_or(0));
    let (shsize, shnum) = (u16_at(b, 46).unwrap_or(0), u16_at(b, 48).unwrap_or(0));
    if phnum == 0 || phsize < 32 || !table_fits(b.len(), phoff, phsize, phnum) {
        return Err("truncated or damaged (program headers missing or past its end)".into());
    }
    for i in 0..usize::from(phnum) {
        let at = phoff as usize + i * usize::from(phsize);
        let (off, filesz) = (u32_at(b, at + 4), u32_at(b, at + 16));
        let fits = off
            .zip(filesz)
            .and_then(|(o, n)| (o as usize).checked_add(n as usize))
            .is_some_and(|end| end <= b.len());
        if !fits {
            return Err(format!("truncated (segment {i} runs past its end)"));
        }
    }
    if shnum != 0 && (shsize < 40 || !table_fits(b.len(), shoff, shsize, shnum)) {
        return Err("truncated (section headers past its end)".into());
    }
    Ok(())
}

/// The contents of section `name` of a checked ELF, if it has one.
pub fn section<'a>(b: &'a [u8], name: &str) -> Option<&'a [u8]> {
    let shoff = u32_at(b, 32)? as usize;
    let (shsize, shnum) = (usize::from(u16_at(b, 46)?), usize::from(u16_at(b, 48)?));
    let shstrndx = usize::from(u16_at(b, 50)?);
    let header = |i: usize| shoff.checked_add(i.checked_mul(shsize)?);
    let contents = |i: usize| -> Option<&'a [u8]> {
        let at = header(i)?;
        let (off, size) = (u32_at(b, at + 16)? as usize, u32_at(b, at + 20)? as usize);
        b.get(off..off.checked_add(size)?)
    };
    let names = contents(shstrndx)?;
    (0..shnum).find_map(|i| {
        let at = header(i)?;
        let n = u32_at(b, at)? as usize;
        let rest = names.get(n..)?;
        let end = rest.iter().position(|&c| c == 0)?;
        (&rest[..end] == name.as_bytes())
            .then(|| contents(i))
            .flatten()
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A minimal ELF built by hand from the format: header, one program
    /// header, three sections (null, `.cvm_config`, `.shstrtab`).
    fn tiny(machine: u16) -> Vec<u8> {
        let names = b"\0.cvm_config\0.shstrtab\0";
        let body = b"j1=9 j2=9";
        let mut b = vec![0u8; 52];
        b[..4].copy_from_slice(b"\x7fELF");
        b[4] = 1;
        b[5] = 1;
        b[16..18].copy_from_slice(&2u16.to_le_bytes());
        b[18..20].copy_from_slice(&machine.to_le_bytes());
        let phoff = b.len() as u32;
        let mut ph = vec![0u8; 32];
        ph[4..8].copy_from_slice(&0u32.to_le_bytes());
        ph[16..20].copy_from_slice(&52u32.to_le_bytes());
        b.extend(ph);
        let body_off = b.len() as u32;
        b.extend(body);
        let names_off = b.len() as u32;
        b.extend(names);
        let shoff = b.len() as u32;
        let sh = |name: u32, off: u32, size: u32| {
            let mut h = vec![0u8; 40];
            h[..4].copy_from_slice(&name.to_le_bytes());
            h[16..20].copy_from_slice(&off.to_le_bytes());
            h[20..24].copy_from_slice(&size.to_le_bytes());
            h
        };
        b.extend(sh(0, 0, 0));
        b.extend(sh(1, body_off, body.len() as u32));
        b.extend(sh(13, names_off, names.len() as u32));
        b[28..32].copy_from_slice(&phoff.to_le_bytes());
        b[32..36].copy_from_slice(&shoff.to_le_bytes());
        b[42..44].copy_from_slice(&32u16.to_le_bytes());
        b[44..46].copy_from_slice(&1u16.to_le_bytes());
        b[46..48].copy_from_slice(&40u16.to_le_bytes());
        b[48..50].copy_from_slice(&3u16.to_le_bytes());
        b[50..52].copy_from_slice(&2u16.to_le_bytes());
        b
    }

    #[test]
    fn a_whole_arm_elf_passes_and_its_section_is_found() {
        let b = tiny(MACHINE_ARM);
        assert_eq!(check(&b), Ok(()));
        assert_eq!(section(&b, CONFIG_SECTION), Some(&b"j1=9 j2=9"[..]));
        assert_eq!(section(&b, ".text"), None);
    }

    #[test]
    fn damaged_or_foreign_elfs_are_named() {
        let b = tiny(MACHINE_ARM);
        assert!(check(&[]).unwrap_err().contains("not an ELF"));
        assert!(
            check(b"garbage garbage")
                .unwrap_err()
                .contains("not an ELF")
        );
        assert!(check(&b[..30]).unwrap_err().contains("truncated"));
        assert!(
            check(&b[..b.len() - 1])
                .unwrap_err()
                .contains("section headers")
        );
        assert!(check(&tiny(62)).unwrap_err().contains("machine 62"));
        let mut c = b.clone();
        c[4] = 2;
        assert!(check(&c).unwrap_err().contains("32-bit"));
    }
}
