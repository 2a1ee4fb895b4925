//! A small, explicit binary format for saving and restoring an episode's dynamic state
//! (snapshots for `get_state`/`set_state` and pickling). Little-endian, fixed widths, no
//! padding; every value is written in full precision, so a restored episode continues bit for
//! bit. Readers check lengths and report a truncated or malformed state as an error, never a
//! panic.

use crate::error::{Result, SimError};

/// Appends values to a byte buffer.
#[derive(Debug, Default, Clone)]
pub struct StateWriter {
    bytes: Vec<u8>,
}

impl StateWriter {
    /// An empty writer.
    pub fn new() -> Self {
        StateWriter::default()
    }

    /// The bytes written.
    pub fn into_bytes(self) -> Vec<u8> {
        self.bytes
    }

    /// Writes raw bytes (no length prefix).
    pub fn raw(&mut self, bytes: &[u8]) {
        self.bytes.extend_from_slice(bytes);
    }

    /// Writes a `u64`.
    pub fn u64(&mut self, v: u64) {
        self.raw(&v.to_le_bytes());
    }

    /// Writes a `u128`.
    pub fn u128(&mut self, v: u128) {
        self.raw(&v.to_le_bytes());
    }

    /// Writes an `i64`.
    pub fn i64(&mut self, v: i64) {
        self.raw(&v.to_le_bytes());
    }

    /// Writes an `f64` (its bits).
    pub fn f64(&mut self, v: f64) {
        self.raw(&v.to_le_bytes());
    }

    /// Writes a `bool` as one byte.
    pub fn bool(&mut self, v: bool) {
        self.raw(&[v as u8]);
    }

    /// Writes a length-prefixed slice of `f64`.
    pub fn f64s(&mut self, v: &[f64]) {
        self.u64(v.len() as u64);
        for x in v {
            self.f64(*x);
        }
    }

    /// Writes a length-prefixed slice of `f32`.
    pub fn f32s(&mut self, v: &[f32]) {
        self.u64(v.len() as u64);
        for x in v {
            self.raw(&x.to_le_bytes());
        }
    }

    /// Writes a length-prefixed byte string.
    pub fn bytes(&mut self, v: &[u8]) {
        self.u64(v.len() as u64);
        self.raw(v);
    }
}

/// Reads values written by [`StateWriter`], in the same order.
#[derive(Debug, Clone)]
pub struct StateReader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> StateReader<'a> {
    /// A reader over `bytes`.
    pub fn new(bytes: &'a [u8]) -> Self {
        StateReader { bytes, at: 0 }
    }

    fn malformed(&self, what: &str) -> SimError {
        SimError::invalid_config(
            "state",
            format!("{} bytes", self.bytes.len()),
            &format!(
                "a state saved by this version (could not read {what} at byte {})",
                self.at
            ),
        )
    }

    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8]> {
        if self.bytes.len() - self.at < n {
            return Err(self.malformed(what));
        }
        let out = &self.bytes[self.at..self.at + n];
        self.at += n;
        Ok(out)
    }

    fn array<const N: usize>(&mut self, what: &str) -> Result<[u8; N]> {
        let mut out = [0u8; N];
        out.copy_from_slice(self.take(N, what)?);
        Ok(out)
    }

    /// Reads `N` raw bytes.
    pub fn raw<const N: usize>(&mut self, what: &str) -> Result<[u8; N]> {
        self.array(what)
    }

    /// Reads a `u64`.
    pub fn u64(&mut self, what: &str) -> Result<u64> {
        Ok(u64::from_le_bytes(self.array(what)?))
    }

    /// Reads a `u128`.
    pub fn u128(&mut self, what: &str) -> Result<u128> {
        Ok(u128::from_le_bytes(self.array(what)?))
    }

    /// Reads an `i64`.
    pub fn i64(&mut self, what: &str) -> Result<i64> {
        Ok(i64::from_le_bytes(self.array(what)?))
    }

    /// Reads an `f64`.
    pub fn f64(&mut self, what: &str) -> Result<f64> {
        Ok(f64::from_le_bytes(self.array(what)?))
    }

    /// Reads a `bool`.
    pub fn bool(&mut self, what: &str) -> Result<bool> {
        match self.take(1, what)?[0] {
            0 => Ok(false),
            1 => Ok(true),
            _ => Err(self.malformed(what)),
        }
    }

    fn len(&mut self, what: &str, expected: usize) -> Result<usize> {
        let n = self.u64(what)?;
        if n != expected as u64 {
            return Err(SimError::invalid_config(
                "state",
                format!("{what} of length {n}"),
                &format!("a state of this configuration ({what} of length {expected})"),
            ));
        }
        Ok(expected)
    }

    /// Reads a length-prefixed `f64` slice into `out`, whose length must match.
    pub fn f64s_into(&mut self, what: &str, out: &mut [f64]) -> Result<()> {
        self.len(what, out.len())?;
        for x in out.iter_mut() {
            *x = self.f64(what)?;
        }
        Ok(())
    }

    /// Reads a length-prefixed `f32` slice into `out`, whose length must match.
    pub fn f32s_into(&mut self, what: &str, out: &mut [f32]) -> Result<()> {
        self.len(what, out.len())?;
        for x in out.iter_mut() {
            *x = f32::from_le_bytes(self.array(what)?);
        }
        Ok(())
    }

    /// Reads a length-prefixed byte string.
    pub fn bytes(&mut self, what: &str) -> Result<&'a [u8]> {
        let n = self.u64(what)?;
        let n = usize::try_from(n).map_err(|_| self.malformed(what))?;
        self.take(n, what)
    }

    /// Fails unless every byte was read.
    pub fn finish(&self) -> Result<()> {
        if self.at != self.bytes.len() {
            return Err(self.malformed("the end (trailing bytes)"));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_truncation() {
        let mut w = StateWriter::new();
        w.u64(7);
        w.f64(-0.1);
        w.bool(true);
        w.f64s(&[1.0, f64::MIN_POSITIVE]);
        w.f32s(&[2.5]);
        w.u128(u128::MAX - 3);
        w.i64(-9);
        w.bytes(b"abc");
        let bytes = w.into_bytes();
        let mut r = StateReader::new(&bytes);
        assert_eq!(r.u64("a").unwrap(), 7);
        assert_eq!(r.f64("b").unwrap().to_bits(), (-0.1f64).to_bits());
        assert!(r.bool("c").unwrap());
        let mut v = [0.0; 2];
        r.f64s_into("d", &mut v).unwrap();
        assert_eq!(v, [1.0, f64::MIN_POSITIVE]);
        let mut f = [0.0f32; 1];
        r.f32s_into("e", &mut f).unwrap();
        assert_eq!(f, [2.5]);
        assert_eq!(r.u128("f").unwrap(), u128::MAX - 3);
        assert_eq!(r.i64("g").unwrap(), -9);
        assert_eq!(r.bytes("h").unwrap(), b"abc");
        r.finish().unwrap();

        for cut in 0..bytes.len() {
            let mut r = StateReader::new(&bytes[..cut]);
            let ok = (|| -> Result<()> {
                r.u64("a")?;
                r.f64("b")?;
                r.bool("c")?;
                r.f64s_into("d", &mut v)?;
                r.f32s_into("e", &mut f)?;
                r.u128("f")?;
                r.i64("g")?;
                r.bytes("h")?;
                Ok(())
            })();
            assert!(ok.is_err(), "cut at {cut} must fail");
        }
        let mut r = StateReader::new(&bytes);
        let mut wrong = [0.0; 3];
        r.u64("a").unwrap();
        r.f64("b").unwrap();
        r.bool("c").unwrap();
        assert!(r.f64s_into("d", &mut wrong).is_err());
    }
}
