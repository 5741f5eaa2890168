//! The SHA-256 of every input as it was read. Inputs are hashed while they stream through
//! [`crate::files::Input`] (a pipe or standard input can be read only once), so the digest is
//! of exactly the bytes the command used.

use std::io::Read;
use std::sync::{Arc, Mutex};

use serde::Serialize;
use sha2::{Digest as _, Sha256};

/// One input's running digest.
struct Hashed {
    name: String,
    state: Mutex<(Sha256, u64)>,
}

/// Every input this process opened, in order (a command opens a handful).
static OPENED: Mutex<Vec<Arc<Hashed>>> = Mutex::new(Vec::new());

/// A reader that feeds every byte it yields into its input's digest.
pub struct Hashing<R> {
    inner: R,
    hashed: Arc<Hashed>,
}

impl<R: Read> Read for Hashing<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        if let Ok(mut s) = self.hashed.state.lock() {
            s.0.update(&buf[..n]);
            s.1 += n as u64;
        }
        Ok(n)
    }
}

impl<R> Hashing<R> {
    /// The input's digest as it stands whenever asked (final once the input is read to its end).
    pub fn digest(&self) -> Digest {
        Digest(self.hashed.clone())
    }
}

/// One input's running digest, kept after its reader is gone.
#[derive(Clone)]
pub struct Digest(Arc<Hashed>);

impl Digest {
    /// SHA-256 of the bytes read so far, lower-case hex.
    pub fn sha256(&self) -> String {
        self.0.sha256().unwrap_or_default()
    }
}

impl Hashed {
    /// SHA-256 of the bytes read so far (hex) and their count.
    fn sha256(&self) -> Option<String> {
        let s = self.state.lock().ok()?;
        Some(s.0.clone().finalize().iter().map(|b| format!("{b:02x}")).collect())
    }
}

/// `inner`, hashed as it is read and listed in `Provenance::inputs` under `name`.
pub fn hashing<R: Read>(name: &str, inner: R) -> Hashing<R> {
    let hashed = Arc::new(Hashed { name: name.into(), state: Mutex::new((Sha256::new(), 0)) });
    if let Ok(mut all) = OPENED.lock() {
        all.push(hashed.clone());
    }
    Hashing { inner, hashed }
}

/// One input: its name as given and the SHA-256 of the bytes read from it.
#[derive(Debug, Clone, Serialize, PartialEq, Eq)]
pub struct InputDigest {
    /// As in messages (`<stdin>` for `-`).
    pub file: String,
    /// SHA-256 of its bytes, lower-case hex.
    pub sha256: String,
    /// Bytes read.
    pub bytes: u64,
}

/// The digests of every input opened so far (each of the bytes read up to now: a command asks
/// once its inputs have been read to the end).
pub fn input_digests() -> Vec<InputDigest> {
    let Ok(all) = OPENED.lock() else { return Vec::new() };
    all.iter()
        .filter_map(|h| {
            let sha256 = h.sha256()?;
            let bytes = h.state.lock().ok()?.1;
            Some(InputDigest { file: h.name.clone(), sha256, bytes })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use std::io::Read;

    use super::*;

    #[test]
    fn digests_are_of_the_bytes_read() {
        let mut r = hashing("unit-test-abc", &b"abc"[..]);
        let mut s = String::new();
        r.read_to_string(&mut s).unwrap();
        let d = input_digests().into_iter().find(|d| d.file == "unit-test-abc").unwrap();
        // FIPS 180-2 test vector for "abc".
        assert_eq!(d.sha256, "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
        assert_eq!(d.bytes, 3);
        assert_eq!(r.digest().sha256(), d.sha256);
    }
}
