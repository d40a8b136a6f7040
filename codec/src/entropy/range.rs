//! An adaptive range coder: 32-bit range, byte-wise output with carry
//! propagation. Binary contexts hold 15-bit probabilities whose adaptation
//! rate slows from 1/2 to 1/32 as a context sees more bits; 17-symbol
//! contexts ([`Cdf`], encoding 4) hold 15-bit cumulative frequencies that
//! adapt the same way. docs/FORMAT.md ("Encoding 3", "Encoding 4") gives
//! the exact arithmetic; this is the reference.

use crate::error::{Error, Result};

/// Probability precision: a context's probability of a 0 is `p / 2^15`.
const PROB_BITS: u32 = 15;
const PROB_ONE: u32 = 1 << PROB_BITS;
/// Probabilities stay in `[PROB_MIN, PROB_ONE − PROB_MIN]`.
const PROB_MIN: u32 = 31;
/// The range is renormalized (one byte shifted out) while below this.
const TOP: u32 = 1 << 24;
/// Adaptation shifts cap at this (rate 1/32).
const MAX_SHIFT: u32 = 5;
/// Bytes a decoder may read past the end of a stream (read as 0): the
/// encoder drops the flush's trailing zero bytes.
const MAX_OVERRUN: usize = 4;

/// `min(1 + ⌊log2(n + 1)⌋, 5)` for `n = 0..=32`.
const SHIFTS: [u32; 33] = {
    let mut t = [0u32; 33];
    let mut n = 0;
    while n < 33 {
        let s = 1 + (31 - (n as u32 + 1).leading_zeros());
        t[n] = if s < MAX_SHIFT { s } else { MAX_SHIFT };
        n += 1;
    }
    t
};

/// One adaptive binary context: the probability of a 0 and how many bits
/// it has seen (capped).
#[derive(Clone, Copy, Debug)]
pub struct Context {
    p: u16,
    n: u16,
}

impl Default for Context {
    fn default() -> Context {
        Context {
            p: (PROB_ONE / 2) as u16,
            n: 0,
        }
    }
}

impl Context {
    /// The probability of a 0 (in units of 2^−15) and the count of bits
    /// seen (capped at 32).
    pub(crate) fn state(&self) -> (u16, u16) {
        (self.p, self.n)
    }

    /// A context in state `(p, n)`, if it is one a context can reach: `p`
    /// within `[31, 2^15 − 31]`, `n ≤ 32`.
    pub(crate) fn from_state(p: u16, n: u16) -> Option<Context> {
        ((PROB_MIN..=PROB_ONE - PROB_MIN).contains(&(p as u32)) && n <= 1 << MAX_SHIFT)
            .then_some(Context { p, n })
    }

    /// Scaled bound of the 0 interval of a `range`.
    #[inline]
    fn bound(&self, range: u32) -> u32 {
        (range >> PROB_BITS) * self.p as u32
    }

    /// [`Context::update`] for the bit whose `mask` is all ones for a 1 and
    /// 0 for a 0, without a branch on it.
    #[inline(always)]
    fn update_masked(&mut self, mask: u32) {
        let n = self.n as u32;
        let shift = SHIFTS[n as usize];
        let p = self.p as u32;
        let down = p - (p >> shift);
        let up = p + ((PROB_ONE - p) >> shift);
        let p = (down & mask) | (up & !mask);
        self.p = p.clamp(PROB_MIN, PROB_ONE - PROB_MIN) as u16;
        self.n += u16::from(n < (1 << MAX_SHIFT));
    }

    /// Moves the probability towards the bit seen, by `1/2^shift` with
    /// `shift = min(1 + ⌊log2(n + 1)⌋, 5)`.
    #[inline(always)]
    fn update(&mut self, bit: bool) {
        let n = self.n as u32;
        let shift = SHIFTS[n as usize];
        let p = self.p as u32;
        let p = if bit {
            p - (p >> shift)
        } else {
            p + ((PROB_ONE - p) >> shift)
        };
        self.p = p.clamp(PROB_MIN, PROB_ONE - PROB_MIN) as u16;
        if n < (1 << MAX_SHIFT) {
            self.n += 1;
        }
    }
}

/// Symbols of a [`Cdf`]: 0..=16.
pub const SYMBOLS: usize = 17;
/// The part of the total a [`Cdf`] adapts: every symbol keeps at least
/// 1/2^15 of it on top.
const CDF_FREE: i32 = PROB_ONE as i32 - SYMBOLS as i32;
/// One adaptive 17-symbol context: cumulative frequencies `b[s]` (the
/// total below symbol `s`, in units of 2^−15) with `b[0] = 0`,
/// `b[17] = 2^15` and `b[s + 1] − b[s] ≥ 1`, and a count of the symbols
/// seen (capped). It stores `b[1..=16]`, which all fit an `i16`.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(32))]
pub struct Cdf {
    inner: [i16; SYMBOLS - 1],
    n: u16,
}

/// `1, 2, …, 16`: the symbol index of each stored frequency.
const INDEX: [i16; SYMBOLS - 1] = {
    let mut t = [0i16; SYMBOLS - 1];
    let mut k = 0;
    while k < SYMBOLS - 1 {
        t[k] = k as i16 + 1;
        k += 1;
    }
    t
};

impl Default for Cdf {
    /// Every symbol about equally likely: `b[s] = s·⌊2^15/17⌋`.
    fn default() -> Cdf {
        Cdf {
            inner: INDEX.map(|i| i * (PROB_ONE / SYMBOLS as u32) as i16),
            n: 0,
        }
    }
}

impl Cdf {
    /// The free parts `a[i] = b[i] − i` (`i = 1..=16`) of the cumulative
    /// frequencies and the count of symbols seen (capped at 32).
    pub(crate) fn state(&self) -> ([u16; SYMBOLS - 1], u16) {
        (
            std::array::from_fn(|k| (self.inner[k] - INDEX[k]) as u16),
            self.n,
        )
    }

    /// A context in state `(a, n)`, if it is one a context can reach:
    /// `0 ≤ a[1] ≤ … ≤ a[16] ≤ 2^15 − 17`, `n ≤ 32`.
    pub(crate) fn from_state(a: [u16; SYMBOLS - 1], n: u16) -> Option<Cdf> {
        let ordered = a.windows(2).all(|w| w[0] <= w[1]);
        (ordered && a[SYMBOLS - 2] as i32 <= CDF_FREE && n <= 1 << MAX_SHIFT).then(|| Cdf {
            inner: std::array::from_fn(|k| a[k] as i16 + INDEX[k]),
            n,
        })
    }

    /// `b[s]`, `s = 0..=17`.
    #[cfg(test)]
    fn b(&self, s: usize) -> u32 {
        match s {
            0 => 0,
            SYMBOLS => PROB_ONE,
            _ => self.inner[s - 1] as u32,
        }
    }

    /// The symbol whose scaled interval holds `t` (`≤ 2^15 − 1`): how many
    /// of `b[1..=16]` are at most `t`.
    #[inline(always)]
    fn find(&self, t: i16) -> usize {
        // Lane-wise, so that it compiles to vector compares.
        let mut count = [0i16; SYMBOLS - 1];
        for (c, &b) in count.iter_mut().zip(&self.inner) {
            *c = i16::from(b <= t);
        }
        count.iter().sum::<i16>() as usize
    }

    /// Moves the frequencies towards symbol `s`: every `b[i]` (i = 1..=16)
    /// by `⌊(target − b[i]) / 2^shift⌋` (floor division) towards `i` if
    /// `i ≤ s`, else towards `2^15 − 17 + i`, with `shift` as a binary
    /// [`Context`]'s: `min(1 + ⌊log2(n + 1)⌋, 5)`.
    #[inline(always)]
    fn update(&mut self, s: usize) {
        let shift = SHIFTS[self.n as usize];
        let s = s as i16;
        for (b, &i) in self.inner.iter_mut().zip(&INDEX) {
            let target = if i <= s { i } else { CDF_FREE as i16 + i };
            *b += (target - *b) >> shift;
        }
        self.n += u16::from(self.n < (1 << MAX_SHIFT));
    }

    /// The bounds `[lo, hi)` of symbol `s` in a `range`.
    #[inline(always)]
    fn interval(&self, range: u32, s: usize) -> (u32, u32) {
        let r = range >> PROB_BITS;
        let lo = if s == 0 {
            0
        } else {
            r * self.inner[s - 1] as u32
        };
        let hi = if s + 1 == SYMBOLS {
            range
        } else {
            r * self.inner[s] as u32
        };
        (lo, hi)
    }
}

/// Writes bits under adaptive contexts.
pub struct Encoder {
    low: u64,
    range: u32,
    cache: u8,
    pending: u64,
    out: Vec<u8>,
    /// The first byte shifted out is always 0 and is not stored.
    started: bool,
}

impl Default for Encoder {
    fn default() -> Encoder {
        Encoder::new()
    }
}

impl Encoder {
    /// An empty stream.
    pub fn new() -> Encoder {
        Encoder {
            low: 0,
            range: u32::MAX,
            cache: 0,
            pending: 1,
            out: Vec::new(),
            started: false,
        }
    }

    /// Codes `bit` with `ctx`, then adapts `ctx`.
    #[inline]
    pub fn bit(&mut self, ctx: &mut Context, bit: bool) {
        let bound = ctx.bound(self.range);
        if bit {
            self.low += bound as u64;
            self.range -= bound;
        } else {
            self.range = bound;
        }
        ctx.update(bit);
        while self.range < TOP {
            self.range <<= 8;
            self.shift_low();
        }
    }

    /// Codes symbol `s` (0..=16) with `cdf`, then adapts `cdf`.
    #[inline]
    pub fn symbol(&mut self, cdf: &mut Cdf, s: usize) {
        let (lo, hi) = cdf.interval(self.range, s);
        self.low += lo as u64;
        self.range = hi - lo;
        cdf.update(s);
        while self.range < TOP {
            self.range <<= 8;
            self.shift_low();
        }
    }

    fn shift_low(&mut self) {
        if self.low < 0xFF00_0000 || self.low >= 1 << 32 {
            let carry = (self.low >> 32) as u8;
            let mut byte = self.cache;
            while self.pending > 0 {
                self.emit(byte.wrapping_add(carry));
                byte = 0xFF;
                self.pending -= 1;
            }
            self.cache = (self.low >> 24) as u8;
        }
        self.pending += 1;
        self.low = (self.low << 8) & 0xFFFF_FFFF;
    }

    fn emit(&mut self, b: u8) {
        if self.started {
            self.out.push(b);
        } else {
            self.started = true;
        }
    }

    /// Ends the stream: picks the value in the final interval with the most
    /// trailing zero bits, flushes it and drops up to 4 trailing zero bytes.
    pub fn finish(mut self) -> Vec<u8> {
        let (lo, hi) = (self.low, self.low + self.range as u64 - 1);
        let mut value = lo;
        for k in (0..32).rev() {
            let mask = (1u64 << k) - 1;
            let v = (lo + mask) & !mask;
            if v <= hi {
                value = v;
                break;
            }
        }
        self.low = value;
        for _ in 0..5 {
            self.shift_low();
        }
        // Only the flush's own bytes may go: the decoder reads at most
        // MAX_OVERRUN bytes past the end.
        for _ in 0..MAX_OVERRUN {
            if self.out.last() != Some(&0) {
                break;
            }
            self.out.pop();
        }
        self.out
    }
}

/// Reads bits under adaptive contexts; input past the end reads as 0 bytes,
/// at most `MAX_OVERRUN` of them.
pub struct Decoder<'a> {
    code: u32,
    range: u32,
    bytes: &'a [u8],
    pos: usize,
}

impl<'a> Decoder<'a> {
    /// Starts decoding `bytes`.
    pub fn new(bytes: &'a [u8]) -> Result<Decoder<'a>> {
        let mut d = Decoder {
            code: 0,
            range: u32::MAX,
            bytes,
            pos: 0,
        };
        for _ in 0..4 {
            d.code = (d.code << 8) | d.next_byte() as u32;
        }
        Ok(d)
    }

    /// The next byte, 0 past the end (counted: [`Decoder::finish`] and
    /// [`Decoder::overrun`] check how far).
    #[inline(always)]
    fn next_byte(&mut self) -> u8 {
        let b = self.bytes.get(self.pos).copied().unwrap_or(0);
        self.pos += 1;
        b
    }

    /// Whether more than `MAX_OVERRUN` bytes past the end were read:
    /// the stream ended early. Decoding may go on (its bits are then
    /// meaningless, and every caller's loop is bounded) but must fail.
    pub fn overrun(&self) -> bool {
        self.pos > self.bytes.len() + MAX_OVERRUN
    }

    fn overrun_error(&self) -> Error {
        Error::corrupt(
            "column payload",
            format!(
                "range-coded stream of {} bytes ends early",
                self.bytes.len()
            ),
        )
    }

    /// Decodes a bit coded with `ctx`, then adapts `ctx`.
    #[inline(always)]
    pub fn bit(&mut self, ctx: &mut Context) -> bool {
        // Branch-free selects (the bit is as unpredictable as the data):
        // `mask` is all ones for a 1.
        let bound = ctx.bound(self.range);
        let bit = self.code >= bound;
        let mask = 0u32.wrapping_sub(bit as u32);
        self.code -= bound & mask;
        self.range = (bound & !mask) | (self.range.wrapping_sub(bound) & mask);
        ctx.update_masked(mask);
        while self.range < TOP {
            self.range <<= 8;
            self.code = (self.code << 8) | self.next_byte() as u32;
        }
        bit
    }

    /// Decodes a symbol coded with `cdf`, then adapts `cdf`.
    #[inline(always)]
    pub fn symbol(&mut self, cdf: &mut Cdf) -> usize {
        // `code < range`, so the quotient is below 2^15 + 2^15/r.
        let t = (self.code / (self.range >> PROB_BITS)).min(PROB_ONE - 1);
        let s = cdf.find(t as i16);
        let (lo, hi) = cdf.interval(self.range, s);
        self.code -= lo;
        self.range = hi - lo;
        cdf.update(s);
        while self.range < TOP {
            self.range <<= 8;
            self.code = (self.code << 8) | self.next_byte() as u32;
        }
        s
    }

    /// Checks that the stream was read to its end: no byte left unread,
    /// no more than `MAX_OVERRUN` read past it.
    pub fn finish(&self) -> Result<()> {
        if self.overrun() {
            return Err(self.overrun_error());
        }
        if self.pos < self.bytes.len() {
            return Err(Error::corrupt(
                "column payload",
                format!(
                    "{} bytes after the range-coded stream",
                    self.bytes.len() - self.pos
                ),
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// The decoder's branch-free adaptation is the encoder's, in every
    /// state a context can reach.
    #[test]
    fn masked_update_matches_update() {
        for p in PROB_MIN..=PROB_ONE - PROB_MIN {
            for n in 0..=(1u16 << MAX_SHIFT) {
                for bit in [false, true] {
                    let start = Context { p: p as u16, n };
                    let (mut a, mut b) = (start, start);
                    a.update(bit);
                    b.update_masked(0u32.wrapping_sub(bit as u32));
                    assert_eq!((a.p, a.n), (b.p, b.n), "p {p} n {n} bit {bit}");
                }
            }
        }
    }

    fn encode(bits: &[(usize, bool)], contexts: usize) -> Vec<u8> {
        let mut ctx = vec![Context::default(); contexts];
        let mut e = Encoder::new();
        for &(c, b) in bits {
            e.bit(&mut ctx[c], b);
        }
        e.finish()
    }

    fn decode(bytes: &[u8], which: &[usize], contexts: usize) -> Result<Vec<bool>> {
        let mut ctx = vec![Context::default(); contexts];
        let mut d = Decoder::new(bytes)?;
        let out = which.iter().map(|&c| d.bit(&mut ctx[c])).collect();
        d.finish()?;
        Ok(out)
    }

    proptest! {
        #[test]
        fn round_trips(bits in prop::collection::vec((0usize..4, any::<bool>()), 0..3000)) {
            let bytes = encode(&bits, 4);
            let which: Vec<usize> = bits.iter().map(|b| b.0).collect();
            let back = decode(&bytes, &which, 4).unwrap();
            let want: Vec<bool> = bits.iter().map(|b| b.1).collect();
            prop_assert_eq!(back, want);
        }

        #[test]
        fn skewed_round_trips(n in 0usize..20000, one_in in 2u32..5000, seed in any::<u64>()) {
            // Long runs drive the probabilities to their bounds and the
            // low register through carries and pending 0xFF bytes.
            let mut s = seed | 1;
            let bits: Vec<(usize, bool)> = (0..n).map(|i| {
                s ^= s << 13; s ^= s >> 7; s ^= s << 17;
                (i % 2, (s % one_in as u64 == 0) ^ (i % 2 == 1))
            }).collect();
            let bytes = encode(&bits, 2);
            let which: Vec<usize> = bits.iter().map(|b| b.0).collect();
            prop_assert_eq!(decode(&bytes, &which, 2).unwrap(),
                bits.iter().map(|b| b.1).collect::<Vec<_>>());
        }

        #[test]
        fn arbitrary_input_never_panics(bytes in prop::collection::vec(any::<u8>(), 0..64), n in 0usize..2000) {
            let _ = decode(&bytes, &vec![0; n], 1);
        }
    }

    /// Symbols and bits mixed in one stream, the symbols' contexts driven
    /// to skewed distributions.
    fn mixed(items: &[(bool, usize)]) -> (Vec<u8>, Vec<usize>) {
        let (mut cdfs, mut bits) = ([Cdf::default(); 3], [Context::default(); 2]);
        let mut e = Encoder::new();
        for (k, &(is_symbol, v)) in items.iter().enumerate() {
            if is_symbol {
                e.symbol(&mut cdfs[k % 3], v);
            } else {
                e.bit(&mut bits[k % 2], v == 1);
            }
        }
        let bytes = e.finish();
        let (mut cdfs, mut bits) = ([Cdf::default(); 3], [Context::default(); 2]);
        let mut d = Decoder::new(&bytes).unwrap();
        let back = items
            .iter()
            .enumerate()
            .map(|(k, &(is_symbol, _))| {
                if is_symbol {
                    d.symbol(&mut cdfs[k % 3])
                } else {
                    usize::from(d.bit(&mut bits[k % 2]))
                }
            })
            .collect();
        d.finish().unwrap();
        (bytes, back)
    }

    proptest! {
        #[test]
        fn symbols_round_trip(items in prop::collection::vec((any::<bool>(), 0usize..SYMBOLS), 0..3000)) {
            let items: Vec<(bool, usize)> = items.into_iter().map(|(s, v)| (s, if s { v } else { v % 2 })).collect();
            let (_, back) = mixed(&items);
            prop_assert_eq!(back, items.iter().map(|i| i.1).collect::<Vec<_>>());
        }

        #[test]
        fn skewed_symbols_round_trip(n in 0usize..20000, top in 1usize..SYMBOLS, seed in any::<u64>()) {
            // One symbol most of the time, the rarest ones now and then:
            // frequencies pinned at their floor of 1.
            let mut s = seed | 1;
            let items: Vec<(bool, usize)> = (0..n).map(|_| {
                s ^= s << 13; s ^= s >> 7; s ^= s << 17;
                (true, if s % 997 == 0 { (s >> 20) as usize % SYMBOLS } else { top })
            }).collect();
            let (_, back) = mixed(&items);
            prop_assert_eq!(back, items.iter().map(|i| i.1).collect::<Vec<_>>());
        }
    }

    /// Every state a [`Cdf`] reaches keeps its invariant: `b[0] = 0`,
    /// `b[17] = 2^15`, every symbol at least 1 wide.
    #[test]
    fn cdf_updates_keep_every_symbol_codable() {
        let mut s = 12345u64;
        for rare in 0..SYMBOLS {
            let mut cdf = Cdf::default();
            for k in 0..5000 {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                let sym = if k % 500 == 499 {
                    (s % 17) as usize
                } else {
                    rare
                };
                cdf.update(sym);
                assert!((0..SYMBOLS).all(|s| cdf.b(s + 1) > cdf.b(s)), "{cdf:?}");
            }
            // A long run drives the symbol towards its largest share (one
            // other symbol at the end takes 1/32 of it back).
            let width = cdf.b(rare + 1) - cdf.b(rare);
            assert!(width > PROB_ONE * 95 / 100, "{rare}: {width}");
        }
    }

    #[test]
    fn skewed_symbols_cost_little() {
        // Symbol 5 with p = 0.99, else 6: entropy 0.081 bit per symbol.
        let items: Vec<(bool, usize)> = (0..10000)
            .map(|i| (true, if i % 100 == 0 { 6 } else { 5 }))
            .collect();
        let (bytes, _) = mixed(&items);
        assert!(bytes.len() < 180, "{} bytes", bytes.len());
    }

    #[test]
    fn skewed_bits_cost_little() {
        let bits: Vec<(usize, bool)> = (0..10000).map(|i| (0, i % 100 == 0)).collect();
        // Entropy of p = 0.01: 0.081 bit per bit, 101 bytes for 10000.
        let bytes = encode(&bits, 1);
        assert!(bytes.len() < 140, "{} bytes", bytes.len());
    }

    #[test]
    fn streams_ending_in_zero_bytes_round_trip() {
        // 0 bits under fresh contexts (p = 1/2) emit 0x00 bytes; the flush
        // then adds zeros of its own, which alone may be dropped.
        for n in [8, 40, 41, 64, 100, 333] {
            let mut bits: Vec<(usize, bool)> = (0..50).map(|i| (0, i % 3 == 0)).collect();
            bits.extend((0..n).map(|i| (1 + i, false)));
            let bytes = encode(&bits, 1 + n);
            let which: Vec<usize> = bits.iter().map(|b| b.0).collect();
            let want: Vec<bool> = bits.iter().map(|b| b.1).collect();
            assert_eq!(decode(&bytes, &which, 1 + n).unwrap(), want, "{n}");
        }
    }

    #[test]
    fn empty_stream_is_empty() {
        assert!(encode(&[], 1).is_empty());
        assert_eq!(decode(&[], &[], 1).unwrap(), Vec::<bool>::new());
    }

    #[test]
    fn trailing_bytes_are_an_error() {
        let bits: Vec<(usize, bool)> = (0..100).map(|i| (0, i % 3 == 0)).collect();
        let mut bytes = encode(&bits, 1);
        bytes.extend_from_slice(&[1, 2, 3, 4, 5, 6]);
        let which = vec![0; 100];
        assert!(decode(&bytes, &which, 1).is_err());
    }

    #[test]
    fn reading_far_past_the_end_is_an_error() {
        // Fresh contexts cost a bit each: 10 000 bits need 1250 bytes.
        let mut d = Decoder::new(&[0x55]).unwrap();
        for _ in 0..10000 {
            d.bit(&mut Context::default());
        }
        assert!(d.overrun());
        assert!(d.finish().is_err());
    }
}
