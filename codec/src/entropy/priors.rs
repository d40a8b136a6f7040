//! Encoding 6's per-file priors (chunk PRIO, format version 9): the state
//! every context of encoding 5's model starts a column in. An adaptive
//! context that starts at p = 1/2 spends its first bits of every column
//! learning what the file's other columns already taught it; a grey
//! 96×72 matrix's 1,536 columns each relearn about a hundred contexts. The
//! writer measures each context's average state at the end of the file's
//! columns ([`PriorTally`]) and codes every column again from it.
//! docs/FORMAT.md ("Priors") is the specification.

use super::column::{decode_from, Model, CLASS_CONTEXTS};
use super::range::{Cdf, Context, SYMBOLS};
use super::{ColumnShape, ValueCoding};
use crate::error::{Error, Result};

/// Binary contexts in the PRIO chunk: the scale codes' 2, block flags' 48,
/// significance's 144, signs' 7 and the bits below the leading one's 17 + 34.
pub const PRIOR_BINARY: usize = 2 + 48 + 144 + 7 + 17 + 34;
/// Magnitude-class contexts in the PRIO chunk.
pub const PRIOR_CLASSES: usize = CLASS_CONTEXTS;
/// Bytes of the PRIO chunk (before packing): two `u16` counts, 4 bytes per
/// binary context and 34 per magnitude-class context.
pub const PRIO_LEN: usize = 4 + 4 * PRIOR_BINARY + 34 * PRIOR_CLASSES;
/// The count a trained context starts at: its adaptation rate is then
/// 1/16, where a fresh context's starts at 1/2. Measured on four grey
/// matrices at 1 % and 3 %, 8 coded smallest of 1, 2, 4, 8, 12, 16 and 32
/// (by 0.1–0.5 % of the columns' bytes).
const TRAINED_COUNT: u16 = 8;

/// The starting state of each context of encoding 6 (chunk PRIO).
#[derive(Clone, Debug)]
pub struct Priors {
    binary: Vec<Context>,
    classes: Vec<Cdf>,
}

impl Priors {
    /// Reads and checks a PRIO chunk: its two counts, and each state one a
    /// context can reach (see docs/FORMAT.md, "Priors").
    pub fn from_bytes(b: &[u8]) -> Result<Priors> {
        if b.len() != PRIO_LEN {
            return Err(Error::corrupt(
                "PRIO chunk",
                format!("{} bytes (valid: {PRIO_LEN})", b.len()),
            ));
        }
        let u16s: Vec<u16> = b
            .chunks_exact(2)
            .map(|w| u16::from_le_bytes([w[0], w[1]]))
            .collect();
        let (binary_n, classes_n) = (u16s[0] as usize, u16s[1] as usize);
        if (binary_n, classes_n) != (PRIOR_BINARY, PRIOR_CLASSES) {
            return Err(Error::corrupt(
                "PRIO chunk",
                format!("{binary_n} binary and {classes_n} class contexts (valid: {PRIOR_BINARY} and {PRIOR_CLASSES})"),
            ));
        }
        let (bin, cls) = u16s[2..].split_at(2 * PRIOR_BINARY);
        let binary = bin
            .chunks_exact(2)
            .enumerate()
            .map(|(k, s)| Context::from_state(s[0], s[1]).ok_or_else(|| bad_state("binary", k, s)))
            .collect::<Result<Vec<_>>>()?;
        let classes = cls
            .chunks_exact(SYMBOLS)
            .enumerate()
            .map(|(k, s)| {
                let a: [u16; SYMBOLS - 1] = s[..SYMBOLS - 1].try_into().expect("16 values");
                Cdf::from_state(a, s[SYMBOLS - 1]).ok_or_else(|| bad_state("class", k, s))
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(Priors { binary, classes })
    }

    /// The PRIO chunk's bytes.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(PRIO_LEN);
        let mut put = |v: u16| out.extend_from_slice(&v.to_le_bytes());
        put(PRIOR_BINARY as u16);
        put(PRIOR_CLASSES as u16);
        for c in &self.binary {
            let (p, n) = c.state();
            put(p);
            put(n);
        }
        for c in &self.classes {
            let (a, n) = c.state();
            a.into_iter().for_each(&mut put);
            put(n);
        }
        out
    }

    /// A column model in these states.
    pub(super) fn model(&self) -> Box<Model> {
        let mut m = Model::new();
        let (binary, classes) = m.compact();
        binary.zip(&self.binary).for_each(|(c, p)| *c = *p);
        classes.copy_from_slice(&self.classes);
        m
    }
}

/// A PRIO state that no context can reach.
fn bad_state(kind: &str, k: usize, s: &[u16]) -> Error {
    Error::corrupt(
        "PRIO chunk",
        format!("{kind} context {k} in state {s:?} (valid: p within 31..=32737 and n ≤ 32; class frequencies a[1] ≤ … ≤ a[16] ≤ 32751)"),
    )
}

/// The sums that make [`Priors`]: each context's state at the end of the
/// columns added, weighted by the count of symbols it saw (capped at 32).
/// Every term is an integer below 2^20, so the `f64` sums are exact for
/// fewer than 2^33 columns, whatever order tallies are merged in: the
/// priors, and so the file, do not depend on the thread count.
#[derive(Clone, Debug)]
pub struct PriorTally {
    binary: Vec<(f64, f64)>,
    classes: Vec<([f64; SYMBOLS - 1], f64)>,
    columns: usize,
}

impl Default for PriorTally {
    fn default() -> PriorTally {
        PriorTally {
            binary: vec![(0.0, 0.0); PRIOR_BINARY],
            classes: vec![([0.0; SYMBOLS - 1], 0.0); PRIOR_CLASSES],
            columns: 0,
        }
    }
}

impl PriorTally {
    /// Decodes an encoding-5 column and adds its contexts' final states.
    pub fn add_column(
        &mut self,
        bytes: &[u8],
        nnz: usize,
        shape: &ColumnShape,
        depth: u32,
    ) -> Result<()> {
        let coding = ValueCoding::Compact;
        let (_, mut model) = decode_from(bytes, nnz, shape, depth, coding, Model::new())?;
        let (binary, classes) = model.compact();
        for (acc, c) in self.binary.iter_mut().zip(binary) {
            let (p, n) = c.state();
            acc.0 += f64::from(p) * f64::from(n);
            acc.1 += f64::from(n);
        }
        for (acc, c) in self.classes.iter_mut().zip(classes.iter()) {
            let (a, n) = c.state();
            for (s, v) in acc.0.iter_mut().zip(a) {
                *s += f64::from(v) * f64::from(n);
            }
            acc.1 += f64::from(n);
        }
        self.columns += 1;
        Ok(())
    }

    /// The sums of both tallies.
    pub fn merge(mut self, other: PriorTally) -> PriorTally {
        for (a, b) in self.binary.iter_mut().zip(other.binary) {
            a.0 += b.0;
            a.1 += b.1;
        }
        for (a, b) in self.classes.iter_mut().zip(other.classes) {
            a.0.iter_mut().zip(b.0).for_each(|(x, y)| *x += y);
            a.1 += b.1;
        }
        self.columns += other.columns;
        self
    }

    /// Columns added.
    pub fn columns(&self) -> usize {
        self.columns
    }

    /// The priors: each context that saw a symbol starts at its weighted
    /// mean state with a count of 8; the others as in encoding 5.
    pub fn priors(&self) -> Priors {
        let binary = self
            .binary
            .iter()
            .map(|&(pn, n)| match n > 0.0 {
                true => {
                    let p = (pn / n).round().clamp(31.0, f64::from((1 << 15) - 31));
                    Context::from_state(p as u16, TRAINED_COUNT).unwrap_or_default()
                }
                false => Context::default(),
            })
            .collect();
        let classes = self
            .classes
            .iter()
            .map(|(an, n)| match *n > 0.0 {
                // The floor of a mean of ordered states is ordered.
                true => Cdf::from_state(an.map(|v| (v / n).floor() as u16), TRAINED_COUNT)
                    .unwrap_or_default(),
                false => Cdf::default(),
            })
            .collect();
        Priors { binary, classes }
    }
}

#[cfg(test)]
mod tests {
    use super::super::column::tests::column;
    use super::super::{decode, encode, encode_primed};
    use super::*;
    use proptest::prelude::*;

    /// Priors tallied from `n` columns of one kind (grey, 48 × 40, 12 bits,
    /// depth 3, a tenth of the positions kept), and the columns.
    fn trained(n: u64, seed: u64) -> (Priors, Vec<crate::column::SparseColumn>, ColumnShape) {
        let mut tally = PriorTally::default();
        let mut cols = Vec::new();
        let mut shape = None;
        for k in 0..n {
            let (col, s) = column((48, 40, 1, 12), 3, 0.1, seed + k);
            let bytes = encode(&col, &s, ValueCoding::Compact).unwrap();
            tally
                .add_column(&bytes, col.indices.len(), &s, col.depth)
                .unwrap();
            cols.push(col);
            shape = Some(s);
        }
        assert_eq!(tally.columns(), n as usize);
        (tally.priors(), cols, shape.unwrap())
    }

    #[test]
    fn priors_round_trip_through_their_chunk() {
        let (priors, _, _) = trained(8, 1);
        let bytes = priors.to_bytes();
        assert_eq!(bytes.len(), PRIO_LEN);
        assert_eq!(Priors::from_bytes(&bytes).unwrap().to_bytes(), bytes);
        // Untrained priors are encoding 5's starting states.
        let fresh = PriorTally::default().priors().to_bytes();
        assert_eq!(Priors::from_bytes(&fresh).unwrap().to_bytes(), fresh);
    }

    /// Every state no context can reach, a wrong count and a wrong length
    /// are refused, with the context named.
    #[test]
    fn unreachable_states_are_refused() {
        let good = trained(4, 2).0.to_bytes();
        let put = |at: usize, v: u16| {
            let mut b = good.clone();
            b[at..at + 2].copy_from_slice(&v.to_le_bytes());
            b
        };
        let class0 = 4 + 4 * PRIOR_BINARY;
        let cases = [
            (put(0, 251), "binary and"),
            (put(2, 0), "0 class contexts"),
            (put(4, 30), "binary context 0"),
            (put(4, 32738), "binary context 0"),
            (put(4 + 4 * 9 + 2, 33), "binary context 9"),
            (put(class0, 40_000), "class context 0"),
            (put(class0 + 30, 32_752), "class context 0"),
            (put(class0 + 34 * 3 + 32, 33), "class context 3"),
        ];
        for (bytes, named) in cases {
            let e = Priors::from_bytes(&bytes).unwrap_err().to_string();
            assert!(e.contains(named), "{e}");
        }
        // a[2] < a[1].
        let mut b = put(class0, 100);
        b[class0 + 2..class0 + 4].copy_from_slice(&99u16.to_le_bytes());
        assert!(Priors::from_bytes(&b).is_err());
        assert!(Priors::from_bytes(&good[..PRIO_LEN - 1]).is_err());
        let mut long = good.clone();
        long.push(0);
        assert!(Priors::from_bytes(&long).is_err());
    }

    /// Columns like the training ones code smaller from the priors, and
    /// decode to the same column; a primed column needs the priors.
    #[test]
    fn primed_columns_are_smaller_and_decode_the_same() {
        let (priors, cols, shape) = trained(40, 3);
        let (mut plain, mut primed) = (0, 0);
        for col in &cols {
            let p = encode_primed(col, &shape, &priors).unwrap();
            let c = encode(col, &shape, ValueCoding::Compact).unwrap();
            (plain, primed) = (plain + c.len(), primed + p.len());
            let n = col.indices.len();
            let back = decode(&p, n, &shape, col.depth, ValueCoding::Primed, Some(&priors));
            assert_eq!(&back.unwrap(), col);
            assert!(decode(&p, n, &shape, col.depth, ValueCoding::Primed, None).is_err());
        }
        assert!(primed * 100 < plain * 97, "{primed} vs {plain} bytes");
        assert!(encode(&cols[0], &shape, ValueCoding::Primed).is_none());
    }

    proptest! {
        /// Any column round-trips from priors trained on unlike columns.
        #[test]
        fn primed_columns_round_trip(w in 1usize..40, h in 1usize..40, rgb in any::<bool>(), bits in 2u32..=16, d in 0u32..8, density in 0.0f64..1.0, seed in any::<u64>()) {
            let (priors, _, _) = trained(3, seed ^ 0x55);
            let (col, shape) = column((w, h, if rgb { 3 } else { 1 }, bits), d, density, seed);
            prop_assume!(!col.indices.is_empty());
            let bytes = encode_primed(&col, &shape, &priors).unwrap();
            let back = decode(&bytes, col.indices.len(), &shape, col.depth, ValueCoding::Primed, Some(&priors)).unwrap();
            prop_assert_eq!(back, col);
        }
    }
}
