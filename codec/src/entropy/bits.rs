//! The raw bit stream of column encoding 4: bits that no model predicts
//! (the low magnitude bits), packed most significant first, outside the
//! range coder so that they cost no arithmetic to read.

use crate::error::{Error, Result};

/// Appends bits, most significant first, into bytes filled from their top
/// bit.
#[derive(Default)]
pub struct BitWriter {
    out: Vec<u8>,
    acc: u64,
    /// Bits held in `acc` (below 8 between calls).
    held: u32,
}

impl BitWriter {
    /// Appends the low `n` bits of `value` (`n ≤ 32`), most significant
    /// first.
    pub fn put(&mut self, n: u32, value: u32) {
        debug_assert!(n <= 32 && (n == 32 || value >> n == 0));
        self.acc = self.acc << n | value as u64;
        self.held += n;
        while self.held >= 8 {
            self.held -= 8;
            self.out.push((self.acc >> self.held) as u8);
        }
        self.acc &= (1 << self.held) - 1;
    }

    /// The bytes, the last one padded with 0 bits.
    pub fn finish(mut self) -> Vec<u8> {
        if self.held > 0 {
            self.out.push((self.acc << (8 - self.held)) as u8);
        }
        self.out
    }
}

/// Reads what a [`BitWriter`] wrote; bits past the end read as 0 and are
/// counted, so that [`BitReader::finish`] refuses the stream.
pub struct BitReader<'a> {
    bytes: &'a [u8],
    pos: usize,
    acc: u64,
    /// Bits held in `acc`.
    held: u32,
    /// Bits read past the end.
    past: u64,
}

impl<'a> BitReader<'a> {
    /// Starts reading `bytes`.
    pub fn new(bytes: &'a [u8]) -> BitReader<'a> {
        BitReader {
            bytes,
            pos: 0,
            acc: 0,
            held: 0,
            past: 0,
        }
    }

    /// Reads `n ≤ 32` bits, most significant first.
    #[inline(always)]
    pub fn get(&mut self, n: u32) -> u32 {
        debug_assert!(n <= 32);
        if self.held < n {
            self.refill();
        }
        if self.held < n {
            // At the end: pad with 0 bits.
            let short = n - self.held;
            self.past += short as u64;
            self.acc <<= short;
            self.held += short;
        }
        self.held -= n;
        let v = (self.acc >> self.held) as u32 & (((1u64 << n) - 1) as u32);
        self.acc &= (1u64 << self.held) - 1;
        v
    }

    /// Tops `acc` up to at least 57 bits while bytes remain.
    #[inline(always)]
    fn refill(&mut self) {
        if let Some(chunk) = self.bytes.get(self.pos..self.pos + 8) {
            let take = (63 - self.held) / 8;
            let word = u64::from_be_bytes(chunk.try_into().expect("8 bytes"));
            self.acc = self.acc << (8 * take) | word >> (64 - 8 * take);
            self.held += 8 * take;
            self.pos += take as usize;
        } else {
            while self.held <= 56 && self.pos < self.bytes.len() {
                self.acc = self.acc << 8 | self.bytes[self.pos] as u64;
                self.held += 8;
                self.pos += 1;
            }
        }
    }

    /// Whether more bits than the stream holds were read.
    pub fn overrun(&self) -> bool {
        self.past > 0
    }

    /// Checks that exactly the stream's bits were read: none past the end,
    /// no byte left unread, and the last byte's padding bits 0.
    pub fn finish(&self) -> Result<()> {
        let unread = (self.bytes.len() - self.pos) as u64 * 8 + self.held as u64;
        if self.past > 0 {
            return Err(Error::corrupt(
                "column payload",
                format!(
                    "raw bit stream of {} bytes ends {} bits early",
                    self.bytes.len(),
                    self.past
                ),
            ));
        }
        if unread >= 8 || self.acc != 0 {
            return Err(Error::corrupt(
                "column payload",
                format!("{unread} bits left after the raw bit stream (valid: 0..=7, all 0)"),
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn bits_round_trip(items in prop::collection::vec((0u32..=32, any::<u32>()), 0..400)) {
            let items: Vec<(u32, u32)> = items
                .into_iter()
                .map(|(n, v)| (n, if n == 32 { v } else { v & ((1u32 << n) - 1) }))
                .collect();
            let mut w = BitWriter::default();
            for &(n, v) in &items {
                w.put(n, v);
            }
            let bytes = w.finish();
            let total: u32 = items.iter().map(|i| i.0).sum();
            prop_assert_eq!(bytes.len() as u32, total.div_ceil(8));
            let mut r = BitReader::new(&bytes);
            for &(n, v) in &items {
                prop_assert_eq!(r.get(n), v);
            }
            prop_assert!(r.finish().is_ok());
            // One bit more is an error, and so is a byte more.
            let mut more = BitReader::new(&bytes);
            for &(n, _) in &items {
                more.get(n);
            }
            if total.is_multiple_of(8) {
                more.get(1);
                prop_assert!(more.finish().is_err());
            }
            let mut longer = bytes.clone();
            longer.push(0);
            let mut r = BitReader::new(&longer);
            for &(n, _) in &items {
                r.get(n);
            }
            prop_assert!(r.finish().is_err());
        }
    }

    #[test]
    fn non_zero_padding_is_an_error() {
        let mut w = BitWriter::default();
        w.put(3, 0b101);
        let mut bytes = w.finish();
        assert_eq!(bytes, [0b1010_0000]);
        bytes[0] |= 1;
        let mut r = BitReader::new(&bytes);
        assert_eq!(r.get(3), 0b101);
        assert!(r.finish().is_err());
    }
}
