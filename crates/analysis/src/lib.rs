//! twinbench bench analysis (paper, chapter 2): how the test bench changes the system it
//! tests.
//!
//! - [`chain`] and [`modal`]: torsional chains of inertias and spring-dampers, their modes,
//!   modal masses and stiffnesses, sensitivity coefficients and damped frequencies
//!   (Eq. 1–8), and a side-by-side comparison of two chains (vehicle vs. bench).
//! - [`signal`]: uniformly sampled time series (a `tb-table` table with a time base).
//! - [`step`]: dead time, rise time and transient time of a step response (Fig. 2).
//! - [`frf`]: Welch spectra, the H1 frequency response, coherence, unwrapped phase and
//!   group delay (Eq. 9–10), matching `scipy.signal`.
//! - [`fit`]: least-squares fit of dead time + first- or second-order lag to an FRF, written
//!   as the dyno FMU's parameters (the Nelder–Mead minimiser is in `optim`).
//! - [`error`]: the crate's error type.

pub mod chain;
pub mod error;
pub mod fit;
pub mod frf;
pub mod modal;
mod optim;
pub mod signal;
pub mod step;

pub use chain::Chain;
pub use error::{AnalysisError, Result};
pub use rustfft::num_complex::Complex64;
