//! Little-endian byte buffers read back with typed errors: the formats svetlo exchanges
//! between processes (partial films, radiosity rows and solutions) are untrusted input, so a
//! truncated or oversized buffer is an `Error::Invalid` naming what was read, never a panic.

use crate::error::{Error, Result};
use crate::spectrum::Rgb;

/// A cursor over `b`; errors say `what` is being read ("partial film", "radiosity solution").
pub(crate) struct ByteReader<'a> {
    b: &'a [u8],
    at: usize,
    what: &'static str,
}

impl<'a> ByteReader<'a> {
    pub(crate) fn new(b: &'a [u8], what: &'static str) -> Self {
        ByteReader { b, at: 0, what }
    }

    /// The error for this buffer: "`what`: `msg`".
    pub(crate) fn bad(&self, msg: impl std::fmt::Display) -> Error {
        Error::Invalid(format!("{}: {msg}", self.what))
    }

    /// Bytes not read yet.
    pub(crate) fn left(&self) -> usize {
        self.b.len() - self.at
    }

    pub(crate) fn take(&mut self, n: usize) -> Result<&'a [u8]> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.b.len()).ok_or_else(|| self.bad(format!("truncated at byte {}", self.at)))?;
        let s = &self.b[self.at..end];
        self.at = end;
        Ok(s)
    }
    fn array<const N: usize>(&mut self) -> Result<[u8; N]> {
        Ok(self.take(N)?.try_into().expect("take returns N bytes"))
    }
    pub(crate) fn u8(&mut self) -> Result<u8> {
        Ok(self.take(1)?[0])
    }
    pub(crate) fn u32(&mut self) -> Result<u32> {
        Ok(u32::from_le_bytes(self.array()?))
    }
    pub(crate) fn u64(&mut self) -> Result<u64> {
        Ok(u64::from_le_bytes(self.array()?))
    }
    pub(crate) fn f32(&mut self) -> Result<f32> {
        Ok(f32::from_le_bytes(self.array()?))
    }
    pub(crate) fn f64(&mut self) -> Result<f64> {
        Ok(f64::from_le_bytes(self.array()?))
    }
    pub(crate) fn rgb(&mut self) -> Result<Rgb> {
        Ok(Rgb { r: self.f32()?, g: self.f32()?, b: self.f32()? })
    }
    /// `n` colours (the caller has checked that `n` fits).
    pub(crate) fn rgbs(&mut self, n: usize) -> Result<Vec<Rgb>> {
        (0..n).map(|_| self.rgb()).collect()
    }
    /// A u64 count of items of `each` bytes, checked to fit in what is left before anything
    /// is allocated for them.
    pub(crate) fn count(&mut self, each: usize) -> Result<usize> {
        let n = self.u64()?;
        let left = self.left() as u64;
        if n.checked_mul(each as u64).is_none_or(|x| x > left) {
            return Err(self.bad(format!("{n} items do not fit in the {left} bytes left")));
        }
        Ok(n as usize)
    }
    /// A counted list of colours (see [`ByteReader::count`]).
    pub(crate) fn counted_rgbs(&mut self) -> Result<Vec<Rgb>> {
        let n = self.count(12)?;
        self.rgbs(n)
    }
    /// Everything was read.
    pub(crate) fn end(&self) -> Result<()> {
        match self.left() {
            0 => Ok(()),
            n => Err(self.bad(format!("{n} bytes left over"))),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_back_and_refuses_what_does_not_fit() {
        let mut b = vec![7u8];
        b.extend_from_slice(&2u64.to_le_bytes());
        for v in [1.0f32, 2.0, 3.0, 4.0, 5.0, 6.0] {
            b.extend_from_slice(&v.to_le_bytes());
        }
        let mut r = ByteReader::new(&b, "test data");
        assert_eq!(r.u8().unwrap(), 7);
        assert_eq!(r.counted_rgbs().unwrap(), vec![Rgb::new(1.0, 2.0, 3.0), Rgb::new(4.0, 5.0, 6.0)]);
        r.end().unwrap();
        assert_eq!(r.u32().unwrap_err().to_string(), Error::Invalid("test data: truncated at byte 33".into()).to_string());
        // A count larger than the buffer is refused before allocating.
        let mut big = u64::MAX.to_le_bytes().to_vec();
        big.extend_from_slice(&[0; 12]);
        let e = ByteReader::new(&big, "test data").counted_rgbs().unwrap_err().to_string();
        assert!(e.contains("do not fit"), "{e}");
        assert!(ByteReader::new(&[1, 2], "test data").end().unwrap_err().to_string().contains("2 bytes left over"));
    }
}
