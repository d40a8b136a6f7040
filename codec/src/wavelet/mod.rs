//! The wavelet filter bank: 1D and separable 2D transforms on `f32` data.
//!
//! Filters (see [`Filter`]):
//! - orthonormal, periodic extension: Haar and Daubechies D4, D6, D8
//!   (Daubechies 1988; PyWavelets `haar`, `db2`, `db3`, `db4` in mode
//!   `periodization`);
//! - biorthogonal, lifting with whole-sample symmetric extension as in
//!   JPEG 2000: LeGall 5/3 and CDF 9/7 (PyWavelets `bior2.2`, `bior4.4`).
//!
//! Multi-level 2D transforms use the Mallat layout: after `l` steps the
//! low band occupies the top-left [`band_size`]`(w, h, l)` corner of the image,
//! and each step splits that corner into low (first `ceil(n/2)` samples) and
//! high (last `floor(n/2)`) halves along every axis whose length is at least 2.
//! Any size works, odd and non-power-of-two included; an axis of length 1 is
//! left as it is. [`forward_step`] and [`inverse_step`] are public because
//! relighting inverts one level at a time (Cheslack-Postava et al. 2007, eq. 6).
//! A step works on a [`PlaneMut`]: a region of a plane of one or more
//! interleaved images, checked when it is made. [`inverse_step`]'s
//! [`RowMode`] filters every row, or skips rows known to be zero (in place
//! or into a second buffer).
//! The row transform over cube faces ([`row_forward`], [`row_inverse`],
//! [`row_level`]) is shared by the compressor and the relighter.
//!
//! Normalization: the lifting filters have low-pass DC gain 1 and high-pass
//! Nyquist gain 2 (JPEG 2000's convention); the orthonormal filters preserve
//! energy. In PyWavelets' terms, `cA = sqrt(2)·low` and `cD = −high/sqrt(2)` for
//! both lifting filters; the orthonormal filters match PyWavelets exactly.
//!
//! Periodic filters on an odd length `n = 2q + 1` transform the first `2q`
//! samples with period `2q` and carry the last sample unchanged as the last
//! low-band coefficient. This keeps the transform orthonormal and gives the
//! same band sizes as the lifting filters.

mod cube;
mod dwt2;
mod lifting;
mod periodic;
mod plane;

pub use cube::{row_forward, row_inverse, row_level};
pub use dwt2::{
    band_size, forward, forward_1d, forward_step, inverse, inverse_1d, inverse_step, max_levels,
};
pub use plane::{PlaneMut, RowMode};

use std::fmt;
use std::str::FromStr;

/// A wavelet filter of the bank (serialized by its [`Filter::name`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
#[non_exhaustive]
pub enum Filter {
    /// Haar (orthonormal, 2 taps).
    Haar,
    /// Daubechies with 2 vanishing moments, 4 taps (PyWavelets `db2`).
    D4,
    /// Daubechies with 3 vanishing moments, 6 taps (PyWavelets `db3`).
    D6,
    /// Daubechies with 4 vanishing moments, 8 taps (PyWavelets `db4`).
    D8,
    /// LeGall 5/3 biorthogonal, lifting (JPEG 2000 reversible filter, in float).
    LeGall53,
    /// Cohen–Daubechies–Feauveau 9/7 biorthogonal, lifting (JPEG 2000 irreversible).
    Cdf97,
}

/// How a filter is computed.
pub(crate) enum Kind {
    /// Orthonormal filter with periodic extension; the analysis low-pass taps
    /// in PyWavelets' `dec_lo` order.
    Periodic(&'static [f64]),
    /// Lifting scheme with whole-sample symmetric extension.
    Lifting(&'static lifting::Scheme),
}

impl Filter {
    /// Every filter, in file-code order.
    pub const ALL: [Filter; 6] = [
        Filter::Haar,
        Filter::D4,
        Filter::D6,
        Filter::D8,
        Filter::LeGall53,
        Filter::Cdf97,
    ];

    /// The name used on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            Filter::Haar => "haar",
            Filter::D4 => "d4",
            Filter::D6 => "d6",
            Filter::D8 => "d8",
            Filter::LeGall53 => "legall53",
            Filter::Cdf97 => "cdf97",
        }
    }

    /// The code stored in `.ltm` headers.
    pub fn code(self) -> u8 {
        match self {
            Filter::Haar => 0,
            Filter::D4 => 1,
            Filter::D6 => 2,
            Filter::D8 => 3,
            Filter::LeGall53 => 4,
            Filter::Cdf97 => 5,
        }
    }

    /// The filter with the given header code.
    pub fn from_code(code: u8) -> Option<Filter> {
        Filter::ALL.into_iter().find(|f| f.code() == code)
    }

    /// True for the filters computed by lifting (LeGall 5/3, CDF 9/7).
    pub fn is_lifting(self) -> bool {
        matches!(self.kind(), Kind::Lifting(_))
    }

    /// True for the energy-preserving filters (Haar, D4, D6, D8).
    pub fn is_orthonormal(self) -> bool {
        matches!(self.kind(), Kind::Periodic(_))
    }

    /// Number of vanishing moments of the analysis high-pass filter:
    /// polynomials of lower degree give zero detail coefficients.
    pub fn vanishing_moments(self) -> usize {
        match self {
            Filter::Haar => 1,
            Filter::D4 => 2,
            Filter::D6 => 3,
            Filter::D8 => 4,
            Filter::LeGall53 => 2,
            Filter::Cdf97 => 4,
        }
    }

    pub(crate) fn kind(self) -> Kind {
        match self {
            Filter::Haar => Kind::Periodic(&periodic::HAAR),
            Filter::D4 => Kind::Periodic(&periodic::DB2),
            Filter::D6 => Kind::Periodic(&periodic::DB3),
            Filter::D8 => Kind::Periodic(&periodic::DB4),
            Filter::LeGall53 => Kind::Lifting(&lifting::LEGALL53),
            Filter::Cdf97 => Kind::Lifting(&lifting::CDF97),
        }
    }

    /// PyWavelets' analysis low-pass taps (`dec_lo`) of the orthonormal
    /// filters; `None` for the lifting filters.
    pub fn orthonormal_taps(self) -> Option<&'static [f64]> {
        match self.kind() {
            Kind::Periodic(taps) => Some(taps),
            Kind::Lifting(_) => None,
        }
    }
}

impl fmt::Display for Filter {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Filter {
    type Err = String;

    fn from_str(s: &str) -> Result<Filter, String> {
        Filter::ALL
            .into_iter()
            .find(|f| f.name().eq_ignore_ascii_case(s))
            .ok_or_else(|| {
                let names: Vec<_> = Filter::ALL.iter().map(|f| f.name()).collect();
                format!(
                    "unknown filter '{s}' (expected one of {})",
                    names.join(", ")
                )
            })
    }
}
